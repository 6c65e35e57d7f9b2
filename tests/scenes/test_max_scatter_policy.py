"""``--max-scatter auto``: one bounce for the catalog's shiny materials, none for the others
(lts360.scenes.materials.auto_max_scatter), and the studies' trials it makes."""

import numpy as np
import pytest

from lts360.scenes.materials import (
    MATERIALS,
    SHINY_SPECULAR_WEIGHT,
    auto_max_scatter,
    resolve_max_scatter,
)
from lts360.scenes.objects import build_object


def test_auto_is_one_bounce_for_the_shiny_materials_only():
    shiny = {n for n, m in MATERIALS.items() if auto_max_scatter(m) == 1}
    assert shiny == {"machined-aluminium", "brass", "polished-aluminium", "glossy-black-plastic"}
    assert all(m.specular_weight >= SHINY_SPECULAR_WEIGHT for n, m in MATERIALS.items()
               if n in shiny)
    # per catalog object: the shiny ones, and the gauge, PVC, shafts, cables, cube without
    per_object = {name: auto_max_scatter(build_object(name).material)
                  for name in ("alu-pipe", "cut-tube", "polished-shaft", "plug-gauge", "pvc-pipe",
                               "grooved-shaft", "undercut-shaft", "cable-6", "cube")}
    assert per_object == {"alu-pipe": 1, "cut-tube": 1, "polished-shaft": 1, "plug-gauge": 0,
                          "pvc-pipe": 0, "grooved-shaft": 0, "undercut-shaft": 0, "cable-6": 0,
                          "cube": 0}


def test_resolve_max_scatter_and_bad_input():
    brass = MATERIALS["brass"]
    assert resolve_max_scatter("auto", brass) == 1
    assert resolve_max_scatter("auto", MATERIALS["white-pvc"]) == 0
    assert resolve_max_scatter("2", brass) == 2 and resolve_max_scatter(0, brass) == 0
    for bad in ("4", "-1", "often", 1.5, True, 7):
        with pytest.raises(ValueError, match="max_scatter"):
            resolve_max_scatter(bad, brass)


def test_the_examples_trials_take_auto_per_object(tmp_path):
    from lts360.experiments.examples_study import examples_params

    objs = ["pvc-pipe", "alu-pipe", "cut-tube", "polished-shaft", "cable-6"]
    got = {p["object"]: p.get("max_scatter", 0) for p in examples_params(tmp_path, objects=objs)}
    assert got == {"pvc-pipe": 0, "alu-pipe": 1, "cut-tube": 1, "polished-shaft": 1, "cable-6": 0}
    # an explicit number holds for every object; 0 leaves the key out (earlier trials' params)
    assert all("max_scatter" not in p for p in examples_params(tmp_path, objects=objs,
                                                                max_scatter=0))
    assert {p["max_scatter"] for p in examples_params(tmp_path, objects=objs, max_scatter="2")} \
        == {2}
    # a mixed study (the default objects: matte and shiny): one schema, as the runner demands
    params = examples_params(tmp_path)
    assert len({tuple(sorted(p)) for p in params}) == 1
    from lts360.experiments.runner import _check_trials, plan_trials

    assert len(_check_trials(plan_trials(params, 0))) == len(params)


def test_stored_frames_are_read_back_for_the_same_scan(tmp_path):
    """A scan stored under the same parameters and seed is read back, not rendered (the 4×5
    frames written here could come from no render of the paper rig); where the study writes and
    which calibration it measures with are not part of the scan."""
    import json

    import lts360.experiments.examples_study as ex

    p = ex.examples_params(tmp_path / "out", objects=["cube"], section_scale=0.04)[0]
    frames = tmp_path / "frames"
    frames.mkdir()
    key = json.dumps(ex._same_trial(dict(p, out="elsewhere", frames="x", calibration="c.json")),
                     sort_keys=True)
    images = np.arange(20, dtype=np.uint8).reshape(1, 4, 5)
    np.savez_compressed(frames / "cube.npz", images=images, z_mm=np.array([1.0]),
                        truth=json.dumps({"k": [1, 2]}), render_s=0.5, params=key, seed=7)
    scan = ex.stored_scan(p, 7, frames)
    assert np.array_equal(scan["images"], images) and scan["truth"] == {"k": [1, 2]}
    assert scan["render_s"] == 0.5 and scan["z_mm"].tolist() == [1.0]
    assert "spp" in key and "max_scatter" not in key  # cube: auto is none
