"""Bicubic (Keys cubic convolution) sampling of an image at sub-pixel positions.

The kernel is Keys' (IEEE TASSP 29(6), 1981) with ``a = −0.5`` — the "cubic interpolation" of
MATLAB's ``interp2``, used by the paper (§3.2) — not OpenCV's ``INTER_CUBIC`` (``a = −0.75``)
and not scipy's cubic B-spline.  With ``a = −0.5`` it interpolates (equals the pixel value at
integer positions) and reproduces polynomials up to degree 2 exactly.

Coordinates follow OpenCV: ``uv[..., 0]`` is the column ``u`` (x), ``uv[..., 1]`` the row ``v``
(y), pixel centres at integers.

Borders: a point is *inside* when ``0 <= u <= w − 1`` and ``0 <= v <= h − 1`` (the hull of the
pixel centres).  Taps of an inside point that fall outside the image take the value of the
nearest edge pixel (edge replication).  Points outside, or with a NaN coordinate, get
``fill_value`` (NaN by default; pass 0.0 for dark background).

A scan images the same grid many times: :class:`CubicSampler` stores, per point, the flat index
of its (0, 0) tap in the edge-padded image and the 16 weights (the 16 flat indices are that
index plus 16 fixed offsets, so they need not be stored), so sampling a new image is one
gather and a weighted sum.  Storing the 16 weights instead of the 4 + 4 separable factors
costs 2.4× the memory and halves the sampling time (0.14 s instead of 0.33 s for 3.6 M points
on one core).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["KEYS_A", "keys_kernel", "keys_weights", "CubicSampler", "sample_cubic"]

KEYS_A = -0.5
#: Points processed at once: bounds the (chunk, 16) temporaries to a few MB (cache friendly).
_CHUNK = 1 << 14
#: Padding of the image: one pixel before, two after (taps −1 … +2 around floor(u)).
_PAD_BEFORE, _PAD_AFTER = 1, 2


def keys_kernel(x, a: float = KEYS_A) -> np.ndarray:
    """Keys' cubic convolution kernel ``W(x)`` (support ``|x| < 2``)."""
    x = np.abs(np.asarray(x, dtype=float))
    out = np.zeros_like(x)
    m1 = x <= 1
    m2 = (x > 1) & (x < 2)
    out[m1] = ((a + 2) * x[m1] - (a + 3)) * x[m1] ** 2 + 1
    out[m2] = a * (((x[m2] - 5) * x[m2] + 8) * x[m2] - 4)
    return out


def keys_weights(t: np.ndarray) -> np.ndarray:
    """Weights of the taps at offsets ``−1, 0, 1, 2`` for fractional positions ``t`` in [0, 1].

    Closed form of ``W(1 + t), W(t), W(1 − t), W(2 − t)`` for ``a = −0.5``; rows sum to 1.

    Parameters
    ----------
    t : (n,) float

    Returns
    -------
    (n, 4) float
    """
    t = np.asarray(t, dtype=float)
    out = np.empty(t.shape + (4,))
    tm1 = t - 1.0
    out[..., 0] = -0.5 * t * tm1 * tm1
    out[..., 1] = 0.5 * ((3.0 * t - 5.0) * t * t + 2.0)
    out[..., 2] = 0.5 * t * ((4.0 - 3.0 * t) * t + 1.0)
    out[..., 3] = 0.5 * t * t * tm1
    return out


def _image_shape(image_shape) -> tuple[int, int]:
    shape = tuple(int(s) for s in image_shape)
    if len(shape) != 2 or min(shape) < 1:
        raise ValueError(f"image_shape must be (height, width) with positive sizes, "
                         f"got {image_shape}")
    return shape


