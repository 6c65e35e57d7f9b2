"""A trial's set-up, one helper for every study: the variant (only where none is set: the
trial's ``variant`` or ``default_variant``), the rig and the object, from the trial's params."""

from __future__ import annotations

import pytest

mi = pytest.importorskip("mitsuba", reason="the set-up sets a Mitsuba variant")

from lts360.experiments.runner import trial_setup  # noqa: E402
from lts360.scenes.objects import build_object  # noqa: E402
from lts360.scenes.rig_io import load_rig, rig_to_toml  # noqa: E402
from lts360.simulator import render  # noqa: E402


@pytest.fixture
def no_variant(monkeypatch):
    """Mitsuba as a fresh worker process sees it (no variant set); records what gets set."""
    chosen = []
    monkeypatch.setattr(mi, "variant", lambda: chosen[-1] if chosen else None)
    monkeypatch.setattr(mi, "set_variant", chosen.append)
    return chosen


def test_rig_and_object_come_from_the_params(no_variant):
    rig, obj = trial_setup({"rig": "paper", "object": "plug-gauge:d=6,x=1", "spp": 4})
    assert rig_to_toml(rig) == rig_to_toml(load_rig("paper"))
    assert obj.spec == build_object("plug-gauge:d=6,x=1").spec


def test_a_spec_given_replaces_the_object_param(no_variant):
    _, obj = trial_setup({"rig": "paper", "spec": "cube"}, spec="plug-gauge:d=8")
    assert obj.spec == build_object("plug-gauge:d=8").spec
    with pytest.raises(KeyError):
        trial_setup({"rig": "paper"})


def test_the_variant_is_the_trials_or_the_default(no_variant, monkeypatch):
    monkeypatch.setattr(render, "default_variant", lambda: "llvm_ad_mono")
    trial_setup({"rig": "paper", "object": "cube"})
    assert no_variant == ["llvm_ad_mono"]
    no_variant.clear()
    trial_setup({"rig": "paper", "object": "cube", "variant": ""})  # empty: the default
    assert no_variant == ["llvm_ad_mono"]
    no_variant.clear()
    trial_setup({"rig": "paper", "object": "cube", "variant": "scalar_rgb"})
    assert no_variant == ["scalar_rgb"]


def test_a_variant_already_set_is_kept(no_variant):
    no_variant.append("llvm_ad_rgb")  # set by the command line, say
    trial_setup({"rig": "paper", "object": "cube", "variant": "scalar_rgb"})
    assert no_variant == ["llvm_ad_rgb"]


def test_without_a_gpu_the_default_is_llvm(no_variant, monkeypatch):
    """On this machine (no usable CUDA device) a trial renders with llvm_ad_mono, as the
    studies always have: their tables do not change."""
    monkeypatch.setattr(render, "cuda_usable", lambda: False)
    monkeypatch.setattr(mi, "variants", lambda: ["scalar_rgb", "llvm_ad_mono", "cuda_ad_mono"])
    trial_setup({"rig": "paper", "object": "cube"})
    assert no_variant == ["llvm_ad_mono"]
