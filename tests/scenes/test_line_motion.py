"""The line's motion, shutter and trigger: closed forms and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lts360.scenes.motion import Acquisition, Motion, Shutter, Trigger


def test_a_still_object_is_still():
    assert Motion().still
    assert Motion(vibration_amplitude_mm=(0.1, 0.0)).still  # no frequency: no motion
    assert not Motion(speed_mm_s=1.0).still
    np.testing.assert_array_equal(Motion().transform(0.3), np.eye(4))


def test_feed_vibration_and_rotation_in_closed_form():
    m = Motion(speed_mm_s=2000.0, vibration_amplitude_mm=(0.05, 0.02), vibration_frequency_hz=50.0,
               vibration_phase_deg=(0.0, 90.0), rotation_rate_deg_s=360.0)
    t = 0.0025  # an eighth of the vibration's period, 0.9° of rotation
    T = m.transform(t)
    w = 2 * math.pi * 50.0
    np.testing.assert_allclose(T[:3, 3], [0.05 * math.sin(w * t), 0.02 * math.cos(w * t), 5.0],
                               atol=1e-12)
    a = math.radians(0.9)
    np.testing.assert_allclose(T[:2, :2], [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]],
                               atol=1e-12)
    # The fastest point within 10 mm: feed + lateral peak speed + rotation at 10 mm.
    assert m.max_point_speed_mm_s(10.0) == pytest.approx(
        2000.0 + w * math.hypot(0.05, 0.02) + 2 * math.pi * 10.0)


def test_a_random_vibration_has_its_rms_and_correlation_and_is_seeded():
    """Over many seeds, x(t) has variance A² and corr(x(t), x(t + τ)) is the truncated
    Lorentzian's ∫ cos(2π f τ) L(f) df / ∫ L(f) df (≈ exp(−2π f_c τ)); one seed gives one path
    at any times; its speed stays within max_point_speed_mm_s."""
    from scipy.integrate import quad

    from lts360.scenes.motion import RANDOM_VIBRATION_CUTOFF

    fc, A, tau = 40.0, 0.08, 0.002
    paths = np.array([Motion(vibration_amplitude_mm=(A, A), vibration_frequency_hz=fc,
                             vibration_kind="random", vibration_seed=k).offset_mm([0.3, 0.3 + tau])
                      for k in range(1500)])  # (seeds, 2 times, 3)
    x0, x1 = paths[:, 0, :2].ravel(), paths[:, 1, :2].ravel()
    assert np.sqrt(np.mean(x0 ** 2)) == pytest.approx(A, rel=0.05)
    lor = lambda f: 1.0 / (1.0 + (f / fc) ** 2)  # noqa: E731
    top = RANDOM_VIBRATION_CUTOFF * fc
    expected = quad(lambda f: math.cos(2 * math.pi * f * tau) * lor(f), 0, top, limit=200)[0] \
        / quad(lor, 0, top)[0]
    assert np.mean(x0 * x1) / A ** 2 == pytest.approx(expected, abs=0.05)
    assert abs(expected - math.exp(-2 * math.pi * fc * tau)) < 0.1  # near the OU's
    m = Motion(vibration_amplitude_mm=(A, 0.02), vibration_frequency_hz=fc,
               vibration_kind="random", vibration_seed=7)
    t = np.linspace(0, 0.05, 2001)
    np.testing.assert_array_equal(m.offset_mm(t)[100], m.offset_mm([t[100]])[0])
    v = np.diff(m.offset_mm(t)[:, :2], axis=0) / np.diff(t)[:, None]
    assert np.hypot(*v.T).max() <= m.max_point_speed_mm_s(0.0)
    assert not m.still
    other = Motion(vibration_amplitude_mm=(A, 0.02), vibration_frequency_hz=fc,
                   vibration_kind="random", vibration_seed=8)
    assert not np.allclose(other.offset_mm(t), m.offset_mm(t))
    with pytest.raises(ValueError, match="vibration_kind"):
        Motion(vibration_kind="square")
    with pytest.raises(ValueError, match="vibration_seed"):
        Motion(vibration_kind="random", vibration_seed=-1)


def test_rolling_rows_start_one_line_time_apart():
    np.testing.assert_allclose(Shutter("rolling", 1e-5).row_start_s([0, 1, 100]), [0, 1e-5, 1e-3])
    np.testing.assert_array_equal(Shutter().row_start_s([0, 5]), [0.0, 0.0])
    acq = Acquisition(1e-4, shutter=Shutter("rolling", 1e-5))
    assert acq.readout_s(1024) == pytest.approx(1023e-5 + 1e-4)


def test_trigger_times_by_rate_and_by_encoder():
    np.testing.assert_allclose(Trigger(profile_rate_hz=200.0).times_s(3, 0.0), [0, 0.005, 0.01])
    # Encoder every 0.5 mm at 1 m/s: a pulse every 0.5 ms.
    np.testing.assert_allclose(Trigger(encoder_pitch_mm=0.5).times_s(3, 1000.0), [0, 5e-4, 1e-3])
    a = Trigger(profile_rate_hz=100.0, jitter_s=1e-5).times_s(50, 0.0, rng=3)
    b = Trigger(profile_rate_hz=100.0, jitter_s=1e-5).times_s(50, 0.0, rng=3)
    np.testing.assert_array_equal(a, b)  # seeded
    assert 0.5e-5 < np.std(a - np.arange(50) / 100.0) < 2e-5


@pytest.mark.parametrize("make, match", [
    (lambda: Acquisition(-1e-4), "exposure_time_s"),
    (lambda: Acquisition(0.0), "exposure_time_s"),
    (lambda: Shutter("rolling", 0.0), "line_time_s"),
    (lambda: Shutter("diagonal"), "global"),
    (lambda: Shutter("rolling", -1e-6), "line_time_s"),
    (lambda: Motion(vibration_amplitude_mm=(-1.0, 0.0)), "vibration_amplitude_mm"),
    (lambda: Motion(speed_mm_s=float("nan")), "speed_mm_s"),
    (lambda: Trigger(), "exactly one"),
    (lambda: Trigger(profile_rate_hz=-5.0), "profile_rate_hz"),
    (lambda: Trigger(profile_rate_hz=10.0, encoder_pitch_mm=1.0), "exactly one"),
    (lambda: Trigger(encoder_pitch_mm=1.0).times_s(3, 0.0), "moving"),
])
def test_bad_input_says_what_is_wrong(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_a_line_time_longer_than_the_frame_period_is_refused():
    acq = Acquisition(1e-4, shutter=Shutter("rolling", 1e-5), trigger=Trigger(profile_rate_hz=200.0))
    acq.check_frame(400)  # 4.1 ms < 5 ms
    with pytest.raises(ValueError, match="trigger period"):
        acq.check_frame(1024)  # 10.3 ms > 5 ms


@settings(max_examples=50, deadline=None)
@given(exposure_us=st.floats(1.0, 500.0), line_us=st.floats(0.0, 50.0), n_rows=st.integers(1, 300),
       n_sub=st.integers(1, 12))
def test_every_row_is_exposed_exactly_once(exposure_us, line_us, n_rows, n_sub):
    from lts360.simulator.motion import exposure_schedule

    shutter = Shutter("rolling", line_us * 1e-6) if line_us > 0 else Shutter()
    acq = Acquisition(exposure_us * 1e-6, shutter=shutter)
    mids, parts = exposure_schedule(acq, n_rows, n_sub)
    total = np.zeros(n_rows)
    start = shutter.row_start_s(np.arange(n_rows))
    for tm, (rows, w) in zip(mids, parts):
        np.add.at(total, rows, w)
        # A sub-interval's middle lies within (half a sub-interval of) each row's exposure.
        half = 0.5 * acq.exposure_time_s / n_sub
        assert np.all(tm >= start[rows] - half - 1e-12)
        assert np.all(tm <= start[rows] + acq.exposure_time_s + half + 1e-12)
    np.testing.assert_allclose(total, 1.0, atol=1e-9)
