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
