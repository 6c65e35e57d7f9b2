"""Fixtures shared by the experiment tests."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest


@pytest.fixture(scope="module")
def truth_calibration(tmp_path_factory):
    """The true calibration of the paper rig, with made-up uncertainties, as a file."""
    mi = pytest.importorskip("mitsuba", reason="the studies render")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.recon.model import calibration_from_frame_truth, save_calibration
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.io import rig_truth

    rig = load_rig("paper")
    t = rig_truth(rig, rig.camera.K, (rig.camera.width_px, rig.camera.height_px))
    cal = calibration_from_frame_truth(json.loads(json.dumps(t, default=lambda v: v.tolist())))
    cov = np.diag([1e-4**2, 1e-4**2, 0.005**2]).tolist()
    cal = dataclasses.replace(cal, uncertainty={"camera": {"std": {"fx": 0.3, "fy": 0.3}},
                                                "mirrors": {"left": {"cov_abd": cov},
                                                            "right": {"cov_abd": cov}},
                                                "laser_plane": {"cov_abd": cov}})
    path = tmp_path_factory.mktemp("cal") / "calibration.json"
    save_calibration(path, cal)
    return path
