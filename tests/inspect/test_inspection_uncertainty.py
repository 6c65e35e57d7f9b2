"""Uncertainty: the re-triangulation round trip, the calibration Monte Carlo, the scatter
component against the spread of repeated noisy sections."""

import dataclasses

import numpy as np
import pytest
from _profiles import polar

from lts360.inspect.section import analyse_section
from lts360.inspect.uncertainty import calibration_u, retriangulate, scatter_u


@pytest.fixture(scope="module")
def cal():
    from lts360.recon.model import calibration_from_dict
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth

    rig = load_rig("paper")
    return calibration_from_dict(rig_truth(rig, rig.camera.K, rig.camera.image_size))


def _views(xy):
    th = np.degrees(np.arctan2(xy[:, 1], xy[:, 0]))
    return np.where(th < -30, "direct", np.where(th < 90, "right", "left"))


def test_retriangulating_with_the_same_calibration_is_the_identity(cal):
    xy = polar(lambda t: np.full_like(t, 10.0), step_deg=1.0)
    back = retriangulate(xy, _views(xy), cal, cal)
    assert back == pytest.approx(xy, abs=1e-9)  # projection and ray ∩ plane invert each other


def test_calibration_monte_carlo(cal):
    xy = polar(lambda t: np.full_like(t, 10.0), step_deg=0.5)
    assert calibration_u([xy], [_views(xy)], cal) is None  # no covariance: no component
    unc = {"laser_plane": {"cov_abd": np.diag([1e-8, 1e-8, 1e-4]).tolist()}}  # δ: 10 µm
    noisy = dataclasses.replace(cal, uncertainty=unc)
    u = calibration_u([xy, xy], [_views(xy)] * 2, noisy, n_draws=12, seed=3)
    assert len(u) == 2 and u[0] == u[1]  # the same points give the same u
    # A plane offset δ moves each view's points along its own viewing direction in the plane
    # by δ·cot α (α = 40°: 11.9 µm for δ = 10 µm); the three views face the section from
    # different sides, so their arcs move apart or together and D changes by about
    # 2 δ cot α = 24 µm (measured: 19–28 µm over seeds 3, 4); 12 draws give u to ±20 %.
    assert 0.012 < u[0]["d_ls_mm"] < 0.040
    # linear in δ: twice the offset (the same seed, so the same normal draws) twice the u
    unc2 = {"laser_plane": {"cov_abd": np.diag([4e-8, 4e-8, 4e-4]).tolist()}}
    u2 = calibration_u([xy], [_views(xy)], dataclasses.replace(cal, uncertainty=unc2),
                       n_draws=12, seed=3)
    assert u2[0]["d_ls_mm"] == pytest.approx(2 * u[0]["d_ls_mm"], rel=0.02)  # 2nd order
    again = calibration_u([xy], [_views(xy)], noisy, n_draws=12, seed=3)
    assert again[0] == u[0]  # seeded


def test_scatter_u_of_the_ls_diameter_matches_repeated_sections():
    rng = np.random.default_rng(5)
    sigma = 0.003
    d, us = [], []
    for _ in range(30):
        s = analyse_section(polar(lambda t: 10.0 + sigma * rng.normal(size=t.size)))
        d.append(s.ls.diameter_mm)
        us.append(scatter_u(s.scatter_mm, s.n_valid, s.points_per_bin)["d_ls_mm"])
    assert np.mean(us) == pytest.approx(2 * sigma / np.sqrt(3600), rel=0.05)
    # 30 repeats: the sample std is within ±40 % of the true one (chi, 29 dof, > 99 %)
    assert np.std(d, ddof=1) == pytest.approx(np.mean(us), rel=0.4)


def test_correlated_mean_u_counts_runs_of_correlated_bins():
    """AR(1) bin errors (ρ = 0.6): τ = (1 + ρ)/(1 − ρ) = 4 through the form's moving average,
    and u(r̄) is the spread of the mean radius over realisations; white bins give τ ≈ 1 and
    σ/√N; a smooth form (an oval, three lobes) is not counted as noise."""
    from lts360.inspect.uncertainty import correlated_mean_u

    rng = np.random.default_rng(11)
    n, rho, sigma = 720, 0.6, 0.005
    th = np.linspace(-np.pi, np.pi, n, endpoint=False)
    form = 0.02 * np.cos(2 * th) + 0.01 * np.sin(3 * th)
    means, us, taus = [], [], []
    for _ in range(300):
        e = np.empty(n)
        e[0] = rng.normal(0, sigma)
        w = rng.normal(0, sigma * np.sqrt(1 - rho ** 2), n)
        for k in range(1, n):
            e[k] = rho * e[k - 1] + w[k]
        u, tau, s_bin = correlated_mean_u(th, 10.0 + form + e, 10.0)
        means.append(e.mean())
        us.append(u)
        taus.append(tau)
    assert np.median(taus) == pytest.approx(4.0, rel=0.15)
    assert np.median(us) == pytest.approx(np.std(means), rel=0.2)
    white = rng.normal(0, sigma, n)
    u, tau, s_bin = correlated_mean_u(th, 10.0 + form + white, 10.0)
    assert tau < 1.3 and u == pytest.approx(sigma / np.sqrt(n), rel=0.2)
    assert s_bin == pytest.approx(sigma, rel=0.1)
    assert np.isnan(correlated_mean_u(th[:10], np.full(10, 10.0), 10.0)[0])
