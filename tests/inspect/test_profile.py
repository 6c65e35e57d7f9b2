import numpy as np
import pytest

from lts360.inspect.profile import coverage_deg, gaps, valid_mask
from lts360.recon.triangulation.peaks import Quality


def test_valid_means_finite_and_an_accepted_quality():
    pts = np.array([[1.0, 0, 0], [np.nan, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    q = np.array([Quality.FOUND, Quality.NO_PEAK, Quality.SATURATED, Quality.SEVERAL_PEAKS])
    assert valid_mask(pts, q).tolist() == [True, False, True, False]


def test_gaps_are_named_by_their_flags():
    th = np.radians(np.arange(-180, 180, 0.1))
    hole = (th > np.radians(10)) & (th < np.radians(20))
    g = gaps(th[~hole], theta_invalid_rad=th[hole],
             quality_invalid=np.full(hole.sum(), int(Quality.OUTSIDE_WINDOW)))
    assert len(g) == 1
    assert g[0].start_deg == pytest.approx(10.0, abs=0.11)
    assert g[0].width_deg == pytest.approx(10.0, abs=0.2)
    assert g[0].flags == {"OUTSIDE_WINDOW": int(hole.sum())}
    assert coverage_deg(th[~hole]) == pytest.approx(350.0, abs=0.6)


def test_the_gaussian_filter_transmits_as_iso_16610_21():
    from lts360.inspect.profile import bin_profile, gaussian_filter

    th = np.radians(np.arange(-180, 180, 0.5))
    for k, gap in ((5, False), (50, False), (15, True)):
        r = 10 + 0.01 * np.cos(k * th)
        keep = ~((th > 1.0) & (th < 1.2)) if gap else np.ones(th.size, bool)
        xy = np.column_stack([r * np.cos(th), r * np.sin(th)])[keep]
        f = gaussian_filter(bin_profile(xy, (0.0, 0.0)), 50)
        amp = 0.5 * np.ptp(f.r_mm)
        H = np.exp(-np.pi * (np.sqrt(np.log(2) / np.pi) * k / 50) ** 2)
        if gap:  # the normalised convolution near a gap: within a few % of the transmission
            assert amp == pytest.approx(0.01 * H, rel=0.05)
            inside = (f.theta_rad > 1.0) & (f.theta_rad < 1.2)
            assert not inside.any()  # the gap is not filled in
            assert len(f.r_mm) >= keep.sum() - 2  # only the grid directions at its edges go
        else:
            assert amp == pytest.approx(0.01 * H, rel=1e-3)  # 50 % at the cut-off, k = 50
    assert H == pytest.approx(0.5 ** ((15 / 50) ** 2), rel=1e-12)
