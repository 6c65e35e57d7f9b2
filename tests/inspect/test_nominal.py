"""Nominal contours from specs, CSV and DXF files, and the deviation along the normal."""

import numpy as np
import pytest
from _profiles import polar

from lts360.inspect.nominal import (
    ToleranceBand,
    deviations,
    load_nominal,
    place_nominal,
    read_contour_csv,
    read_contour_dxf,
)


def _write_csv(path, xy, header="x_mm,y_mm"):
    lines = ([header] if header else []) + [f"{float(x)!r},{float(y)!r}" for x, y in xy]
    path.write_text("\n".join(lines) + "\n")
    return path


def _circle_xy(r, n=360):
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    xy = np.column_stack([r * np.cos(th), r * np.sin(th)])
    return np.vstack([xy, xy[:1]])


def test_deviation_from_a_circle_is_the_radius_difference():
    nom = _circle_xy(10.0, 3600)[:-1]
    pts = polar(lambda t: 10.0 + 0.03 * np.cos(2 * t))
    dev = deviations(pts, nom)
    # the chord of 0.1° lies inside the circle by r·(1 − cos 0.05°) = 3.8e-6 mm at most
    assert dev == pytest.approx(0.03 * np.cos(2 * np.arctan2(pts[:, 1], pts[:, 0])), abs=5e-6)


def test_csv_units_scale_and_close(tmp_path):
    n = read_contour_csv(_write_csv(tmp_path / "c.csv", _circle_xy(10_000.0), "x_um,y_um"))
    assert np.hypot(*n.fixed_xy_mm.T) == pytest.approx(10.0)
    assert n.is_round


def test_csv_errors_name_the_problem(tmp_path):
    xy = _circle_xy(5.0)
    with pytest.raises(ValueError, match="not closed"):
        read_contour_csv(_write_csv(tmp_path / "open.csv", xy[:-2]))
    with pytest.raises(ValueError, match="unit does not parse"):
        read_contour_csv(_write_csv(tmp_path / "u.csv", xy, "x_furlong,y_furlong"))
    (tmp_path / "v.csv").write_text("x_mm,y_mm\n0,0\n1,abc\n")
    with pytest.raises(ValueError, match="not two finite numbers"):
        read_contour_csv(tmp_path / "v.csv")


def test_dxf_circle_and_units(tmp_path):
    import ezdxf

    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 5  # cm
    doc.modelspace().add_circle((0, 0), 1.0)
    doc.modelspace().add_line((0, 0), (3, 0))  # not a contour: ignored
    doc.saveas(tmp_path / "c.dxf")
    n = read_contour_dxf(tmp_path / "c.dxf")
    assert np.hypot(*n.fixed_xy_mm.T) == pytest.approx(10.0, abs=1e-9)  # vertices on it
    doc = ezdxf.new()
    doc.modelspace().add_lwpolyline([(0, 0), (1, 0), (1, 1)])  # open
    doc.saveas(tmp_path / "open.dxf")
    with pytest.raises(ValueError, match="not closed"):
        read_contour_dxf(tmp_path / "open.dxf")


def test_spec_nominal_is_the_generator_contour():
    n = load_nominal("pvc-pipe:dent=0")
    ring = n.contour(0.0)
    r = np.hypot(*ring.T)
    assert np.ptp(r) == pytest.approx(0.4, abs=1e-9)  # default ovality 0.8 mm: r ± 0.2 mm
    assert not n.is_round and load_nominal("plug-gauge").is_round
    moved = place_nominal(ring, (1.0, 2.0))
    assert moved.mean(axis=0) == pytest.approx([1.0, 2.0], abs=1e-9)


def test_tolerance_band():
    assert ToleranceBand.symmetric(0.1) == ToleranceBand(0.05, -0.05)
    with pytest.raises(ValueError, match="must exceed"):
        ToleranceBand(-0.1, 0.1)
