"""Calibration targets: a printed chessboard (paper §4.2: 7×6 squares of 2 mm on a 3 mm glass
plate), placed in the world, with its exact corner positions as ground truth.

Board frame: x along the squares' columns, y along the rows, z = board normal (the printed
side faces +z); the origin is the board's outer corner at the first square, so the inner
corner ``(i, j)`` (``i`` along x, ``j`` along y, both from 0) lies at
``((i + 1) s, (j + 1) s, 0)`` for squares of side ``s``.  numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lts360.scenes.checks import RigError, _check, _in_range

__all__ = ["Chessboard"]


@dataclass(frozen=True, eq=False)
class Chessboard:
    """A chessboard target and its pose.

    Attributes
    ----------
    squares_x, squares_y : int, [3, 40]
        Number of squares along x and y (paper: 7 × 6).
    square_mm : float, (0.1, 100]
        Side of a square (paper: 2 mm).
    margin_mm : float, [0, 50]
        White border around the squares.
    dark_reflectance, light_reflectance : float, [0, 1]
        Diffuse albedo of the printed black and white at the laser wavelength.
    T_world_board : (4, 4) float
        Pose of the board frame in the world.
    """

    squares_x: int = 7
    squares_y: int = 6
    square_mm: float = 2.0
    margin_mm: float = 1.0
    dark_reflectance: float = 0.04
    light_reflectance: float = 0.80
    T_world_board: np.ndarray = None

    def __post_init__(self) -> None:
        for name in ("squares_x", "squares_y"):
            v = getattr(self, name)
            _check(isinstance(v, (int, np.integer)) and 3 <= v <= 40, f"chessboard.{name}",
                   f"must be an integer in [3, 40], got {v!r}")
        _in_range("chessboard.square_mm", self.square_mm, 0.1, 100.0, lo_open=True)
        _in_range("chessboard.margin_mm", self.margin_mm, 0.0, 50.0)
        _in_range("chessboard.dark_reflectance", self.dark_reflectance, 0.0, 1.0)
        _in_range("chessboard.light_reflectance", self.light_reflectance, 0.0, 1.0)
        if not self.light_reflectance > self.dark_reflectance:
            raise RigError("chessboard.light_reflectance: must exceed dark_reflectance")
        T = np.eye(4) if self.T_world_board is None else np.asarray(self.T_world_board, dtype=float)
        _check(T.shape == (4, 4) and np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
               and np.linalg.det(T[:3, :3]) > 0 and np.allclose(T[3], [0, 0, 0, 1]),
               "chessboard.T_world_board", "must be a 4×4 rigid transform")
        object.__setattr__(self, "T_world_board", T)

    @property
    def pattern_size(self) -> tuple[int, int]:
        """OpenCV's ``patternSize``: inner corners per row and per column."""
        return self.squares_x - 1, self.squares_y - 1

    @property
    def size_mm(self) -> tuple[float, float]:
        """Printed area including the margin (x, y)."""
        return (self.squares_x * self.square_mm + 2 * self.margin_mm,
                self.squares_y * self.square_mm + 2 * self.margin_mm)

    def corners_board_mm(self) -> np.ndarray:
        """(n, 3) inner corners in the board frame, row-major (x fastest), z = 0."""
        nx, ny = self.pattern_size
        i, j = np.meshgrid(np.arange(1, nx + 1), np.arange(1, ny + 1))
        return np.column_stack([i.ravel() * self.square_mm, j.ravel() * self.square_mm,
                                np.zeros(nx * ny)])

    def corners_world_mm(self) -> np.ndarray:
        """(n, 3) inner corners in the world frame (the exact truth of a calibration image)."""
        T = self.T_world_board
        return self.corners_board_mm() @ T[:3, :3].T + T[:3, 3]

    def texture(self, px_per_square: int = 32) -> np.ndarray:
        """(h, w) float albedo image of the printed side; row 0 is the board's y = y_max edge
        (image convention), column 0 its x = x_min edge."""
        if px_per_square < 2:
            raise ValueError(f"px_per_square must be >= 2, got {px_per_square}")
        s = px_per_square / self.square_mm  # pixels per mm
        w_mm, h_mm = self.size_mm
        w, h = int(round(w_mm * s)), int(round(h_mm * s))
        x = (np.arange(w) + 0.5) / s - self.margin_mm
        y = h_mm - (np.arange(h) + 0.5) / s - self.margin_mm
        ix = np.floor(x / self.square_mm)
        iy = np.floor(y / self.square_mm)
        inside = (ix[None, :] >= 0) & (ix[None, :] < self.squares_x) & \
                 (iy[:, None] >= 0) & (iy[:, None] < self.squares_y)
        dark = ((ix[None, :] + iy[:, None]) % 2 == 0) & inside
        return np.where(dark, self.dark_reflectance, self.light_reflectance)

    def rectangle_transform(self) -> np.ndarray:
        """World transform of Mitsuba's ``rectangle`` ([-1, 1]², normal +z, uv (0,0) at
        (-1, -1)) onto the printed area of the board."""
        w_mm, h_mm = self.size_mm
        S = np.diag([w_mm / 2, h_mm / 2, 1.0, 1.0])
        S[:2, 3] = [w_mm / 2 - self.margin_mm, h_mm / 2 - self.margin_mm]
        return self.T_world_board @ S
