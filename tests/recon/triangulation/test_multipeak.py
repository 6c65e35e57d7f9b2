"""The choice between several lines along a radial direction
(lts360.recon.triangulation.multipeak): on synthetic profiles, and on a synthetic gauge image
with a secondary stripe 0.6 mm inside the section over part of the turn."""

import numpy as np
import pytest
from test_inverse import R_GAUGE_MM, synthesize_section

from lts360.recon.model import calibration_from_dict
from lts360.recon.triangulation.grid import CylGrid
from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse
from lts360.recon.triangulation.multipeak import (
    MultiPeakTolerances,
    _main_runs,
    choose_peaks,
    choose_run,
    profile_runs,
)
from lts360.recon.triangulation.peaks import Quality, centroid
from lts360.scenes.rig_io import load_rig
from lts360.simulator.io import rig_truth


def _line(x, at, amp, sigma=2.0):
    return amp * np.exp(-0.5 * ((x - at) / sigma) ** 2)


def test_profile_runs_finds_every_run_and_the_detectors_centroid():
    x = np.arange(200, dtype=float)
    prof = np.stack([_line(x, 60.3, 100) + _line(x, 140.7, 40),   # two runs
                     _line(x, 100.0, 80),                           # one
                     np.zeros(200),                                 # none
                     _line(x, 1.0, 90) + _line(x, 120.0, 30)])      # the first cut by the end
    prof[3, 150] = np.nan
    row, start, stop, centre, peak, cut = profile_runs(prof, 10.0)
    assert row.tolist() == [0, 0, 1, 3, 3]
    assert np.all(stop > start)
    # The strongest run's centroid is the detector's (thresholded weights).
    ref = centroid(prof, x, threshold=10.0, max_plateau_mm=None).r_mm
    np.testing.assert_allclose(centre[[0, 2]], ref[:2], atol=1e-9)
    alone = centroid(_line(x, 140.7, 40)[None], x, threshold=10.0, max_plateau_mm=None).r_mm
    np.testing.assert_allclose(centre[1], alone[0], atol=1e-9)
    assert peak[0] == prof[0].max() and peak[1] == prof[0, 100:].max() and peak[2] == prof[1].max()
    assert cut.tolist() == [False, False, False, True, False]
    # each row's strongest run: the one the detector measured
    assert _main_runs(row, peak).tolist() == [True, False, True, True, False]


def test_choose_run_takes_the_line_the_neighbours_agree_with():
    tol = MultiPeakTolerances()
    # rows: 0 the weak run agrees; 1 both agree within the margin (ambiguous); 2 no
    # reference; 3 a line split by a dark grain (two runs 0.05 mm apart) and a far one;
    # 4 the agreeing run is cut by the band's end; 5 nothing within match_mm.
    run_row = np.array([0, 0, 1, 1, 2, 2, 3, 3, 3, 4, 4, 5, 5])
    run_r = np.array([9.4, 10.01, 10.0, 10.2, 9.4, 10.0, 10.0, 10.05, 9.3, 10.0, 9.4,
                      9.5, 10.4])
    cut = np.zeros(run_r.size, bool)
    cut[9] = True
    ref = np.array([10.0, 10.0, np.nan, 10.0, 10.0, 10.0])
    chosen = choose_run(run_row, run_r, cut, ref, n_rows=6, tol=tol)
    assert chosen.tolist() == [1, -1, -2, 6, -1, -1]


def test_bad_tolerances():
    for kw in ({"fraction": 0.0}, {"match_mm": 0.0}, {"margin_mm": -1.0},
               {"min_reference": 0}, {"same_line_mm": -0.1}):
        with pytest.raises(ValueError):
            MultiPeakTolerances(**kw)


@pytest.fixture(scope="module")
def case():
    rig = load_rig("paper")
    cal = calibration_from_dict(rig_truth(rig, rig.camera.K, rig.camera.image_size))
    grid = CylGrid.from_ranges((R_GAUGE_MM - 2.0, R_GAUGE_MM + 2.0), theta_step_deg=0.25)
    primary, _ = synthesize_section(rig, R_GAUGE_MM)
    inner, _ = synthesize_section(rig, R_GAUGE_MM - 0.6, amp=1.0)
    # the secondary stripe over a band of image columns only: a stretch of each view's turn
    h, w = primary.shape
    cols = (np.arange(w) > 0.45 * w) & (np.arange(w) < 0.55 * w)
    inner = inner * cols[None, :]
    return cal, grid, plan_inverse(cal, grid, precompute=False), primary, inner


def _run(case, amp):
    cal, grid, plan, primary, inner = case
    img = primary + amp * inner
    before = inverse_triangulate(img, cal, grid, plan=plan)
    return img, before, choose_peaks(before, img, plan)


def _off(res, mm):
    return sum(int(np.sum(np.abs(v.r_mm[v.valid] - R_GAUGE_MM) > mm))
               for v in res.views.values())


def _valid(res):
    return sum(int(v.valid.sum()) for v in res.views.values())


def test_a_brighter_secondary_stripe_is_not_taken_for_the_line(case):
    _, before, after = _run(case, 2.5 * 200.0)  # the secondary 2.5 x the primary
    assert _off(before, 0.3) > 20               # the detector took it: 0.6 mm inside
    assert _off(after, 0.02) == 0               # the choice takes the section's line
    # and keeps those rows as points, as many as without the secondary stripe
    free = inverse_triangulate(case[3], case[0], case[1], plan=case[2])
    assert _valid(after) >= _valid(free) - 5


def test_a_comparable_secondary_stripe_gives_points_back(case):
    _, before, after = _run(case, 1.2 * 200.0)  # today: SEVERAL_PEAKS, no point
    several = sum(int(np.sum(v.quality == Quality.SEVERAL_PEAKS)) for v in before.views.values())
    assert several > 20
    assert _valid(after) >= _valid(before) + several - 5
    assert _off(after, 0.02) == 0


def test_a_weak_secondary_stripe_changes_nothing(case):
    _, before, after = _run(case, 0.3 * 200.0)
    for name, v in before.views.items():
        assert np.array_equal(v.quality, after.views[name].quality)
        np.testing.assert_array_equal(v.r_mm, after.views[name].r_mm)


def test_two_lines_everywhere_have_no_reference_and_stay_as_detected(case):
    cal, grid, plan, primary, _ = case
    inner, _ = synthesize_section(load_rig("paper"), R_GAUGE_MM - 0.6)
    img = primary + inner  # both at the same strength on the whole turn
    before = inverse_triangulate(img, cal, grid, plan=plan)
    after = choose_peaks(before, img, plan)
    for name, v in before.views.items():
        assert np.array_equal(v.quality, after.views[name].quality)
