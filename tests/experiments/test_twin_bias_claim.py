"""STUDIES.md "Line-centre bias and the digital twin": at 64 spp the twin removes the gauge's
line-centre bias, its expected value (the mean over renders: the render noise averaged out)
to |b| ≤ 1.5 µm, and the views' expected mean errors to within 3.6 µm of each other.

Three of the 16 cases, rendered exactly as the table's run renders them (``lts360 study bias
--placements-mm 0:0,3:0,0:-3,-4:4 --spp 64``, the trial seeds of root seeds 0–7), the hardest
first: Ø6 mm 5.7 mm off the axis at (−4, 4), and the case whose views spread most. One render is
one realisation of the render noise: a single 64-spp frame's views' spread ranged 0.6–4.0 µm at
Ø6 mm (3, 0) over these eight seeds, above 3.6 µm in 3 of 8, so the claim and this test are on
the mean of eight renders. The limits are the claim's, not the values measured.
"""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="the twin renders")

#: The study's plan: diameters × placements, in the order the table's run made its trials.
DIAMETERS_MM = (6.0, 12.0, 20.0, 28.0)
PLACEMENTS_MM = ((0.0, 0.0), (3.0, 0.0), (0.0, -3.0), (-4.0, 4.0))
#: The study's root seeds rendered per case.
ROOT_SEEDS = tuple(range(8))
#: The claim: |expected twin-corrected radius bias| ≤ 1.5 µm.
BIAS_MAX_UM = 1.5
#: The claim at 64 spp: the views' expected mean errors within 3.6 µm of each other.
SPREAD_MAX_UM = 3.6


def _trial(diameter_mm, placement_mm, root_seed):
    from lts360.experiments.runner import plan_trials

    params = [{"diameter_mm": float(d), "x_mm": float(x), "y_mm": float(y), "spp": 64,
               "twin_spp": 64, "noise": "none", "rig": "paper", "variant": ""}
              for d in DIAMETERS_MM for x, y in PLACEMENTS_MM]
    i = DIAMETERS_MM.index(diameter_mm) * len(PLACEMENTS_MM) + PLACEMENTS_MM.index(placement_mm)
    return plan_trials(params, root_seed)[i]


# measured 2026-12-04 on pixel-support frames (code of da7e6d5), root seeds 0–7: twin-corrected
# bias, mean ± sd of the eight (standard error), µm; the views' mean errors averaged over the
# eight, direct / left / right, and their spread; the mean of the eight renders' own spreads
# (range; how many above 3.6 µm):
#   Ø6 (−4, 4):  −1.46 ± 0.26 (0.09); −0.76 / −0.63 / −2.67, 2.04; 2.34 (1.42–3.63; 1)
#   Ø6 (3, 0):   +0.53 ± 0.31 (0.11); −0.78 / +0.14 / +1.77, 2.55; 2.63 (0.65–4.00; 3)
#   Ø12 (−4, 4): +0.29 ± 0.15 (0.05); −0.05 / +0.25 / +0.54, 0.59; 1.13 (0.68–1.74; 0)
# Ø6 (−4, 4) is at the edge of the bias limit: two of its eight renders read beyond 1.5 µm
# (−1.72, −1.96): the −1 µm residual far off the axis that the twin does not model.
@pytest.mark.slow  # eight 64-spp support frames and their twins per case (~1 min on 2 cores)
@pytest.mark.parametrize("diameter_mm, placement_mm", [(6.0, (-4.0, 4.0)), (6.0, (3.0, 0.0)),
                                                       (12.0, (-4.0, 4.0))],
                         ids=["d6-(-4,4)", "d6-(3,0)", "d12-(-4,4)"])
def test_the_twin_removes_the_bias_to_the_claimed_limit(diameter_mm, placement_mm):
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.experiments.bias_study import bias_trial

    bias, views = [], []
    for root_seed in ROOT_SEEDS:
        v = bias_trial(_trial(diameter_mm, placement_mm, root_seed)).values
        assert v["n_valid"] > 4000  # the whole section (4500–4650 points about its own centre)
        # what there is to correct: −11…−13 µm at Ø6 mm, −6…−7 µm at Ø12 mm
        assert v["bias_plain_um"] < -5.0, (root_seed, v["bias_plain_um"])
        bias.append(v["bias_twin_um"])
        views.append(np.asarray(v["view_twin_um"], float))
    views = np.asarray(views)
    assert np.all(np.isfinite(views)) and np.all(np.isfinite(bias)), (bias, views)
    assert abs(np.mean(bias)) <= BIAS_MAX_UM, bias
    assert np.ptp(views.mean(axis=0)) <= SPREAD_MAX_UM, views
    # the renders' own spreads scatter about the expected one (one render is not the claim)
    assert np.mean(np.ptp(views, axis=1)) <= SPREAD_MAX_UM, views
