"""The Monte Carlo's stored placements: their render noise is common to every trial (a bias of
the study, not a spread), so they are rendered at PLACEMENT_SPP, and renders made at another
sample count are refused rather than reused."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from lts360.cli import build_parser


def test_the_placements_render_at_placement_spp_by_default():
    from lts360.experiments.monte_carlo import PLACEMENT_SPP, run_monte_carlo_study

    assert PLACEMENT_SPP == 256
    assert inspect.signature(run_monte_carlo_study).parameters["spp"].default == PLACEMENT_SPP
    parser = build_parser()
    # the command line says the default without importing the study (a fast --help)
    assert parser.parse_args(["study", "monte-carlo", "--out", "s"]).spp is None
    assert parser.parse_args(["study", "monte-carlo", "--out", "s", "--spp", "64"]).spp == 64
    studies = next(a for a in parser._actions if a.dest == "command").choices["study"]
    mc = next(a for a in studies._actions if a.dest == "study").choices["monte-carlo"]
    spp = next(a for a in mc._actions if a.dest == "spp")
    assert f"default {PLACEMENT_SPP}," in spp.help


def test_the_monte_carlo_refuses_a_bad_spp_before_rendering(tmp_path):
    from lts360.experiments.monte_carlo import run_monte_carlo_study

    for bad in (0, 5000, True):
        with pytest.raises(ValueError, match="spp must be in"):
            run_monte_carlo_study(tmp_path, calibration="unused.json", spp=bad)
    assert not (tmp_path / "renders").exists()


def test_stored_placements_of_another_sample_count_are_refused(tmp_path):
    pytest.importorskip("mitsuba", reason="the placements are rendered")
    from lts360.experiments.monte_carlo import _render_placements

    quiet = {"rig": "paper", "seed": 3, "say": lambda *_: None}
    root = _render_placements(tmp_path, 1, spp=4, **quiet)
    stamp = (root / "placement_00" / "radiance.exr").stat().st_mtime_ns
    assert _render_placements(tmp_path, 1, spp=4, **quiet) == root  # reused as it is
    with pytest.raises(ValueError, match=r"rendered at 4 spp, this run asks 8: give --spp 4"):
        _render_placements(tmp_path, 1, spp=8, **quiet)
    assert (root / "placement_00" / "radiance.exr").stat().st_mtime_ns == stamp


@pytest.mark.slow
def test_the_nominal_compensation_does_not_carry_the_reference_renders_noise(
        tmp_path, truth_calibration):
    """The nominal §4.4 compensation is fitted to the stored reference placement once and
    used by every trial: measured with it, the same converged (1024-spp) image of the gauge
    reads within 1 µm whether the reference was rendered at 1024 spp or at PLACEMENT_SPP; a
    16-spp reference moves it further (on average −2.3 µm: its render noise biases the views'
    offsets, STUDIES.md)."""
    from lts360.experiments.gauge_study import gauge_placements
    from lts360.experiments.mc_measure import _grid, _noise_free_image, _nominal_calibration
    from lts360.experiments.monte_carlo import PLACEMENT_SPP, _radius_error_um
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame, write_frame

    spec = gauge_placements(1, 0)[0]["spec"]
    rig, step = load_rig("paper"), 0.5  # the study's grid
    y = {}
    image = None
    for spp in (1024, PLACEMENT_SPP, 16):
        root = tmp_path / f"spp{spp}"
        write_frame(root / "placement_00", simulate_frame(rig, build_object(spec), spp=spp,
                                                          seed=500, noise="none"))
        if image is None:
            image = _noise_free_image(str(root / "placement_00"), "paper")
        cal = _nominal_calibration(str(truth_calibration), str(root), "paper", step)
        res = inverse_triangulate(image, cal, _grid(step), compensate=True)
        y[spp] = _radius_error_um(res, 0.0)[0]
    assert np.isfinite(list(y.values())).all(), y
    assert abs(y[PLACEMENT_SPP] - y[1024]) <= 1.0, y
    assert abs(y[16] - y[1024]) > abs(y[PLACEMENT_SPP] - y[1024]), y
