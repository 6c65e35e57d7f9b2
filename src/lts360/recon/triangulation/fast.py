"""The per-image hot path of inverse triangulation as one Dr.Jit kernel (LLVM on CPU, CUDA on GPU).

Same arithmetic as the numpy reference (:mod:`lts360.recon.triangulation.inverse` with the ``centroid``
detector of :mod:`lts360.recon.triangulation.peaks`), which it is tested against: bicubic sampling of the
image at the planned grid points (Keys, or cubic B-spline when the plan asks for it — the
B-spline prefilter then runs on the host), then per radial direction the main run above the
threshold, its thresholded centroid and the quality flag.  Single precision on the device (the
reference is double): radii agree to ~1e-6 mm.

How it is laid out (the plan is fixed for a scan, the image changes):

* **4×4 pixel windows.**  The standard grid (0.1° × 5 µm, 3.5 M points in three views)
  samples only ~14 000 distinct 4×4 pixel neighbourhoods: consecutive radii are ~0.03 px
  apart.  The plan stores, per point, the index of its window (``uint32``) and its fractional
  position inside it (two ``float32``; NaN outside the image); per image, one small gather
  copies the 16 taps of every window into a table (``16 × n_windows`` floats; edge pixels
  replicated, or B-spline coefficients mirrored, as :mod:`lts360.recon.triangulation.interp` pads), so that
  each sample reads its 16 taps with one packet load of 64 contiguous bytes instead of 16
  scattered gathers.
* **One thread per radial direction.**  A single kernel walks each profile from the inner to
  the outer radius, sampling as it goes, and keeps a running account of the runs above the
  threshold (start, maximum, Σw, Σw·j of the current and of the strongest run, the largest
  maximum of the other runs) and of the profile's maximum — the quantities
  :func:`lts360.recon.triangulation.peaks.main_run` and :func:`~lts360.recon.triangulation.peaks.centroid` compute with
  whole-array passes.  No intermediate sample array, no block reductions, no atomics: the
  sums are accumulated in profile order (deterministic).  A run replaces the strongest one
  only if its maximum is strictly larger, so ties resolve to the first maximum as
  ``argmax`` does in the reference.
* Threshold, saturation and second-peak fraction enter the kernel as opaque values: a new
  threshold does not recompile it.

Measured on the standard grid (3 600 θ × 801 r, three views, 3.5 M points; 2-core VM shared
with other jobs, 2026-11-23): a whole call (``__call__``, with the numpy assembly) 20.0 ms
with the previous multi-pass kernel (16 gathers per sample, block reductions) → 9.0 ms
(medians of 66 interleaved calls; 10–90 % range 19.5–21.5 → 7.9–10.2 ms); the kernel alone
(``peaks``) 7.9 ms; ``benchmarks/bench_recon.py``.
On CUDA the kernel runs one thread per θ row (~4 400 threads for the standard grid); that
path has not been run on a GPU.
"""

from __future__ import annotations

import numpy as np

from lts360.recon.images import default_saturation, default_threshold
from lts360.recon.triangulation.interp import prefilter
from lts360.recon.triangulation.inverse import (
    DEFAULT_ACCEPT,
    InversePlan,
    InverseResult,
    assemble_view,
    compensation_of,
)
from lts360.recon.triangulation.peaks import (
    DEFAULT_MAX_PLATEAU_MM,
    DEFAULT_SECOND_PEAK_FRACTION,
    SATURATION_RTOL,
    PeakResult,
    Quality,
    plateau_samples,
)

__all__ = ["FastInverse", "window_layout"]

#: Taps of a window: offsets −1 … +2 around ``floor(u)``, ``floor(v)`` (Keys' support).
_TAPS = np.arange(-1, 3)


def _backend(name: str):
    import drjit as dr

    if name == "llvm":
        import drjit.llvm as mod

        if not dr.has_backend(dr.JitBackend.LLVM):
            raise RuntimeError("Dr.Jit's LLVM backend is not available (install LLVM >= 16)")
    elif name == "cuda":
        import drjit.cuda as mod

        if not dr.has_backend(dr.JitBackend.CUDA):
            raise RuntimeError("Dr.Jit's CUDA backend is not available (no CUDA device)")
    else:
        raise ValueError(f"backend must be 'llvm' or 'cuda', got {name!r}")
    return dr, mod


def _keys_weights(t):
    """Keys (a = −0.5) weights of the taps −1, 0, 1, 2 at fractional position ``t`` — the closed
    form of :func:`lts360.recon.triangulation.interp.keys_weights`, on Dr.Jit arrays."""
    tm1 = t - 1.0
    return (-0.5 * t * tm1 * tm1, 0.5 * ((3.0 * t - 5.0) * t * t + 2.0),
            0.5 * t * ((4.0 - 3.0 * t) * t + 1.0), 0.5 * t * t * tm1)


