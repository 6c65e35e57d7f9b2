"""Shape and value checks at the public boundary of the geometry functions."""

from __future__ import annotations

import numpy as np


def as_points(points, name: str, dim: int = 3) -> np.ndarray:
    """Return ``points`` as a float (n, dim) array or raise ``ValueError`` naming it."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1 and arr.size == dim:
        arr = arr.reshape(1, dim)
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n, {dim}), got {arr.shape}")
    return arr


def as_matrix(m, shape: tuple[int, int], name: str) -> np.ndarray:
    """Return ``m`` as a float array of exactly ``shape`` or raise ``ValueError`` naming it."""
    arr = np.asarray(m, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def unit(v, name: str) -> np.ndarray:
    """Return ``v`` normalised, or raise if it is zero or not finite."""
    arr = np.asarray(v, dtype=float)
    norm = np.linalg.norm(arr, axis=-1, keepdims=True)
    if not np.all(np.isfinite(arr)) or np.any(norm == 0):
        raise ValueError(f"{name} must be a finite non-zero vector, got {arr!r}")
    return arr / norm
