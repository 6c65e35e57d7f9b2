"""The laser line on a chessboard by fitting an image model (laser calibration, paper §4.3).

A line detector (Steger, a centroid) finds the centre of the *image* of the laser band.  On a
chessboard that image is the band times the printed albedo (4 % black against 80 % white),
blurred by the lens: where the band runs over a black/white edge, the blur mixes the dim and
the bright side and the centre moves towards the white square.  On the paper's 2 mm squares
(~18 px) seen 4–5 px out of focus these errors do not average out along a line: measured on
rendered laser shots of that board with the true board pose, the detected line lay −105 to
+9 µm from the true one at the board's centre.

Here the board's pose is known (from its corners), so the sharp albedo under every pixel is
known too.  The model of the laser-on minus laser-off image is

    A · (1 + g · s) · G_σ ∗ [ albedo(x) · exp(−½ ((n(φ) · x − c) / w)²) ]

with ``x`` the board coordinates seen by a pixel (4 × 4 samples per pixel, averaged), ``s``
the coordinate along the line (mm, from the detected line's centre), ``G_σ`` a Gaussian blur
whose σ is fitted first to the board image (``k · G_σ ∗ albedo + b``), and the line's
direction ``φ``, offset ``c``, band width ``w``, amplitude ``A`` and gain ``g`` fitted by
least squares inside the printed squares.  Measured on the same shots: −10.5 to +2.6 µm.

The gain: the band's brightness changes along the line (the fan's profile, the distance to
the laser, the incidence on the tilted board; fitted g = −0.010…−0.017 /mm on the rendered
shots, i.e. 10–25 % over the line).  A constant amplitude cannot follow it, and the misfit,
lopsided where the band crosses black/white edges, turns the fitted line: on the twelve
rendered laser shots of the f/2.8 and f/8 rigs (true board pose), the points tilted against
the true sheet by −0.8…+1.5 µm per mm along the line without the gain, −0.2…+0.4 with it,
and their mean offsets went from −4.5…+1.2 µm to −1.7…−0.3 µm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from lts360.geometry.camera import backproject_pixels, project_camera_points
from lts360.recon.calibration.board import BoardGeometry

__all__ = ["BoardLine", "fit_line_on_board"]

_SS = 4  # samples per pixel and axis


@dataclass(frozen=True)
class BoardLine:
    """A straight line on the board: points ``x`` with ``normal · x = offset_mm`` (board
    frame, mm), the fitted band width (1 σ, mm), the blur (1 σ, px), the band's relative
    change of brightness along the line (per mm) and the RMS residual of the fit in the
    image's units."""

    normal: np.ndarray
    offset_mm: float
    width_mm: float
    blur_px: float
    rms: float
    gain_per_mm: float = 0.0


def _board_coords(R, t, K, dist, u0: int, v0: int, h: int, w: int) -> np.ndarray:
    """(h·S, w·S, 2) board coordinates (mm) of S × S samples in every pixel of the crop."""
    o = (np.arange(_SS) + 0.5) / _SS - 0.5
    u = u0 + np.repeat(np.arange(w), _SS) + np.tile(o, w)
    v = v0 + np.repeat(np.arange(h), _SS) + np.tile(o, h)
    uu, vv = np.meshgrid(u, v)
    rays = backproject_pixels(np.column_stack([uu.ravel(), vv.ravel()]), K, dist)
    n = R[:, 2]
    X = rays * (float(n @ t) / (rays @ n))[:, None]
    return ((X - t) @ R)[:, :2].reshape(h * _SS, w * _SS, 2)


def _pixel_mean(a: np.ndarray, h: int, w: int) -> np.ndarray:
    return a.reshape(h, _SS, w, _SS).mean(axis=(1, 3))


