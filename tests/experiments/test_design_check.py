"""The design model against the rendered Monte Carlo: the comparison runs and its figures are
sane (the agreement itself is recorded in STUDIES.md, from 120 draws a rig)."""

from __future__ import annotations

import math

import pytest

from lts360.experiments.design_check import check_rig
from lts360.scenes.rig_io import load_rig


@pytest.mark.slow  # one render + 3 measured draws (~20 s)
def test_check_rig_reports_model_and_simulation():
    r = check_rig(load_rig("paper"), draws=3, spp=4, seed=1)
    assert r["simulation"]["draws"] == 3
    lo, hi = r["simulation"]["sigma_R_95_um"]
    assert lo < r["simulation"]["sigma_R_um"] < hi
    for key in ("model_pixel", "model_dorsch"):
        assert math.isfinite(r[key]["sigma_R_um"]) and r[key]["coverage_deg"] > 359.0
    # per point: the pixel model against the render, loosely (3 draws, 4 spp)
    assert r["model_pixel"]["point_rms_um"] == pytest.approx(r["simulation"]["point_rms_um"],
                                                              rel=0.3)
