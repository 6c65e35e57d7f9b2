"""Fixtures shared by the simulator's tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def variant():
    """Mitsuba's ``llvm_ad_mono`` variant set (skipped where Mitsuba or the variant is
    missing; under ``CI=true`` a skip fails the run, tests/conftest.py)."""
    mi = pytest.importorskip("mitsuba", reason="rendering needs Mitsuba 3 (installed by scripts/install.sh)")
    if "llvm_ad_mono" not in mi.variants():
        pytest.skip("Mitsuba's llvm_ad_mono variant is not available")
    mi.set_variant("llvm_ad_mono")
    return "llvm_ad_mono"
