import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lts360.geometry import fit_circle, fit_plane


@given(seed=st.integers(0, 2**31 - 1))
def test_plane_fit_recovers_a_known_plane(seed):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    d = rng.uniform(-100, 100)
    basis = np.linalg.svd(n[None])[2][1:]
    pts = n * d + rng.uniform(-20, 20, (200, 2)) @ basis
    noise = rng.normal(0, 1e-3, 200)
    fit = fit_plane(pts + noise[:, None] * n)
    sign = np.sign(fit.normal @ n)
    # 200 points, σ = 1 µm: the normal is determined to ~1e-4 rad, the offset to ~1e-4 mm.
    assert np.degrees(np.arccos(min(1.0, sign * fit.normal @ n))) < 0.01
    assert abs(sign * fit.offset_mm - d) < 1e-3
    assert fit.rms_mm == pytest.approx(np.std(noise), rel=0.1)


def test_plane_fit_rejects_collinear_points():
    pts = np.outer(np.linspace(0, 10, 20), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="collinear"):
        fit_plane(pts)
    with pytest.raises(ValueError, match="at least 3"):
        fit_plane(pts[:2])


@given(seed=st.integers(0, 2**31 - 1))
def test_circle_fit_is_exact_on_noise_free_arcs(seed):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-5, 5, 2)
    r = rng.uniform(1, 30)
    start = rng.uniform(-np.pi, np.pi)
    theta = start + np.linspace(0, rng.uniform(0.5, 2 * np.pi), 50)
    pts = c + r * np.column_stack([np.cos(theta), np.sin(theta)])
    fit = fit_circle(pts)
    assert np.allclose(fit.center_mm, c, atol=1e-8)
    assert fit.radius_mm == pytest.approx(r, abs=1e-8)


def test_circle_fit_is_unbiased_under_noise():
    rng = np.random.default_rng(7)
    theta = rng.uniform(-np.pi, np.pi, 3600)
    pts = 9.99935 * np.column_stack([np.cos(theta), np.sin(theta)]) + rng.normal(0, 0.01, (3600, 2))
    fit = fit_circle(pts)
    # σ/√n ≈ 0.01/60 ≈ 0.17 µm; 1 µm is six standard errors.
    assert fit.radius_mm == pytest.approx(9.99935, abs=1e-3)
