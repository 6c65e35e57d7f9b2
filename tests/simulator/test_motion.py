"""Moving frames: a still object renders as today, a feed along a straight cylinder changes
nothing, the sub-frame count converges, and the per-view truth follows the shutter."""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the simulator needs Mitsuba 3")

from lts360.scenes.motion import Acquisition, Motion, Shutter  # noqa: E402
from lts360.scenes.objects import build_object  # noqa: E402
from lts360.scenes.rig_io import load_rig  # noqa: E402


@pytest.fixture(scope="module")
def variant():
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")


@pytest.fixture(scope="module")
def paper():
    return load_rig("paper")


def _stripe_rows(laser: np.ndarray) -> np.ndarray:
    """Per column with laser light, the intensity-weighted mean row (px)."""
    w = laser.sum(axis=0)
    cols = w > 0.05 * w.max()
    rows = np.arange(laser.shape[0])[:, None]
    return (laser * rows).sum(axis=0)[cols] / w[cols]


def test_a_still_object_renders_bit_identically(variant, paper):
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.motion import simulate_moving_frame

    obj = build_object("plug-gauge")
    a = simulate_frame(paper, obj, spp=2, seed=4, noise="realistic", scale=0.125,
                       exposure_time_s=5e-4)
    b = simulate_moving_frame(paper, obj, Acquisition(5e-4), spp=2, seed=4, noise="realistic",
                              scale=0.125)
    np.testing.assert_array_equal(a.image, b.image)
    assert b.truth["motion"]["renders"] == 1


def test_a_feed_along_a_straight_cylinder_changes_nothing(variant, paper):
    # Global shutter, 1 m/s over 1 ms: the section slides 1 mm along a straight gauge.
    from lts360.simulator.frame import simulate_frame
    from lts360.simulator.motion import simulate_moving_frame

    obj = build_object("plug-gauge")
    still = simulate_frame(paper, obj, spp=16, seed=1, scale=0.25, exposure_time_s=1e-3)
    acq = Acquisition(1e-3, motion=Motion(speed_mm_s=1000.0))
    moving = simulate_moving_frame(paper, obj, acq, spp=16, seed=1, scale=0.25, n_subframes=4)
    a, b = still.render.laser_W_m2_sr, moving.render.laser_W_m2_sr
    assert abs(b.sum() / a.sum() - 1.0) < 0.04  # Monte Carlo noise of 4 × 4 spp
    # The stripe stays where it was: mean row per column within 0.02 px on average.
    assert abs(np.mean(_stripe_rows(b) - _stripe_rows(a))) < 0.02
    m = moving.truth["motion"]
    assert m["subframes_per_exposure"] == 4 and m["renders"] == 4
    # Global shutter: every view's exposure is centred on the same instant.
    assert {round(v["t_mid_s"], 12) for v in m["views"].values()} == {5e-4}
    assert all(v["section_z_mm"] == pytest.approx(-0.5) for v in m["views"].values())


def test_rolling_shutter_views_are_exposed_at_their_rows_times(variant, paper):
    from lts360.simulator.motion import simulate_moving_frame

    obj = build_object("plug-gauge")
    line = 2e-5
    acq = Acquisition(1e-4, shutter=Shutter("rolling", line), motion=Motion(speed_mm_s=50.0))
    f = simulate_moving_frame(paper, obj, acq, spp=4, seed=0, scale=0.125)
    views = f.truth["motion"]["views"]
    assert set(views) == {"direct", "left", "right"}
    for v in views.values():
        assert v["t_mid_s"] == pytest.approx(v["row_mean_px"] * line + 5e-5)
        assert v["section_z_mm"] == pytest.approx(-50.0 * v["t_mid_s"])
    # The mirror views sit higher in the image than the direct view: exposed earlier.
    assert views["left"]["t_mid_s"] < views["direct"]["t_mid_s"]
    assert f.image.shape == (128, 160)


def test_the_chosen_subframe_count_is_converged(variant, paper):
    # A lateral vibration blurs the stripe during the exposure; the stripe's mean row with
    # the N chosen for 0.1 px steps is within 0.02 px of that with 4 N (same total samples).
    from lts360.simulator.motion import simulate_moving_frame, subframe_count

    obj = build_object("plug-gauge")
    acq = Acquisition(2e-3, motion=Motion(vibration_amplitude_mm=(0.4, 0.0),
                                          vibration_frequency_hz=200.0))
    n = subframe_count(paper, acq, 10.0, scale=0.125)
    assert n > 1
    rows = {}
    for k in (n, 4 * n):
        f = simulate_moving_frame(paper, obj, acq, spp=64, seed=3, scale=0.125, n_subframes=k)
        rows[k] = _stripe_rows(f.render.laser_W_m2_sr)
    assert abs(np.mean(rows[n] - rows[4 * n])) < 0.02


def test_a_feed_off_the_measured_zone_is_refused(variant, paper):
    from lts360.simulator.motion import simulate_moving_frame

    obj = build_object("plug-gauge")
    acq = Acquisition(1e-3, shutter=Shutter("rolling", 1e-3), motion=Motion(speed_mm_s=5000.0))
    with pytest.raises(ValueError, match="measured zone"):
        simulate_moving_frame(paper, obj, acq, spp=1, scale=0.125)
