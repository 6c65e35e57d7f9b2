"""A printed calibration board as the calibration knows it: its pattern and square size."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BoardGeometry"]


@dataclass(frozen=True)
class BoardGeometry:
    """What a real calibration needs to know of a printed board (the manifest).

    Attributes
    ----------
    pattern_size : (int, int)
        Inner corners per row and per column (OpenCV's ``patternSize``).
    square_mm : float
        Side of a square (measured, e.g. on a coordinate measuring machine).
    """

    pattern_size: tuple[int, int]
    square_mm: float

    def __post_init__(self) -> None:
        nx, ny = self.pattern_size
        if not (isinstance(nx, (int, np.integer)) and isinstance(ny, (int, np.integer))
                and nx >= 2 and ny >= 2):
            raise ValueError(f"pattern_size must be two integers >= 2, got {self.pattern_size!r}")
        if not self.square_mm > 0:
            raise ValueError(f"square_mm must be > 0, got {self.square_mm!r}")

    def object_points(self) -> np.ndarray:
        """(n, 3) float32 corners in the board frame, OpenCV's row-major order."""
        nx, ny = self.pattern_size
        i, j = np.meshgrid(np.arange(nx), np.arange(ny))
        return (np.column_stack([i.ravel(), j.ravel(), np.zeros(nx * ny)])
                * self.square_mm).astype(np.float32)