def _board_residuals(dark_share: np.ndarray, crop_b: np.ndarray, inside: np.ndarray):
    """Residuals of the board image's model ``k · G_σ ∗ ⟨albedo⟩ + b`` inside the squares,
    ``p = (σ, k, b, ρ)``, with ``⟨albedo⟩ = 1 − (1 − ρ) · dark_share`` (the pixel mean of an
    albedo of ρ on the dark squares and 1 elsewhere is linear in ρ, so the supersampled
    squares are averaged once, not at every evaluation).  ``dark_share``: (h, w) the pixel
    mean of the dark squares' indicator.

    The blur is linear and keeps a constant (its kernel sums to one, the border reflected),
    so ``G_σ ∗ ⟨albedo⟩ = 1 − (1 − ρ) · G_σ ∗ dark_share``: one blur per σ, kept for the
    evaluations at the same σ (the optimiser's finite differences in k, b and ρ)."""
    blurred: dict[float, np.ndarray] = {}

    def board_res(p):
        sigma, k, b, rho = p
        sigma = abs(float(sigma))
        if sigma not in blurred:
            if len(blurred) > 4:
                blurred.clear()
            blurred[sigma] = ndimage.gaussian_filter(dark_share, sigma)
        return (k * (1.0 - (1.0 - rho) * blurred[sigma]) + b - crop_b)[inside]
    return board_res


class _BandModel:
    """The laser band's image model of :func:`fit_line_on_board`,
    ``A · (1 + g · s) · G_σ ∗ ⟨albedo · exp(−½ ((n(φ) · x − c) / w)²)⟩``, and its analytic
    Jacobian in ``p = (φ, c, w, A, g)`` (the first ``len(p)`` of them free, the rest
    ``fixed``): the band's derivatives per sample, averaged over each pixel and blurred like
    the band (the pixel mean and the blur are linear).  The last evaluation is cached (the
    optimiser asks for the residuals and the Jacobian at the same point)."""

    def __init__(self, xb, albedo, s_px, sigma, crop, inside, *, fixed=()):
        self.xb, self.albedo, self.s_px, self.sigma = xb, albedo, s_px, sigma
        self.crop, self.inside, self.fixed = crop, inside, list(fixed)
        self.h, self.w = crop.shape
        self._key = None

    def _blur(self, a):
        return ndimage.gaussian_filter(_pixel_mean(a, self.h, self.w), self.sigma)

    def _evaluate(self, p):
        if self._key is not None and np.array_equal(self._key, p):
            return self._cache
        phi, c, width, amp, gain = np.append(p, self.fixed[:5 - len(p)])
        n = np.array([np.cos(phi), np.sin(phi)])
        q = (self.xb @ n - c) / width
        ab = self.albedo * np.exp(-0.5 * q * q)
        blurred = self._blur(ab)
        self._key = np.array(p, float)
        self._cache = (phi, width, amp, gain, q, ab, blurred)
        return self._cache

    def residuals(self, p):
        _, _, amp, gain, _, _, blurred = self._evaluate(p)
        return (amp * (1.0 + gain * self.s_px) * blurred - self.crop)[self.inside]

    def jacobian(self, p):
        phi, width, amp, gain, q, ab, blurred = self._evaluate(p)
        scale = amp * (1.0 + gain * self.s_px)
        along = self.xb @ np.array([-np.sin(phi), np.cos(phi)])  # d(n · x)/dφ
        # d band/dφ = −band q (n' · x)/w, d band/dc = band q/w, d band/dw = band q²/w.
        aq = ab * q / width
        cols = [scale * self._blur(-aq * along), scale * self._blur(aq),
                scale * self._blur(aq * q), (1.0 + gain * self.s_px) * blurred,
                amp * self.s_px * blurred]
        return np.column_stack([c[self.inside] for c in cols[:len(p)]])


