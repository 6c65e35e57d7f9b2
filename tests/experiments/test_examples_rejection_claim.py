"""STUDIES.md "Examples": spurious points still valid ≤ 1 % on every object, with realistic
noise and the scan's own rejection pass (FLANK, NEIGHBOURS, the scan's 60 µm NOTCH, the convex
exemption of FADING), measured as ``lts360 study examples`` measures a scan.

Five sections from the middle of each scan instead of the paper's 40 (cable-6, the claim's
largest share: 0.86 %) and 20 (the grooved shaft, 0.64 %), at the paper's pitch: the middle
three have both neighbours, as every section of a long scan but its two ends. The limit is the
claim's; the floor on valid points keeps an emptied cloud from passing (0 ≤ 1 % of 0).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the scans render")

#: The claim: at most 1 % of the valid points spurious (truth-aware).
SPURIOUS_MAX = 0.01
SECTIONS = 5


def _scan(name: str, seed: int) -> tuple[dict, dict]:
    """Render ``SECTIONS`` sections at the paper's pitch about the middle of the measured
    zone, realistic noise, 16 spp; measure them as the examples study does, and again with no
    rejection; score both."""
    from lts360.experiments.examples_study import PAPER_EXAMPLES
    from lts360.experiments.score import score_cloud
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.measure import Section, measure_sections_following
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    obj = build_object(name)
    rig = load_rig("paper")
    pitch = PAPER_EXAMPLES[name][2]
    zs = float(np.mean(obj.measured_zone_z_mm)) + (np.arange(SECTIONS) - 2) * pitch
    sections, truth = [], None
    for k, z in enumerate(zs):
        frame = simulate_frame(rig, obj, z_mm=float(z), spp=16, seed=seed + k,
                               noise="realistic")
        if truth is None:
            truth = json.loads(json.dumps(frame.truth, default=lambda v: v.tolist()))
        sections.append(Section(Path(f"{name}-{k:03d}"), float(z), image=frame.image))
    cal = calibration_from_frame_truth(truth)
    scored = []
    for reject in (True, False):
        cloud, _, _ = measure_sections_following(sections, cal, theta_step_deg=0.2,
                                                 r_step_mm=0.01, reject=reject)
        scored.append(score_cloud(cloud, obj, rig_truth=truth))
    return scored[0], scored[1]


def _valid(m: dict) -> int:
    return m["n_points"] + m.get("n_spurious", 0)


# measured 2026-12-04 (valid / spurious still valid; rejected NOTCH, FLANK, NEIGHBOURS; with
# no rejection: valid / spurious): cable-6 6906 / 0; 2614, 0, 58; 11490 / 1229 (10.7 %)
# (full frames, the earlier speckle). Grooved shaft, pixel-support frames, keyed speckle:
# 7425 / 24 (0.32 %); 113, 0, 17; raw spurious 64. FLANK fires on this five-section scan in
# some realisations only (its middle section on a groove's flank, near the slope threshold):
# with the earlier speckle, full frames at seeds 0-5 gave 75, 0, 0, 0, 139, 0 points and a
# support frame at seed 2 gave 69; with the keyed speckle, 0 at seeds 0-5 on full and on
# support frames. It is not asserted here; tests/recon/triangulation/test_reject.py tests it.
@pytest.mark.slow  # five 16-spp frames per object, two measurements, the ray-cast score
@pytest.mark.parametrize("name, valid_measured, raw_spurious_measured, fired", [
    ("cable-6", 6906, 1229, ("notch", "neighbours")),
    ("grooved-shaft", 7425, 64, ("notch", "neighbours")),
])
def test_spurious_points_still_valid_stay_under_1_percent(name, valid_measured,
                                                          raw_spurious_measured, fired):
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    m, raw = _scan(name, seed=0)
    spurious, raw_spurious = m.get("n_spurious", 0), raw.get("n_spurious", 0)
    # 90 % of the valid points measured: room for a changed detector, not for a lost view
    assert _valid(m) >= 0.9 * valid_measured, _valid(m)
    for criterion in fired:  # the scan's own criteria are on, not only the one-frame ones
        assert m["rejected"][criterion] > 0, (criterion, m["rejected"])
    # what there is to reject (seeded renders: half the count measured), and the rejection
    # removes most of it
    assert raw_spurious >= 0.5 * raw_spurious_measured, raw_spurious
    assert spurious <= 0.5 * raw_spurious, (spurious, raw_spurious)
    assert spurious <= SPURIOUS_MAX * _valid(m), (spurious, _valid(m))