def _pad(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D (height, width), got shape {img.shape}")
    if img.dtype.kind not in "uif":
        raise ValueError(f"image must hold numbers, got dtype {img.dtype}")
    if img.dtype.kind == "f" or img.dtype.itemsize > 2:
        img = img.astype(np.float64, copy=False)  # small integers stay small: cheaper gathers
    return np.pad(img, ((_PAD_BEFORE, _PAD_AFTER), (_PAD_BEFORE, _PAD_AFTER)), mode="edge")


@dataclass(frozen=True, eq=False)
class CubicSampler:
    """Precomputed Keys bicubic sampling of a fixed set of points in images of one size.

    Build it with :meth:`from_points`; call it with an image to get the samples.

    Attributes
    ----------
    image_shape : (int, int)
        ``(height, width)`` of the images it samples.
    out_shape : tuple of int
        Shape of the returned samples (``uv.shape[:-1]``).
    base : (n,) int
        Flat index, in the edge-padded image ``(h + 3, w + 3)``, of each point's (0, 0) tap
        (``floor(v)``, ``floor(u)``); 0 for points outside.
    weights : (n, 16) float
        Keys weights of the taps ``(dy, dx)`` in ``{−1, 0, 1, 2}²``, row-major
        (``weights[:, 4 (dy + 1) + dx + 1] = W_v(dy) W_u(dx)``).
    inside : (n,) bool
        Points inside the image (others give ``fill_value``).
    fill_value : float
    """

    image_shape: tuple[int, int]
    out_shape: tuple[int, ...]
    base: np.ndarray
    weights: np.ndarray
    inside: np.ndarray
    fill_value: float

    @classmethod
    def from_points(cls, uv, image_shape, *, fill_value: float = np.nan,
                    dtype=np.float64) -> "CubicSampler":
        """Precompute taps and weights.

        Parameters
        ----------
        uv : (..., 2) float
            Pixel coordinates ``(u, v)``; NaN allowed (→ ``fill_value``).
        image_shape : (int, int)
            ``(height, width)``.
        fill_value : float
            Value of points outside the image.
        dtype : numpy float dtype
            Storage of the weights (``float32`` halves the memory of a large grid; the
            sample then carries a relative rounding of ~1e-7).
        """
        h, w = _image_shape(image_shape)
        uv = np.asarray(uv, dtype=float)
        if uv.ndim < 1 or uv.shape[-1] != 2:
            raise ValueError(f"uv must have shape (..., 2), got {uv.shape}")
        out_shape = uv.shape[:-1]
        flat = uv.reshape(-1, 2)
        u, v = flat[:, 0], flat[:, 1]
        with np.errstate(invalid="ignore"):
            inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
        u = np.where(inside, u, 0.0)
        v = np.where(inside, v, 0.0)
        iu = np.floor(u)
        iv = np.floor(v)
        index_dtype = np.int32 if (h + 3) * (w + 3) < 2**31 else np.int64
        base = ((iv.astype(np.int64) + _PAD_BEFORE) * (w + _PAD_BEFORE + _PAD_AFTER)
                + iu.astype(np.int64) + _PAD_BEFORE).astype(index_dtype)
        weights = np.einsum("py,px->pyx", keys_weights(v - iv), keys_weights(u - iu))
        return cls(image_shape=(h, w), out_shape=out_shape, base=base,
                   weights=weights.reshape(-1, 16).astype(dtype, copy=False), inside=inside,
                   fill_value=float(fill_value))

    @property
    def n_points(self) -> int:
        return int(self.base.size)

    @property
    def nbytes(self) -> int:
        return int(self.base.nbytes + self.weights.nbytes + self.inside.nbytes)

    def _offsets(self) -> np.ndarray:
        stride = self.image_shape[1] + _PAD_BEFORE + _PAD_AFTER
        d = np.arange(-1, 3)
        return (d[:, None] * stride + d[None, :]).ravel()  # (16,) row-major (dy, dx)

    def __call__(self, image) -> np.ndarray:
        """Sample ``image`` (shape ``image_shape``) at the stored points.

        Returns
        -------
        out_shape float
            Interpolated values (float64), ``fill_value`` outside.
        """
        img = np.asarray(image)
        if img.shape != self.image_shape:
            raise ValueError(f"image has shape {img.shape}, the sampler was built for "
                             f"{self.image_shape}")
        flat = _pad(img).ravel()
        offsets = self._offsets()
        out = np.empty(self.n_points)
        for s in range(0, self.n_points, _CHUNK):
            e = min(s + _CHUNK, self.n_points)
            taps = flat[self.base[s:e, None] + offsets]  # (chunk, 16), row-major (dy, dx)
            out[s:e] = np.einsum("pk,pk->p", taps, self.weights[s:e], dtype=np.float64)
        out[~self.inside] = self.fill_value
        return out.reshape(self.out_shape)


def sample_cubic(image, uv, *, fill_value: float = np.nan) -> np.ndarray:
    """Keys bicubic interpolation of ``image`` at pixel coordinates ``uv``.

    Parameters
    ----------
    image : (h, w) array
        Greyscale image (any integer or float dtype).
    uv : (..., 2) float
        ``(u, v)`` = (column, row), pixel centres at integers.
    fill_value : float
        Value for points outside ``[0, w − 1] × [0, h − 1]`` or with NaN coordinates.

    Returns
    -------
    (...) float
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D (height, width), got shape {img.shape}")
    uv = np.asarray(uv, dtype=float)
    if uv.ndim < 1 or uv.shape[-1] != 2:
        raise ValueError(f"uv must have shape (..., 2), got {uv.shape}")
    flat = uv.reshape(-1, 2)
    out = np.empty(len(flat))
    step = 16 * _CHUNK  # bounds the temporary weights to ~35 MB
    for s in range(0, len(flat), step):
        part = flat[s:s + step]
        out[s:s + len(part)] = CubicSampler.from_points(part, img.shape, fill_value=fill_value)(img)
    return out.reshape(uv.shape[:-1])
