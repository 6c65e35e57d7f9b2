"""STUDIES.md "Line-centre bias and the digital twin": at 64 spp the twin removes the gauge's
line-centre bias to |b| ≤ 1.45 µm at every diameter and placement (the headline; ≤ 1.35 µm in
the 64-spp table, ≤ 1.45 µm as the mean of five 16-spp renders).

Three of the 16 cases, rendered exactly as the table's run renders them (``lts360 study bias
--placements-mm 0:0,3:0,0:-3,-4:4 --spp 64``, root seed 0: the same trial seeds), the hardest
first: Ø6 mm 5.7 mm off the axis at (−4, 4). The limit is the claim's, not the value measured.
"""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the twin renders")

#: The study's plan: diameters × placements, in the order the table's run made its trials.
DIAMETERS_MM = (6.0, 12.0, 20.0, 28.0)
PLACEMENTS_MM = ((0.0, 0.0), (3.0, 0.0), (0.0, -3.0), (-4.0, 4.0))
#: The claim: |twin-corrected radius bias| ≤ 1.45 µm.
BIAS_MAX_UM = 1.45
#: The claim at 64 spp: the views' mean errors within 3.6 µm of each other.
SPREAD_MAX_UM = 3.6


def _trial(diameter_mm, placement_mm):
    from lts360.experiments.runner import plan_trials

    params = [{"diameter_mm": float(d), "x_mm": float(x), "y_mm": float(y), "spp": 64,
               "twin_spp": 64, "noise": "none", "rig": "paper", "variant": ""}
              for d in DIAMETERS_MM for x, y in PLACEMENTS_MM]
    i = DIAMETERS_MM.index(diameter_mm) * len(PLACEMENTS_MM) + PLACEMENTS_MM.index(placement_mm)
    return plan_trials(params, 0)[i]


# measured 2026-12-04 (bias as measured → twin-corrected, µm; views' spread): Ø6 (−4, 4)
# −11.94 → −1.35, 1.99; Ø6 (3, 0) −11.49 → +0.89, 2.74 (the table: +1.13); Ø12 (−4, 4)
# −6.03 → +0.54, 0.54
@pytest.mark.slow  # a 64-spp full frame and its twin per case (~1–2 min on 2 cores)
@pytest.mark.parametrize("diameter_mm, placement_mm", [(6.0, (-4.0, 4.0)), (6.0, (3.0, 0.0)),
                                                       (12.0, (-4.0, 4.0))],
                         ids=["d6-(-4,4)", "d6-(3,0)", "d12-(-4,4)"])
def test_the_twin_removes_the_bias_to_the_claimed_limit(diameter_mm, placement_mm):
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.bias_study import bias_trial

    v = bias_trial(_trial(diameter_mm, placement_mm)).values
    assert v["n_valid"] > 4000  # the whole section (4200–4650 points about its own centre)
    # what there is to correct: −11…−13 µm at Ø6 mm, −6…−7 µm at Ø12 mm
    assert v["bias_plain_um"] < -5.0, v["bias_plain_um"]
    assert abs(v["bias_twin_um"]) <= BIAS_MAX_UM, v["bias_twin_um"]
    views = np.asarray(v["view_twin_um"], float)
    assert np.all(np.isfinite(views)) and np.ptp(views) <= SPREAD_MAX_UM, views
