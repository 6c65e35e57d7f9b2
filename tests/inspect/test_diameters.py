"""Two-point diameters, calliper widths and ovality on profiles with known answers."""

import numpy as np
import pytest
from _profiles import constant_width, ellipse, polar

from lts360.inspect.circles import least_squares_circle
from lts360.inspect.diameters import calliper_widths, diameters
from lts360.inspect.profile import bin_profile


def _dia(xy, bin_deg=0.5):
    return diameters(bin_profile(xy, least_squares_circle(xy).centre_mm, bin_deg=bin_deg))


def test_ellipse_ovality_exact():
    a, b = 10.4, 9.6
    d = _dia(ellipse(a, b, centre=(0.2, -0.1)), bin_deg=0.1)  # one point per bin: no averaging
    assert d.d_max_mm == pytest.approx(2 * a, abs=1e-9)
    assert d.d_min_mm == pytest.approx(2 * b, abs=1e-9)
    assert d.ovality_mm == pytest.approx(2 * (a - b), abs=1e-9)
    assert d.phi_d_max_deg == pytest.approx(0.0) and d.phi_d_min_deg == pytest.approx(90.0)
    assert d.ovality_over_sum_pct == pytest.approx(100 * (a - b) / (a + b), abs=1e-8)
    assert d.ovality_over_mean_pct == pytest.approx(100 * 2 * (a - b) / d.d_mean_mm, abs=1e-12)
    # Feret widths of an ellipse are 2a and 2b too
    assert (d.calliper_min_mm, d.calliper_max_mm) == pytest.approx((2 * b, 2 * a), abs=1e-9)


def test_ellipse_with_the_default_bins_is_within_their_averaging():
    a, b = 10.4, 9.6
    d = _dia(ellipse(a, b))
    # 0.5° bins average r over ±0.2°: bias ½·r″·var(θ) ≈ 5.5e-6 mm per radius at the axes
    assert d.ovality_mm == pytest.approx(2 * (a - b), abs=3e-5)


def test_three_lobes_have_a_constant_two_point_diameter():
    xy = polar(lambda t: 10.0 + 0.05 * np.cos(3 * t))
    d = _dia(xy)
    assert d.ovality_mm == pytest.approx(0.0, abs=1e-9)  # odd orders cancel across the centre
    assert d.d_mean_mm == pytest.approx(20.0, abs=1e-9)


def test_constant_width_curve_has_one_calliper_width():
    xy = constant_width(10.0, 0.08)
    _, w = calliper_widths(xy)
    assert np.ptp(w) < 1e-6  # the support function's width 2R; chords of 0.1° sample it
    assert w.mean() == pytest.approx(20.0, abs=1e-6)


def test_a_gap_leaves_its_directions_without_a_diameter():
    xy = polar(lambda t: np.full_like(t, 5.0))
    th = np.arctan2(xy[:, 1], xy[:, 0])
    keep = ~((th > np.radians(40)) & (th < np.radians(50)))
    d = _dia(xy[keep])
    missing = d.phi_rad[~np.isfinite(d.d_mm)]
    assert missing.size > 0 and np.all((missing > np.radians(39)) & (missing < np.radians(51)))
    assert d.n_directions_measured == np.isfinite(d.d_mm).sum()
