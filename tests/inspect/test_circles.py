"""The four reference circles: closed forms, ISO's ordering, a brute-force minimum zone."""

import numpy as np
import pytest
from _profiles import polar

from lts360.geometry.fit import fit_circle
from lts360.inspect.circles import (
    least_squares_circle,
    maximum_inscribed_circle,
    minimum_circumscribed_circle,
    minimum_zone_circle,
    reference_circles,
)


def test_ls_circle_agrees_with_the_geometry_fit():
    rng = np.random.default_rng(1)
    xy = polar(lambda t: 7.0 + 0.01 * rng.normal(size=t.size), centre=(0.3, -0.2))
    ours, ref = least_squares_circle(xy), fit_circle(xy)
    assert ours.centre_mm == pytest.approx(ref.center_mm, abs=1e-10)  # both converged LS
    assert ours.radius_mm == pytest.approx(ref.radius_mm, abs=1e-10)


def test_three_lobes_about_the_true_centre():
    a = 0.02
    xy = polar(lambda t: 10.0 + a * np.cos(3 * t), centre=(1.0, 2.0))
    c = reference_circles(xy)
    for name in ("LSCI", "MZCI"):  # by symmetry both sit on the centre: RONt = 2a exactly
        assert c[name].centre_mm == pytest.approx([1.0, 2.0], abs=1e-7)
        assert c[name].ront_mm == pytest.approx(2 * a, abs=1e-7)  # MZ tolerance 1e-7 mm


def test_noisy_circle_obeys_the_iso_ordering():
    rng = np.random.default_rng(7)
    xy = polar(lambda t: 12.0 + 0.004 * rng.normal(size=t.size) + 0.003 * np.cos(5 * t),
               centre=(-0.4, 0.1), step_deg=0.5)
    c = reference_circles(xy)
    mz = c["MZCI"].ront_mm
    for name in ("LSCI", "MCCI", "MICI"):  # the minimum zone is the least peak-to-valley
        assert mz <= c[name].ront_mm + 1e-9
    ls = c["LSCI"]
    assert c["MCCI"].radius_mm <= ls.r_max_mm + 1e-9  # no circle holding the points is smaller
    assert c["MICI"].radius_mm >= ls.r_min_mm - 1e-4  # none inside is larger (MIC tol 1e-4)
    assert c["MICI"].radius_mm <= ls.radius_mm <= c["MCCI"].radius_mm
    d = np.hypot(*(xy - c["MCCI"].centre_mm).T)
    assert d.max() <= c["MCCI"].radius_mm + 1e-9  # it holds every point


def _brute_force_mz(xy, centre, half_mm, levels=5, n=41):
    """Nested grid search of the minimum-zone centre (the reference)."""
    best, c = np.inf, np.asarray(centre, float)
    for _ in range(levels):
        g = np.linspace(-half_mm, half_mm, n)
        X, Y = np.meshgrid(g + c[0], g + c[1])
        cand = np.column_stack([X.ravel(), Y.ravel()])
        r = np.hypot(xy[:, 0][None] - cand[:, :1], xy[:, 1][None] - cand[:, 1:])
        f = r.max(axis=1) - r.min(axis=1)
        k = int(np.argmin(f))
        if f[k] < best:
            best, c = f[k], cand[k]
        half_mm *= 4.0 / n
    return best


@pytest.mark.parametrize("seed", range(6))
def test_minimum_zone_matches_a_brute_force_search(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(40, 200))
    th = np.sort(rng.uniform(-np.pi, np.pi, n))
    k = rng.integers(2, 8)
    r = 5.0 + rng.uniform(0.005, 0.05) * np.cos(k * th + rng.uniform(0, 6)) \
        + 0.01 * rng.normal(size=n)
    xy = np.column_stack([r * np.cos(th), r * np.sin(th)]) + rng.normal(size=2) * 0.1
    mz = minimum_zone_circle(xy)
    ref = _brute_force_mz(xy, least_squares_circle(xy).centre_mm, 0.1)
    assert mz.ront_mm <= ref + 1e-8  # never worse than the search (float rounding)
    assert mz.ront_mm == pytest.approx(ref, abs=1e-6)  # the search's last grid: ~1e-8 mm


def test_mcc_and_mic_of_a_circle_are_the_circle():
    xy = polar(lambda t: np.full_like(t, 4.0), centre=(0.5, 0.5), step_deg=1.0)
    assert minimum_circumscribed_circle(xy).radius_mm == pytest.approx(4.0, abs=1e-9)
    mic = maximum_inscribed_circle(xy)
    assert mic.centre_mm == pytest.approx([0.5, 0.5], abs=2e-4)  # search tolerance 1e-4
    assert mic.ront_mm < 1e-3


def test_too_few_points_is_a_clear_error():
    with pytest.raises(ValueError, match="at least 3 finite points"):
        least_squares_circle(np.zeros((2, 2)))


def test_the_filter_lowers_the_roundness_of_point_noise():
    from lts360.inspect.section import analyse_section

    rng = np.random.default_rng(2)
    xy = polar(lambda t: 10.0 + 0.02 * np.cos(3 * t) + 0.01 * rng.normal(size=t.size))
    raw = analyse_section(xy).circles["MZCI"].ront_mm
    filt = analyse_section(xy, filter_upr=50).circles["MZCI"].ront_mm
    assert filt < raw and filt == pytest.approx(0.04, abs=0.005)  # the 3 lobes survive
