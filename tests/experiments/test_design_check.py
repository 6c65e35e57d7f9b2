"""The design model against the rendered Monte Carlo: the comparison runs and its figures are
sane on the paper rig, and the model is within ±20 % of the simulation at two other designs
(STUDIES.md "Rig design by gradient": per point and the image's noise)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from lts360.experiments.design_check import check_rig
from lts360.scenes.rig_io import load_rig

RIGS = Path(__file__).parent / "rigs"


@pytest.mark.slow  # one render + 3 measured draws (~20 s)
def test_check_rig_reports_model_and_simulation():
    r = check_rig(load_rig("paper"), draws=3, spp=4, seed=1)
    assert r["simulation"]["draws"] == 3
    for key in ("model_pixel", "model_dorsch"):
        assert math.isfinite(r[key]["sigma_R_um"]) and r[key]["coverage_deg"] > 359.0
    # the model's σ_R is the image's own share (no compensation: the simulation measures with
    # the true calibration), 1.81 µm on the paper rig, not the compensated 6.0 µm
    assert r["model_pixel"]["sigma_R_um"] == pytest.approx(1.81, rel=0.02)
    # per point: the pixel model against the render, loosely (3 draws at 4 spp: the render's
    # own fixed error, 9.5 µm rms at 16 spp, is larger at 4 spp); the tight test is below
    assert r["model_pixel"]["point_rms_um"] == pytest.approx(r["simulation"]["point_rms_um"],
                                                              rel=0.3)


@pytest.mark.slow  # per design one 16-spp render and 100 measured draws (~2–4 min on 2 cores)
@pytest.mark.parametrize("rig", ["paper-f8", str(RIGS / "ds-a55-b110.toml")],
                         ids=["paper-f8", "a55-b110"])
def test_the_model_is_within_20_percent_of_the_simulation(rig):
    """STUDIES.md claims the model's radius σ within ±20 % of the simulation at five designs
    (and per point at four, paper-f8 being 14 % high). With 100 draws the simulated σ's 95 %
    interval is −12 %/+16 %, so ±20 % is a test of the model, not of the draws' noise; the
    draws are seeded."""
    # measured 2026-12-04 (model / simulated): paper-f8 σ_R 4.25 / 4.55 µm (0.93), per point
    # 78.4 / 68.8 µm (1.14); α 55°, β 110°: σ_R 1.39 / 1.21 µm (1.15), per point 28.0 / 28.4 µm
    # (0.99)
    r = check_rig(load_rig(rig), draws=100, spp=16, seed=0)
    sim, model = r["simulation"], r["model_pixel"]
    assert sim["draws"] == 100
    ratio = model["sigma_R_um"] / sim["sigma_R_um"]
    assert 0.8 <= ratio <= 1.2, (model["sigma_R_um"], sim["sigma_R_um"])
    per_point = model["point_rms_um"] / sim["point_rms_um"]
    assert 0.8 <= per_point <= 1.2, (model["point_rms_um"], sim["point_rms_um"])