def fit_line_on_board(diff, image_board, board: BoardGeometry, R, t, K, dist, *,
                      initial_normal, initial_offset_mm: float,
                      inset_squares: float = 0.25, margin_px: int = 20,
                      along_line_gain: bool = True) -> BoardLine:
    """Fit the laser band on the board (module docstring) and return its centre line.

    Parameters
    ----------
    diff : (h, w) array
        Laser-on minus laser-off.
    image_board : (h, w) array
        The board under ambient light (its blur and which squares are dark come from it).
    R, t : the board's pose (board → camera).
    initial_normal, initial_offset_mm : the line from a line detector (board frame).
    inset_squares : float
        The fit uses the pixels at least this many squares inside the printed squares.
    along_line_gain : bool
        Fit the gain ``g`` (module docstring); ``False``: a constant amplitude along the line.

    Raises
    ------
    ValueError
        The board lies outside the image, or the fit does not converge.
    """
    R, t = np.asarray(R, float), np.asarray(t, float)
    nx, ny = board.pattern_size
    s = board.square_mm
    outline = np.array([[-s, -s, 0.0], [nx * s, -s, 0.0], [nx * s, ny * s, 0.0],
                        [-s, ny * s, 0.0]])
    uv = project_camera_points(outline @ R.T + t, K, dist)
    H, W = np.shape(diff)
    u0, v0 = np.maximum(np.floor(uv.min(axis=0)).astype(int) - margin_px, 0)
    u1, v1 = np.minimum(np.ceil(uv.max(axis=0)).astype(int) + margin_px, [W, H])
    if u1 - u0 < 8 or v1 - v0 < 8:
        raise ValueError("laser line model: the board lies outside the image")
    h, w = v1 - v0, u1 - u0
    xb = _board_coords(R, t, K, dist, u0, v0, h, w)
    crop = np.asarray(diff, float)[v0:v1, u0:u1]
    crop_b = np.asarray(image_board, float)[v0:v1, u0:u1]
    lo, hx, hy = (inset_squares - 1.0) * s, (nx - inset_squares) * s, (ny - inset_squares) * s
    inside = _pixel_mean(((xb[..., 0] > lo) & (xb[..., 0] < hx) & (xb[..., 1] > lo)
                          & (xb[..., 1] < hy)).astype(float), h, w) > 0.999
    if inside.sum() < 50:
        raise ValueError("laser line model: too few pixels on the board")
    parity = (np.floor(xb[..., 0] / s) + np.floor(xb[..., 1] / s)) % 2 == 0

    # Blur, dark share and which squares are dark, from the board image.
    best = None
    top = float(np.percentile(crop_b[inside], 95))
    for dark in (parity, ~parity):
        board_res = _board_residuals(_pixel_mean(dark.astype(float), h, w), crop_b, inside)
        sol = least_squares(board_res, [1.5, top, 0.0, 0.05],
                            bounds=([0.05, 0.0, -np.inf, 0.0], [20.0, np.inf, np.inf, 1.0]))
        if best is None or sol.cost < best[0]:
            best = (sol.cost, dark, sol.x)
    _, dark, (sigma, _, _, rho) = best
    albedo = np.where(dark, rho, 1.0)

    n0 = np.asarray(initial_normal, float)[:2]
    n0 = n0 / np.linalg.norm(n0)
    # Coordinate along the detected line (mm), zero at the board area's middle: the gain's
    # lever arm; it varies slowly, so its pixel mean is applied after the blur.
    along = np.array([-n0[1], n0[0]])
    s_px = _pixel_mean(xb @ along, h, w)
    s_px -= 0.5 * (s_px[inside].min() + s_px[inside].max())

    peak = float(crop[inside].max())
    if peak <= 0:
        raise ValueError("laser line model: no laser light on the board")
    p0 = [np.arctan2(n0[1], n0[0]), float(initial_offset_mm), 0.3 * s / 2.0, 2.0 * peak, 0.0]
    free = slice(0, 5 if along_line_gain else 4)
    band = _BandModel(xb, albedo, s_px, sigma, crop, inside, fixed=p0[free.stop:])
    sol = least_squares(band.residuals, p0[free], jac=band.jacobian,
                        x_scale=[1e-3, 1e-3 * s, 1e-2 * s, peak, 1e-2 / s][free],
                        bounds=([-np.inf, -np.inf, 0.01 * s, 0.0, -np.inf][free],
                                [np.inf, np.inf, 2.0 * s, np.inf, np.inf][free]))
    if not sol.success:
        raise ValueError(f"laser line model: the fit did not converge ({sol.message})")
    phi, c, width, _, gain = np.append(sol.x, p0[len(sol.x):])
    return BoardLine(normal=np.array([np.cos(phi), np.sin(phi)]), offset_mm=float(c),
                     width_mm=float(width), blur_px=float(sigma),
                     rms=float(np.sqrt(np.mean(sol.fun ** 2))), gain_per_mm=float(gain))
