"""Plane perturbation, plane covariance and random calibrations (lts360.recon.calibration.uncertainty)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lts360.geometry.fit import fit_plane
from lts360.recon.calibration.uncertainty import (
    jackknife_covariance,
    perturb_plane,
    plane_covariance,
    plane_offset_abd,
    sample_calibration,
    tangent_basis,
)
from lts360.recon.model import calibration_from_frame_truth

unit = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(
    lambda v: np.linalg.norm(v) > 1e-3)


@given(unit)
def test_tangent_basis_is_orthonormal_and_right_handed(v):
    n = np.asarray(v) / np.linalg.norm(v)
    e1, e2 = tangent_basis(n)
    B = np.column_stack([e1, e2, n])
    np.testing.assert_allclose(B.T @ B, np.eye(3), atol=1e-12)
    assert np.linalg.det(B) == pytest.approx(1.0, abs=1e-12)


@settings(max_examples=50)
@given(unit, st.floats(-1e-3, 1e-3), st.floats(-1e-3, 1e-3), st.floats(-0.1, 0.1))
def test_perturb_then_measure_the_offset_round_trips(v, a, b, delta):
    n = np.asarray(v) / np.linalg.norm(v)
    n2, d2 = perturb_plane(n, -100.0, (a, b, delta))
    assert np.linalg.norm(n2) == pytest.approx(1.0)
    abd = plane_offset_abd(n, -100.0, n2, d2)
    # (a, b) come back to first order (normalisation shrinks them by cos of the angle).
    np.testing.assert_allclose(abd, [a, b, delta], atol=2e-6)


def test_plane_covariance_matches_the_scatter_of_refits():
    rng = np.random.default_rng(3)
    n0, d0 = np.array([0.1, -0.2, 0.97]), -150.0
    n0 /= np.linalg.norm(n0)
    e1, e2 = tangent_basis(n0)
    uv = rng.uniform(-10, 10, (200, 2))
    base = (d0 * n0) + uv[:, :1] * e1 + uv[:, 1:] * e2
    sigma = 0.01
    fits = []
    for _ in range(400):
        pts = base + rng.normal(0, sigma, (200, 1)) * n0
        f = fit_plane(pts)
        fits.append(plane_offset_abd(n0, d0, f.normal, f.offset_mm))
    emp = np.cov(np.array(fits).T)
    pts = base + rng.normal(0, sigma, (200, 1)) * n0
    f = fit_plane(pts)
    pred = plane_covariance(pts, f.normal, f.offset_mm)
    np.testing.assert_allclose(np.sqrt(np.diag(pred)), np.sqrt(np.diag(emp)), rtol=0.15)


def test_jackknife_needs_three_groups_and_gives_the_mean_variance():
    with pytest.raises(ValueError, match="3 groups"):
        jackknife_covariance(np.zeros((2, 3)))
    rng = np.random.default_rng(0)
    x = rng.normal(0, 1, (20, 3))
    loo = np.array([(x.sum(0) - xi) / 19 for xi in x])  # leave-one-out means
    # The jackknife variance of a mean is the classical s²/m.
    np.testing.assert_allclose(np.diag(jackknife_covariance(loo)), x.var(0, ddof=1) / 20, rtol=1e-9)


def _true_calibration():
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth

    rig = load_rig("paper")
    truth = rig_truth(rig, rig.camera.K, (rig.camera.width_px, rig.camera.height_px))
    return calibration_from_frame_truth(json.loads(json.dumps(truth, default=lambda v: v.tolist())))


def test_sample_calibration_draws_with_the_stored_spread_and_stays_valid():
    cal = _true_calibration()
    cov = np.diag([1e-4**2, 2e-4**2, 0.01**2])
    import dataclasses

    cal = dataclasses.replace(cal, uncertainty={
        "camera": {"std": {"fx": 0.5, "cx": 0.2}},
        "mirrors": {"left": {"cov_abd": cov.tolist()}},
        "laser_plane": {"cov_abd": cov.tolist()}})
    rng = np.random.default_rng(7)
    draws = [sample_calibration(cal, rng) for _ in range(400)]
    fx = np.array([c.K[0, 0] for c in draws])
    assert fx.std() == pytest.approx(0.5, rel=0.15)
    assert np.all([c.K[1, 1] == cal.K[1, 1] for c in draws])  # no σ given: fixed
    m = cal.mirror("left")
    d = np.array([c.mirror("left").d_mm for c in draws])
    assert d.std() == pytest.approx(0.01, rel=0.15)
    assert np.all([c.mirror("right").d_mm == cal.mirror("right").d_mm for c in draws])
    abd = np.array([plane_offset_abd(m.n, m.d_mm, c.mirror("left").n, c.mirror("left").d_mm)
                    for c in draws])
    assert abd[:, 1].std() == pytest.approx(2e-4, rel=0.15)
    for c in draws[:20]:  # every draw is a valid calibration: frame in the drawn laser plane
        n, dd = c.laser_plane
        assert abs(n @ c.T_cam_meas[:3, 3] - dd) < 1e-9
        corners = c.mirror("left").corners_mm
        assert np.abs(corners @ c.mirror("left").n - c.mirror("left").d_mm).max() < 1e-9


def test_a_camera_covariance_is_drawn_jointly():
    """``camera.cov`` (the jackknife's) wins over ``camera.std``: fx and fy move together."""
    import dataclasses

    cal = _true_calibration()
    cov = np.array([[0.25, 0.24, 0.0], [0.24, 0.25, 0.0], [0.0, 0.0, 0.04]])  # fx, fy, cy
    cal = dataclasses.replace(cal, uncertainty={"camera": {
        "std": {"fx": 5.0}, "cov": cov.tolist(), "cov_names": ["fx", "fy", "cy"]}})
    rng = np.random.default_rng(3)
    draws = [sample_calibration(cal, rng) for _ in range(600)]
    x = np.array([[c.K[0, 0], c.K[1, 1], c.K[1, 2], c.K[0, 2]] for c in draws])
    assert x[:, 0].std() == pytest.approx(0.5, rel=0.12)
    assert np.corrcoef(x[:, 0], x[:, 1])[0, 1] == pytest.approx(0.96, abs=0.02)
    assert x[:, 2].std() == pytest.approx(0.2, rel=0.12)
    assert np.all(x[:, 3] == cal.K[0, 2])  # cx not in the covariance: fixed
    bad = dataclasses.replace(cal, uncertainty={"camera": {"cov": np.eye(2).tolist(),
                                                           "cov_names": ["fx", "fy", "cy"]}})
    with pytest.raises(ValueError, match="cov must be"):
        sample_calibration(bad, rng)
