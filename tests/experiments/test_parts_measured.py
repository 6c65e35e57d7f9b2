"""A hexagonal bar of your own, end to end (slow: four renders): from a binary STL written by
trimesh and from a DXF of its section, rendered noise-free, measured with the true calibration
and scored against its own truth (STUDIES.md, "Your own parts")."""

import json

import numpy as np
import pytest

from lts360.cli import main

pytestmark = pytest.mark.slow

SPP = "16"


def hex_ring():
    a = np.radians(np.arange(6) * 60.0)  # corners at 0°, 60°, …
    return 8.0 / np.cos(np.pi / 6.0) * np.column_stack([np.cos(a), np.sin(a)])


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    import ezdxf

    from lts360.scenes.objects.profile_part import extrude_ring

    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    root = tmp_path_factory.mktemp("hexbar")
    extrude_ring(hex_ring(), -20.0, 20.0).export(root / "hex.stl")  # binary STL (float32)
    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4
    doc.modelspace().add_lwpolyline([tuple(p) for p in hex_ring()], close=True)
    doc.saveas(root / "hex.dxf")
    out = {}
    for name, spec in (("stl", f"mesh:path={root / 'hex.stl'}"),
                       ("dxf", f"profile:path={root / 'hex.dxf'}"),
                       ("gauge", "plug-gauge")):
        f, c, s = root / f"f-{name}", root / f"c-{name}.ply", root / f"s-{name}.json"
        assert main(["render", "--object", spec, "--out", str(f), "--spp", SPP]) == 0
        assert main(["measure", str(f), "--calibration", str(f / "frame.json"),
                     "--out", str(c)]) == 0
        assert main(["score", str(c), "--truth", str(f), "--out", str(s)]) == 0
        out[name] = (f, c, json.loads(s.read_text()))
        if name != "dxf":  # the twin, its corners restored (none on the gauge)
            ct, st = root / f"ct-{name}.ply", root / f"st-{name}.json"
            assert main(["measure", str(f), "--calibration", str(f / "frame.json"),
                         "--out", str(ct), "--bias-model", "twin", "--twin-corners", "on"]) == 0
            assert main(["score", str(ct), "--truth", str(f), "--out", str(st)]) == 0
            out[f"{name}-twin"] = (f, ct, json.loads(st.read_text()))
    (root / "hex.stl").unlink()  # from here on the frame folder's own copy is the truth
    f, c, _ = out["stl"]
    # unfiltered: the default ISO 12181-2 filter treats the truth as the measurement and
    # rounds the hexagon's corners in both; here the true section is the part's own cut
    assert main(["inspect", str(c), "--out", str(root / "report"), "--nominal",
                 str(root / "hex.dxf"), "--tolerance-mm", "0.4", "--truth", str(f),
                 "--calibration", str(f / "frame.json"), "--filter", "none"]) == 0
    out["inspection"] = json.loads((root / "report" / "inspection.json").read_text())
    return out


def _mesh_errors(frame, cloud_path):
    from lts360.experiments.score import load_truth, signed_mesh_distance
    from lts360.recon.triangulation.cloud import read_cloud

    obj, _ = load_truth(frame)
    c = read_cloud(cloud_path)
    c = c.select(c.valid)
    theta = np.arctan2(c.points_mm[:, 1], c.points_mm[:, 0])
    return signed_mesh_distance(obj.mesh_world(), c.points_mm), theta


def test_the_bar_is_measured_all_round_with_few_far_points(measured):
    f, c, m = measured["stl"]
    assert m["coverage_deg"] >= 0.95 * 360.0
    err, _ = _mesh_errors(f, c)
    assert np.mean(np.abs(err) > 0.150) <= 0.001


def test_the_dxf_profile_measures_as_the_stl(measured):
    from lts360.recon.triangulation.cloud import read_cloud

    a, b = read_cloud(measured["stl"][1]), read_cloud(measured["dxf"][1])
    assert np.array_equal(a.valid, b.valid)
    # the same hexagon (float32 STL vs float64 polygon, both float32 in the renderer): 1 µm
    assert np.nanmax(np.abs(a.points_mm - b.points_mm)) <= 1e-3
    assert measured["dxf"][2]["rms_mm"] == pytest.approx(measured["stl"][2]["rms_mm"], abs=1e-3)


def test_away_from_the_corners_the_bar_measures_like_the_gauge(measured):
    """The error is the corners' (the line's centroid across a 120° corner rounds it, ~0.14 mm
    deep at the apex, within ~2° of it); more than 4° from a corner the flats measure within
    1.5× the gauge's rms at the same settings."""
    err, theta = _mesh_errors(*measured["stl"][:2])
    from_corner = np.abs(np.mod(np.degrees(theta) + 30.0, 60.0) - 30.0)
    flats = from_corner > 4.0
    gauge = measured["gauge"][2]["mesh_distance"]["rms_mm"]
    assert np.sqrt(np.mean(err[flats] ** 2)) <= 1.5 * gauge
    assert np.sqrt(np.mean(err[~flats] ** 2)) > np.sqrt(np.mean(err[flats] ** 2))


def test_inspect_gives_the_true_section_of_the_part(measured):
    """``inspect --truth`` cuts the part's own truth (the STL's copy in the frame folder) by the
    sheet's plane."""
    s = measured["inspection"]["sections"][0]
    truth = s["truth"]
    # the true section is sampled every 0.1° (D min 48 nm over 16 mm, measured 2026-12-04): 0.1 µm
    assert truth["d_min_mm"] == pytest.approx(16.0, abs=1e-4)
    # the measured LS diameter within its own U of the true one (the corners are rounded)
    assert abs(s["d_ls_mm"]["value"] - truth["d_ls_mm"]) <= s["d_ls_mm"]["U_k2"]


def test_with_its_corners_restored_in_the_twin_the_bar_measures_like_the_gauge(measured):
    """The issue's target, at 16 spp: valid points' rms distance to the mesh ≤ 1.5× the
    gauge's at the same settings (both measured with ``--bias-model twin --twin-corners on``;
    and against the gauge measured plainly), with all of 360° and no point beyond 150 µm."""
    f, c, m = measured["stl-twin"]
    hexagon = m["mesh_distance"]["rms_mm"]
    assert hexagon <= 1.5 * measured["gauge-twin"][2]["mesh_distance"]["rms_mm"]
    assert hexagon <= 1.5 * measured["gauge"][2]["mesh_distance"]["rms_mm"]
    assert m["coverage_deg"] >= 0.95 * 360.0
    err, theta = _mesh_errors(f, c)
    assert np.mean(np.abs(err) > 0.150) <= 0.001
    from_corner = np.abs(np.mod(np.degrees(theta) + 30.0, 60.0) - 30.0)
    plain, _ = _mesh_errors(*measured["stl"][:2])
    near = from_corner < 2.0
    assert np.sqrt(np.mean(err[near] ** 2)) < 0.3 * np.sqrt(np.mean(plain[near] ** 2))