def _bspline_weights(t):
    """:func:`lts360.recon.triangulation.interp.bspline_weights` on Dr.Jit arrays."""
    s = 1.0 - t
    return (s * s * s * (1.0 / 6.0), ((3.0 * t - 6.0) * t * t + 4.0) * (1.0 / 6.0),
            (((-3.0 * t + 3.0) * t + 3.0) * t + 1.0) * (1.0 / 6.0), t * t * t * (1.0 / 6.0))


def _mirror(k: np.ndarray, n: int) -> np.ndarray:
    """Indices reflected about the first and last pixel centre (scipy's ``mode="mirror"``)."""
    if n == 1:
        return np.zeros_like(k)
    period = 2 * (n - 1)
    k = np.abs(k) % period
    return np.where(k > n - 1, period - k, k)


def window_layout(uv: np.ndarray, image_shape, *, boundary: str = "edge"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sampling of points by shared 4×4 pixel windows (plan-time, numpy).

    Parameters
    ----------
    uv : (n, 2) float
        Pixel coordinates ``(u, v)`` (NaN allowed).
    image_shape : (int, int)
        ``(height, width)``.
    boundary : {"edge", "mirror"}
        Taps beyond the border: the edge pixel (Keys) or the mirrored one (B-spline
        coefficients), as :mod:`lts360.recon.triangulation.interp` pads.

    Returns
    -------
    window : (n,) uint32
        Index of each point's window (0 for points outside the image).
    fx, fy : (n,) float32
        Position inside the window's (0, 0) pixel, in [0, 1]; NaN for points outside
        ``[0, w − 1] × [0, h − 1]`` (the sample is then NaN, as in the reference).
    taps : (n_windows, 16) uint32
        Flat pixel indices of each window's taps, row-major ``(dy, dx)`` in ``{−1 … 2}²``.
    """
    if boundary not in ("edge", "mirror"):
        raise ValueError(f"boundary must be 'edge' or 'mirror', got {boundary!r}")
    h, w = (int(s) for s in image_shape)
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    u, v = uv[:, 0], uv[:, 1]
    with np.errstate(invalid="ignore"):
        inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    u = np.where(inside, u, 0.0)
    v = np.where(inside, v, 0.0)
    iu, iv = np.floor(u), np.floor(v)
    fx = np.where(inside, u - iu, np.nan).astype(np.float32)
    fy = np.where(inside, v - iv, np.nan).astype(np.float32)
    key = iv.astype(np.int64) * w + iu.astype(np.int64)
    # np.unique(key, return_inverse=True) without its sort: the keys are pixel indices, so a
    # table over the image gives the same sorted corners and inverse in O(n + h·w).
    used = np.zeros(h * w, bool)
    used[key] = True
    corner = np.flatnonzero(used)
    rank = np.cumsum(used, dtype=np.int64) - 1
    window = rank[key]
    ty = corner[:, None, None] // w + _TAPS[None, :, None]
    tx = corner[:, None, None] % w + _TAPS[None, None, :]
    if boundary == "edge":
        ty, tx = np.clip(ty, 0, h - 1), np.clip(tx, 0, w - 1)
    else:
        ty, tx = _mirror(ty, h), _mirror(tx, w)
    taps = (ty * w + tx).reshape(-1, 16).astype(np.uint32)
    return window.astype(np.uint32).ravel(), fx, fy, taps


def _walk_profiles(dr, mod, sample, n: int, nr: int, threshold: float,
                   saturation: float | None, fraction: float, max_plateau: int | None = None):
    """The main run and thresholded centroid of ``n`` profiles in one pass each (Dr.Jit).

    ``sample(j)`` returns the ``j``-th sample of every profile (a Float of size ``n``; NaN
    counts as below the threshold, as in :func:`lts360.recon.triangulation.peaks.main_run`).  The loop keeps,
    per profile, the current run above the threshold and the strongest run so far (start,
    maximum, Σw, Σw·(j − start), w = value − threshold; whether it starts at the band's first
    sample or after a NaN one, and its count of saturated samples), the largest maximum of the
    other runs and the profile's maximum.  A run replaces the strongest one only if its maximum
    is strictly larger: ties go to the first maximum, as ``argmax`` in the reference.  A run
    that ends on a NaN sample or at the last sample is truncated.

    Returns
    -------
    centre : Float
        Centroid of the main run in samples (NaN where there is none).
    quality : UInt32
        :class:`Quality` (``FOUND``, ``NO_PEAK``, ``SATURATED``, ``SEVERAL_PEAKS``,
        ``TRUNCATED``, ``SATURATED_PLATEAU``).
    peak : Float
        Largest sample (−inf for an all-NaN profile).
    other : Float
        Largest maximum of the other runs (−inf where there is none).
    """
    Float, UInt32, Bool = mod.Float, mod.UInt32, mod.Bool
    thr = dr.opaque(Float, threshold)
    sat = dr.opaque(Float, float("inf") if saturation is None
                    else saturation * (1.0 - SATURATION_RTOL))

    def close(ending, right_cut, cur, best, other):
        """Fold the current run into (best, other) where ``ending``; ``right_cut``: the run
        ends on a NaN sample or at the band's end."""
        c_start, c_max, c_sw, c_swj, c_cut, c_nsat = cur
        b_start, b_max, b_sw, b_swj, b_cut, b_nsat = best
        better = ending & (c_max > b_max)
        other = dr.select(better, dr.maximum(other, b_max),
                          dr.select(ending, dr.maximum(other, c_max), other))
        best = (dr.select(better, c_start, b_start), dr.select(better, c_max, b_max),
                dr.select(better, c_sw, b_sw), dr.select(better, c_swj, b_swj),
                dr.select(better, c_cut | right_cut, b_cut), dr.select(better, c_nsat, b_nsat))
        return best, other

    def body(j, peak, in_run, prev_nan, c_start, c_max, c_sw, c_swj, c_cut, c_nsat,
             b_start, b_max, b_sw, b_swj, b_cut, b_nsat, other):
        v = sample(j)
        is_nan = dr.isnan(v)
        v = dr.select(is_nan, -dr.inf, v)  # NaN (outside the image) is never above
        peak = dr.maximum(peak, v)
        above = v > thr
        wgt = v - thr
        best, other = close(in_run & ~above, is_nan, (c_start, c_max, c_sw, c_swj, c_cut, c_nsat),
                            (b_start, b_max, b_sw, b_swj, b_cut, b_nsat), other)
        b_start, b_max, b_sw, b_swj, b_cut, b_nsat = best
        new = above & ~in_run
        grow = above & in_run
        one_sat = dr.select(v >= sat, UInt32(1), UInt32(0))
        c_start = dr.select(new, j, c_start)
        c_max = dr.select(new, v, dr.select(grow, dr.maximum(c_max, v), c_max))
        c_sw = dr.select(new, wgt, dr.select(grow, c_sw + wgt, c_sw))
        c_swj = dr.select(new, 0.0, dr.select(grow, c_swj + wgt * Float(j - c_start), c_swj))
        c_cut = dr.select(new, prev_nan | (j == 0), c_cut)
        c_nsat = dr.select(new, one_sat, dr.select(grow, c_nsat + one_sat, c_nsat))
        return (j + 1, peak, above, is_nan, c_start, c_max, c_sw, c_swj, c_cut, c_nsat,
                b_start, b_max, b_sw, b_swj, b_cut, b_nsat, other)

    zu, zf, zb = dr.zeros(UInt32, n), dr.zeros(Float, n), dr.zeros(Bool, n)
    ninf = dr.full(Float, -dr.inf, n)
    state = (zu, ninf, zb, zb, zu, ninf, zf, zf, zb, zu, zu, ninf, zf, zf, zb, zu, ninf)
    (_, peak, in_run, _, c_start, c_max, c_sw, c_swj, c_cut, c_nsat, b_start, b_max, b_sw, b_swj,
     b_cut, b_nsat, other) = dr.while_loop(state, lambda j, *_: j < nr, body,
                                           label="lts360_profiles")
    (b_start, b_max, b_sw, b_swj, b_cut, b_nsat), other = close(
        in_run, dr.full(Bool, True, n), (c_start, c_max, c_sw, c_swj, c_cut, c_nsat),
        (b_start, b_max, b_sw, b_swj, b_cut, b_nsat), other)
    has = peak > thr
    centre = dr.select(has, Float(b_start) + b_swj / b_sw, dr.nan)
    q = dr.select(has, UInt32(int(Quality.FOUND)), UInt32(int(Quality.NO_PEAK)))
    if saturation is not None:
        q = dr.select(has & (peak >= sat), UInt32(int(Quality.SATURATED)), q)
        if max_plateau is not None:
            q = dr.select(has & (b_nsat > dr.opaque(UInt32, int(max_plateau))),
                          UInt32(int(Quality.SATURATED_PLATEAU)), q)
    several = has & (other >= dr.opaque(Float, fraction) * peak)
    q = dr.select(several, UInt32(int(Quality.SEVERAL_PEAKS)), q)
    q = dr.select(has & b_cut, UInt32(int(Quality.TRUNCATED)), q)
    return centre, q, peak, other


class FastInverse:
    """Dr.Jit version of the per-image work of :func:`inverse_triangulate` for one plan.

    Parameters
    ----------
    plan : InversePlan
        From :func:`lts360.recon.triangulation.inverse.plan_inverse` (the sampler need not be precomputed).
    backend : {"llvm", "cuda"}

    Notes
    -----
    Device memory: 12 bytes per grid point (window index and fractional position; 42 MB for
    the standard grid) plus 64 bytes per window.
    """

    def __init__(self, plan: InversePlan, *, backend: str = "llvm") -> None:
        if not isinstance(plan, InversePlan):
            raise ValueError(f"plan must be an InversePlan, got {type(plan).__name__}")
        dr, mod = _backend(backend)
        self.dr, self.mod, self.plan = dr, mod, plan
        self.backend = backend
        w, h = plan.cal.image_size
        self.shape = (h, w)
        self.nr = plan.grid.n_r
        r = np.asarray(plan.grid.r_mm, dtype=float)
        self._r0, self._step = float(r[0]), float(r[1] - r[0])
        # All views in one launch: their windowed rows are stacked (each row is nr samples).
        uvs, self._rows = [], {}
        start = 0
        for name, vp in plan.views.items():
            uvs.append(vp.uv.reshape(-1, 2))
            k = len(vp.theta_index)
            self._rows[name] = (start, start + k)
            start += k
        self._n_rows = start
        uv = np.concatenate(uvs) if uvs else np.zeros((0, 2))
        self.interpolation = plan.interpolation
        window, fx, fy, taps = window_layout(
            uv, self.shape, boundary="edge" if self.interpolation == "keys" else "mirror")
        self.n_windows = len(taps)
        self._window = mod.UInt32(window)
        self._fx = mod.Float(fx)
        self._fy = mod.Float(fy)
        self._taps = mod.UInt32(taps.ravel())

    def _device_image(self, image):
        """``image`` if it is a Dr.Jit tensor of this backend (checked), else ``None``."""
        dr = self.dr
        if not dr.is_tensor_v(image):
            return None
        if dr.backend_v(image) != dr.backend_v(self.mod.Float):
            raise ValueError(f"image is a {type(image).__name__} of another Dr.Jit backend than "
                             f"this plan's {self.backend!r}")
        if tuple(image.shape) != self.shape:
            raise ValueError(f"image has shape {tuple(image.shape)}, the plan was built for "
                             f"{self.shape}")
        return image

    def _tap_table(self, img):
        """``(16 n_windows,)`` floats: the taps of every window in this image."""
        dr, mod = self.dr, self.mod
        dev = self._device_image(img)
        if dev is not None and self.interpolation == "keys":
            # Already on the device: the gather reads it there (uint8 converted after).
            table = mod.Float(dr.gather(type(dev.array), dev.array, self._taps))
            dr.eval(table)
            return table
        if dev is not None:  # the B-spline prefilter runs on the host
            img = dev.numpy()
        if self.interpolation == "bspline":
            img = prefilter(img, "bspline")  # B-spline coefficients, on the host (scipy)
        flat = np.ascontiguousarray(img).ravel()
        if flat.dtype == np.uint8:  # 1 byte per pixel over the bus, converted after the gather
            table = mod.Float(dr.gather(mod.UInt8, mod.UInt8(flat), self._taps))
        else:
            table = dr.gather(mod.Float, mod.Float(flat.astype(np.float32, copy=False)),
                              self._taps)
        dr.eval(table)
        return table

    def _profile_kernel(self, table, threshold, saturation, fraction, max_plateau=None):
        """Walk every profile once; return centroid radius, quality and peak per row."""
        dr, mod = self.dr, self.mod
        Float, UInt32 = mod.Float, mod.UInt32
        n = self._n_rows
        base = dr.arange(UInt32, n) * self.nr
        weights = _keys_weights if self.interpolation == "keys" else _bspline_weights

        def sample(j):
            p = base + j
            taps = dr.gather(mod.ArrayXf, table, dr.gather(UInt32, self._window, p),
                             shape=(16, n))
            wx = weights(dr.gather(Float, self._fx, p))
            wy = weights(dr.gather(Float, self._fy, p))
            acc = None
            for k in range(4):
                row = (wx[0] * taps[4 * k] + wx[1] * taps[4 * k + 1] + wx[2] * taps[4 * k + 2]
                       + wx[3] * taps[4 * k + 3])
                acc = wy[k] * row if acc is None else acc + wy[k] * row
            return acc

        centre, q, peak, other = _walk_profiles(dr, mod, sample, n, self.nr, threshold,
                                                saturation, fraction, max_plateau)
        return self._r0 + self._step * centre, q, peak, other

    def peaks(self, image, *, threshold: float, saturation: float | None,
              second_peak_fraction: float = DEFAULT_SECOND_PEAK_FRACTION,
              max_plateau_mm: float | None = DEFAULT_MAX_PLATEAU_MM) -> dict[str, PeakResult]:
        """Per view: the centroid peak of every windowed θ (numpy arrays on return), radii on
        the grid's base radii ``grid.r_mm`` (:func:`assemble_view` adds the per-θ shift)."""
        dr = self.dr
        img = self._device_image(image)
        if img is None:
            img = np.asarray(image)
            if img.shape != self.shape:
                raise ValueError(f"image has shape {img.shape}, the plan was built for {self.shape}")
        if self._n_rows == 0:
            return {name: PeakResult(r_mm=np.zeros(0), quality=np.zeros(0, np.uint8),
                                     intensity=np.zeros(0), second=np.zeros(0))
                    for name in self._rows}
        table = self._tap_table(img)
        rc, q, peak, other = self._profile_kernel(
            table, float(threshold), None if saturation is None else float(saturation),
            float(second_peak_fraction), plateau_samples(max_plateau_mm, self.plan.grid.r_mm))
        dr.eval(rc, q, peak, other)
        r_all = np.asarray(rc, dtype=float)
        q_all = np.asarray(q, dtype=np.uint8)
        p_all = np.asarray(peak, dtype=float)
        o_all = np.asarray(other, dtype=float)
        res = {}
        for name, (a, b) in self._rows.items():
            r, quality, pk, ot = r_all[a:b], q_all[a:b], p_all[a:b], o_all[a:b]
            keep = np.isfinite(r) | (quality == Quality.NO_PEAK) | (quality == Quality.TRUNCATED)
            quality = np.where(keep, quality, np.uint8(Quality.NO_PEAK)).astype(np.uint8)
            r = np.where(quality == Quality.NO_PEAK, np.nan, r)
            res[name] = PeakResult(r_mm=r, quality=quality,
                                   intensity=np.where(np.isfinite(pk), pk, np.nan),
                                   second=np.where(np.isfinite(ot), ot, np.nan))
        return res

    def __call__(self, image, *, threshold: float | None = None, saturation: float | None = None,
                 accept=DEFAULT_ACCEPT, compensate: bool = False) -> InverseResult:
        """Same result as ``inverse_triangulate(image, cal, grid, peak="centroid", plan=plan,
        compensate=compensate)`` (to float32 rounding).

        ``image`` : (H, W) array, or a Dr.Jit tensor of this backend (``TensorXu8``,
        ``TensorXf``) already on the device — a rendered frame that never left it: only the
        per-θ results are read back (and, for a float tensor without ``threshold``, its
        maximum)."""
        img = self._device_image(image)
        if img is None:
            img = np.asarray(image)
            thr = default_threshold(img) if threshold is None else float(threshold)
            sat = default_saturation(img) if saturation is None else float(saturation)
        else:  # the defaults of the numpy image: full scale of an integer type, else its max
            integer = {self.dr.VarType.UInt8: 255.0, self.dr.VarType.UInt16: 65535.0}.get(
                self.dr.type_v(img))
            if threshold is not None:
                thr = float(threshold)
            elif integer is not None:
                thr = default_threshold(np.zeros(0, np.uint8 if integer == 255.0 else np.uint16))
            else:  # one scalar read back (a float image's maximum)
                peak = float(self.dr.max(img.array)[0]) if self.dr.width(img.array) else 0.0
                thr = default_threshold(np.array([max(peak, 0.0)], np.float32))
            sat = (integer if saturation is None else float(saturation))
        if sat is not None and sat <= thr:
            sat = None
        peaks = self.peaks(img, threshold=thr, saturation=sat)
        cal = self.plan.cal

        views = {name: assemble_view(self.plan.views[name], self.plan.grid, pk, accept=accept,
                                     **compensation_of(cal, name, compensate))
                 for name, pk in peaks.items()}
        return InverseResult(grid=self.plan.grid, views=views, peak="centroid", threshold=thr,
                             saturation=sat, compensated=bool(compensate),
                             accept=tuple(Quality(q) for q in accept))
