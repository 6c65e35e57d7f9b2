"""Pixel locking: the stored fit is the one locking_fit() computes, and the locking is
periodic in the sub-pixel phase with no mean (symmetric kernel and threshold)."""

from __future__ import annotations

import numpy as np
import pytest

from lts360.design.locking import LOCKING_COEFFS, locking_fit, locking_rms_px


@pytest.mark.slow  # ~3 s: 180 line widths × 16 phases
def test_stored_coefficients_are_current():
    np.testing.assert_allclose(LOCKING_COEFFS, locking_fit(), rtol=1e-9)


def test_locking_falls_with_line_width():
    """A wider line samples its profile better: 0.3 px → ~0.1 px rms, 3 px → < 1e-4 px."""
    assert locking_rms_px(0.3) > 0.05
    assert locking_rms_px(3.0) < 1e-4
