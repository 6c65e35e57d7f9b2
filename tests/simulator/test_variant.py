"""The Mitsuba variant chosen when nobody names one: ``default_variant`` (CUDA where a device is
usable, else LLVM), and ``ensure_variant``, which sets it only where no variant is set."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

mi = pytest.importorskip("mitsuba", reason="the variant is Mitsuba's")

from lts360.simulator import render  # noqa: E402
from lts360.simulator.render import cuda_usable, default_variant  # noqa: E402


def test_default_variant_is_llvm_without_a_usable_gpu():
    """On a machine without a CUDA device (this one, CI) the choice is ``llvm_ad_mono``;
    where one is usable and compiled in, ``cuda_ad_mono``. Never raises either way."""
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    usable = cuda_usable()
    assert isinstance(usable, bool)
    expected = ("cuda_ad_mono" if usable and "cuda_ad_mono" in mi.variants()
                else "llvm_ad_mono")
    assert default_variant() == expected


def test_default_variant_follows_the_cuda_check(monkeypatch):
    """cuda_ad_mono exactly when it is compiled in and the device is usable; llvm_ad_mono else;
    the first compiled variant when neither is there."""
    monkeypatch.setattr(render, "cuda_usable", lambda: True)
    monkeypatch.setattr(mi, "variants", lambda: ["scalar_rgb", "llvm_ad_mono", "cuda_ad_mono"])
    assert default_variant() == "cuda_ad_mono"
    monkeypatch.setattr(render, "cuda_usable", lambda: False)
    assert default_variant() == "llvm_ad_mono"
    monkeypatch.setattr(render, "cuda_usable", lambda: True)
    monkeypatch.setattr(mi, "variants", lambda: ["scalar_rgb", "llvm_ad_mono"])
    assert default_variant() == "llvm_ad_mono"
    monkeypatch.setattr(mi, "variants", lambda: ["scalar_rgb", "scalar_mono"])
    assert default_variant() == "scalar_rgb"


def test_cuda_check_never_raises(monkeypatch):
    """A Dr.Jit that cannot answer (no has_backend, a driver that throws) means no CUDA."""
    import drjit as dr

    def broken(_backend):
        raise RuntimeError("cuInit failed")

    monkeypatch.setattr(dr, "has_backend", broken)
    assert cuda_usable() is False
    monkeypatch.delattr(dr, "has_backend")
    assert cuda_usable() is False


def test_a_fresh_process_without_a_gpu_chooses_and_sets_llvm():
    """In a fresh process with every CUDA device hidden, the choice is ``llvm_ad_mono`` and
    nothing crashes; ``ensure_variant`` sets it once and then keeps whatever is set."""
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    code = ("import mitsuba as mi; from lts360.simulator.render import default_variant, "
            "ensure_variant, cuda_usable;"
            "assert mi.variant() is None;"
            "print(cuda_usable(), default_variant(), ensure_variant(),"
            " ensure_variant('scalar_rgb'), mi.variant())")
    import lts360

    src = str(Path(lts360.__file__).parents[1])  # this checkout's, not an installed lts360
    env = dict(os.environ, CUDA_VISIBLE_DEVICES="",
               PYTHONPATH=os.pathsep.join(filter(None, [src, os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ["False"] + ["llvm_ad_mono"] * 4


def test_the_command_line_takes_its_default_from_default_variant(monkeypatch):
    """``_set_variant(None)`` sets what default_variant chooses (no second choice in the CLI)."""
    from lts360.cli import usage

    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    calls = []
    monkeypatch.setattr(render, "default_variant",
                        lambda: calls.append(1) or "llvm_ad_mono")
    monkeypatch.setattr(mi, "set_variant", lambda name: calls.append(name))
    assert usage._set_variant(None) == "llvm_ad_mono"
    assert calls == [1, "llvm_ad_mono"]
