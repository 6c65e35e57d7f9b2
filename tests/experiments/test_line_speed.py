"""The line-speed study: closed forms (lumps missed, undoing the motion) and end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lts360.experiments.line_speed import _object_frame_points, _robust, lumps_missed
from lts360.scenes.motion import Motion


def test_lumps_missed_in_closed_form():
    # Sections every 5 mm (1 m/s at 200 /s): a 2 mm lump is missed 60 % of the time.
    assert lumps_missed(1000.0, 200.0, 2.0) == pytest.approx(0.6)
    assert lumps_missed(1000.0, 200.0, 6.0) == 0.0  # longer than the spacing: always seen
    assert lumps_missed(0.0, 200.0, 1.0) == 0.0  # a still object: every section on it
    np.testing.assert_allclose(lumps_missed([100.0, 400.0], 100.0, [[0.5], [2.0]]),
                               [[0.5, 0.875], [0.0, 0.5]])


@settings(max_examples=40, deadline=None)
@given(t=st.floats(0.0, 0.02), v=st.floats(-2000.0, 2000.0), w=st.floats(-720.0, 720.0),
       a=st.floats(0.0, 0.5), f=st.floats(0.0, 300.0))
def test_undoing_the_motion_recovers_the_object_point(t, v, w, a, f):
    m = Motion(speed_mm_s=v, vibration_amplitude_mm=(a, 0.5 * a), vibration_frequency_hz=f,
               rotation_rate_deg_s=w)
    T_placed = np.eye(4)
    T_placed[:3, 3] = [0.3, -0.2, 1.0]
    q = np.array([[9.0, 1.0, 2.0], [-3.0, 8.0, -1.0]])
    world = (q @ T_placed[:3, :3].T + T_placed[:3, 3])
    T = m.transform(t)
    world = world @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(_object_frame_points(world, np.full(2, t), m, T_placed), q,
                               atol=1e-9)


def test_robust_error_ignores_a_few_gross_points():
    rng = np.random.default_rng(0)
    e = np.concatenate([rng.normal(0.002, 0.010, 2000), np.full(60, 0.4)])  # 3 % at 400 µm
    med, spread, rms = _robust(e)
    assert med == pytest.approx(0.002, abs=0.001)
    assert spread == pytest.approx(0.010, rel=0.1)
    assert np.isnan(_robust(np.zeros(0))[2])


@pytest.mark.slow
def test_line_speed_study_end_to_end(tmp_path):
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.line_speed import run_line_speed_study

    # A gauge tilted by 10° feeding at 500 mm/s; 40 µs per row of the quarter-scale image
    # (10 ms per frame, as 10 µs on the full one): its views are exposed ~3 ms apart.
    table = run_line_speed_study(tmp_path, objects=("plug-gauge:d=20,tilt_deg=10",),
                                 speeds_mm_s=(0.0, 500.0), shutters=("global", "rolling"),
                                 line_time_us=40.0, scale=0.25, spp=4)
    rows = {(r["shutter"], r["speed_mm_s"]): r for r in table["rows"]}
    # Still: the two shutters render the same frame (same seed), so the same errors.
    assert rows[("global", 0.0)]["rms_instant_mm"] == rows[("rolling", 0.0)]["rms_instant_mm"]
    # A global shutter exposes every row at once: row-aware is the one instant.
    g = rows[("global", 500.0)]
    assert g["rms_instant_mm"] == g["rms_rows_mm"]
    # A rolling shutter: the views, seen ~3 ms apart, hold a section moved by ~0.26 mm; taken
    # as one instant they are far off, row-aware they are not.
    r = rows[("rolling", 500.0)]
    assert r["rms_instant_mm"] > r["rms_rows_mm"] + 0.05
    # The frozen frame (same sub-frames, object held still) has the still frame's error level,
    # so the rolling shutter's excess is the motion's: the largest speed within 20 µm is 0.
    assert r["rms_frozen_mm"] < 0.5 * r["rms_instant_mm"]
    assert rows[("global", 0.0)]["rms_frozen_mm"] == rows[("global", 0.0)]["rms_instant_mm"]
    limits = {L["shutter"]: L["largest_speed_mm_s"] for L in table["largest_speed"]}
    assert limits["rolling"] == 0.0
    for name in ("table.json", "table.txt", "line-speed.png", "trials/results.nc"):
        assert (tmp_path / name).is_file()
    assert json.loads((tmp_path / "table.json").read_text())["lumps"]["p_missed"]
