"""What every part of the reconstruction reads from an image: the pixels of a file
(:func:`lts360.folders.read_image`, the folder format's reader), and the detector's default
threshold and saturation level (full scale of the image's type)."""

from __future__ import annotations

import numpy as np

from lts360.folders import read_image

__all__ = ["read_image", "default_threshold", "default_saturation",
           "DEFAULT_THRESHOLD_FRACTION"]

#: Default threshold as a fraction of full scale (integer images) or of the image maximum.
DEFAULT_THRESHOLD_FRACTION = 0.1


def default_threshold(image: np.ndarray) -> float:
    """10 % of full scale for integer images (25.5 DN at 8 bit), 10 % of the maximum otherwise.

    At 8 bit that lies well above the dark level and read noise of the paper's camera
    (a few DN) and well below a properly exposed line (the paper sets the exposure for it).
    """
    img = np.asarray(image)
    if img.dtype.kind in "ui":
        return DEFAULT_THRESHOLD_FRACTION * float(np.iinfo(img.dtype).max)
    peak = float(np.nanmax(img)) if img.size else 0.0
    return DEFAULT_THRESHOLD_FRACTION * peak if peak > 0 else 0.0


def default_saturation(image: np.ndarray) -> float | None:
    """Full scale for integer images (255 at 8 bit); ``None`` (never saturated) for float images."""
    img = np.asarray(image)
    return float(np.iinfo(img.dtype).max) if img.dtype.kind in "ui" else None
