"""``design check --pipeline``'s split of the errors (seeds × placements): closed forms on
hand-made numbers, and the split recovering known within- and between-seed σ over many
synthetic draws."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lts360.experiments import design_pipeline as P


def test_components_closed_form():
    errs = [np.array([1.0, 3.0]), np.array([-1.0, 1.0, np.nan]), np.array([4.0, 6.0])]
    c = P.components(errs, master_um=[1.5, -0.5, 5.0])
    # within: each pair deviates ±1 from its mean → Σ squares 2+2+2 over 3 dof
    assert c["within_dof"] == 3
    assert c["within_sd_um"] == pytest.approx(math.sqrt(6 / 3), rel=1e-12)
    means = np.array([2.0, 0.0, 5.0])
    assert c["means_um"] == pytest.approx(means.tolist())
    assert c["means_sd_um"] == pytest.approx(np.std(means, ddof=1), rel=1e-12)
    assert c["between_sd_um"] == pytest.approx(
        math.sqrt(np.var(means, ddof=1) - 2.0 / 2.0), rel=1e-12)
    d = means - np.array([1.5, -0.5, 5.0])
    assert c["mean_minus_master_sd_um"] == pytest.approx(np.std(d, ddof=1), rel=1e-12)
    lo, hi = c["means_sd_95_um"]
    # χ² with 2 degrees of freedom: 0.0506 and 7.378 at 2.5 % and 97.5 %
    assert hi / c["means_sd_um"] == pytest.approx(math.sqrt(2 / 0.05064), rel=1e-3)
    assert lo / c["means_sd_um"] == pytest.approx(math.sqrt(2 / 7.3778), rel=1e-3)


def test_between_is_zero_when_the_means_scatter_less_than_the_noise():
    c = P.components([np.array([0.0, 2.0]), np.array([0.1, 2.1])])
    assert c["between_sd_um"] == 0.0


def test_model_components():
    model = {"noise_um": 0.5, "compensation_um": 0.4, "calibration_um": 0.3}
    mc = P._model_components(model, 5)
    assert mc["within_sd_um"] == 0.5
    assert mc["between_sd_um"] == pytest.approx(0.5, rel=1e-12)
    assert mc["means_sd_um"] == pytest.approx(math.sqrt(0.25 + 0.25 / 5), rel=1e-12)
    assert mc["mean_minus_master_sd_um"] == pytest.approx(0.5 / math.sqrt(5), rel=1e-12)


def test_the_split_recovers_known_sigmas():
    """Seeds with a shared master error (σ_b = 0.6) and placements with their own (σ_w = 0.4):
    over 400 runs of 5 seeds × 5 placements the split's variances average to σ_w², σ_b² and
    σ_w²/5 (the seeds' means less their masters' parts), within 6 %."""
    rng = np.random.default_rng(7)
    sw, sb, runs = 0.4, 0.6, 400
    w2, b2, mm2 = [], [], []
    for _ in range(runs):
        master = rng.normal(0.0, sb, 5)
        errs = [m + rng.normal(0.0, sw, 5) for m in master]
        c = P.components(errs, master_um=master)
        w2.append(c["within_sd_um"] ** 2)
        b2.append(c["means_sd_um"] ** 2 - c["within_sd_um"] ** 2 / 5)
        mm2.append(c["mean_minus_master_sd_um"] ** 2)
    assert np.mean(w2) == pytest.approx(sw ** 2, rel=0.06)
    assert np.mean(b2) == pytest.approx(sb ** 2, rel=0.06)
    assert np.mean(mm2) == pytest.approx(sw ** 2 / 5, rel=0.06)
