import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lts360.recon.triangulation.interp import (
    CubicSampler,
    bspline_weights,
    keys_kernel,
    keys_weights,
    sample_cubic,
)

H, W = 40, 56


def _reference(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Textbook Keys interpolation: 16 taps, kernel evaluated at each tap distance, edge clamp."""
    h, w = image.shape
    out = np.empty(len(uv))
    for k, (u, v) in enumerate(uv):
        i0, j0 = int(np.floor(u)), int(np.floor(v))
        acc = 0.0
        for j in range(j0 - 1, j0 + 3):
            for i in range(i0 - 1, i0 + 3):
                acc += image[min(max(j, 0), h - 1), min(max(i, 0), w - 1)] * \
                    keys_kernel(u - i) * keys_kernel(v - j)
        out[k] = acc
    return out


def _quadratic(u, v):
    return 3.0 + 0.7 * u - 1.1 * v + 0.03 * u * u - 0.02 * u * v + 0.05 * v * v


def test_weights_are_the_kernel_and_sum_to_one():
    t = np.linspace(0.0, 1.0, 101)
    ref = np.stack([keys_kernel(1 + t), keys_kernel(t), keys_kernel(1 - t), keys_kernel(2 - t)], -1)
    assert np.allclose(keys_weights(t), ref, atol=1e-15)
    assert np.allclose(keys_weights(t).sum(-1), 1.0, atol=1e-15)
    assert keys_kernel(0.0) == 1.0 and keys_kernel(1.0) == 0.0 and keys_kernel(2.0) == 0.0


def test_interpolates_at_pixel_centres():
    img = np.random.default_rng(0).random((H, W))
    vv, uu = np.mgrid[0:H, 0:W]
    uv = np.column_stack([uu.ravel(), vv.ravel()]).astype(float)
    assert np.allclose(sample_cubic(img, uv), img.ravel(), atol=1e-14)


@given(u=st.floats(1.0, W - 3.0), v=st.floats(1.0, H - 3.0))
def test_reproduces_quadratics_exactly(u, v):
    """Keys (a = −0.5) is third-order accurate: polynomials up to degree 2 come out exactly
    (where all 16 taps lie inside the image; the edge clamp breaks it at the border)."""
    vv, uu = np.mgrid[0:H, 0:W].astype(float)
    img = _quadratic(uu, vv)
    got = sample_cubic(img, [[u, v]])
    assert got[0] == pytest.approx(_quadratic(u, v), abs=1e-11)  # float rounding of ~1e2 values


def test_matches_the_textbook_formula_including_the_border():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (H, W)).astype(np.uint8)
    uv = np.column_stack([rng.uniform(0, W - 1, 300), rng.uniform(0, H - 1, 300)])
    uv[:4] = [[0, 0], [W - 1, H - 1], [0.3, H - 1.2], [W - 1.0, 0.5]]  # corners and edges
    assert np.allclose(sample_cubic(img, uv), _reference(img.astype(float), uv), atol=1e-10)


def test_outside_points_get_the_fill_value():
    img = np.ones((H, W))
    uv = np.array([[-0.01, 5], [W - 0.99, 5], [5, -1], [5, H], [np.nan, 3], [3, 3]])
    out = sample_cubic(img, uv)
    assert np.all(np.isnan(out[:5])) and out[5] == pytest.approx(1.0)
    assert np.array_equal(sample_cubic(img, uv, fill_value=0.0)[:5], np.zeros(5))


def test_precomputed_sampler_equals_direct_sampling_on_new_images():
    rng = np.random.default_rng(2)
    uv = np.stack([rng.uniform(-2, W + 1, (30, 20)), rng.uniform(-2, H + 1, (30, 20))], -1)
    sampler = CubicSampler.from_points(uv, (H, W))
    sampler32 = CubicSampler.from_points(uv, (H, W), dtype=np.float32)
    for _ in range(3):
        img = rng.random((H, W)) * 255
        want = sample_cubic(img, uv)
        got = sampler(img)
        assert got.shape == (30, 20)
        assert np.array_equal(np.isnan(got), np.isnan(want))
        assert np.allclose(got, want, atol=1e-12, equal_nan=True)
        # float32 weights: relative rounding 6e-8 per weight, |Σ w| <= 1.6 → < 1e-4 on 0..255.
        assert np.allclose(sampler32(img), want, atol=1e-4, equal_nan=True)
    with pytest.raises(ValueError, match="shape"):
        sampler(np.zeros((H + 1, W)))


def test_bspline_weights_are_the_cubic_bspline_and_sum_to_one():
    def beta3(x):
        x = np.abs(x)
        return np.where(x < 1, 2 / 3 - x**2 + x**3 / 2, np.where(x < 2, (2 - x) ** 3 / 6, 0.0))

    t = np.linspace(0.0, 1.0, 101)
    ref = np.stack([beta3(1 + t), beta3(t), beta3(1 - t), beta3(2 - t)], -1)
    assert np.allclose(bspline_weights(t), ref, atol=1e-15)
    assert np.allclose(bspline_weights(t).sum(-1), 1.0, atol=1e-15)


def test_bspline_interpolation_is_scipys_including_the_border():
    """Prefilter + 16 taps = ``scipy.ndimage.map_coordinates(order=3, mode="mirror")``; it
    interpolates the pixels (and stays inside with a float32 precomputed sampler)."""
    from scipy.ndimage import map_coordinates

    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (H, W)).astype(np.uint8)
    uv = np.column_stack([rng.uniform(0, W - 1, 300), rng.uniform(0, H - 1, 300)])
    uv[:4] = [[0, 0], [W - 1, H - 1], [0.3, H - 1.2], [W - 1.0, 0.5]]
    want = map_coordinates(img.astype(float), [uv[:, 1], uv[:, 0]], order=3, mode="mirror")
    assert np.allclose(sample_cubic(img, uv, interpolation="bspline"), want, atol=1e-9)
    sampler = CubicSampler.from_points(uv, (H, W), interpolation="bspline", dtype=np.float32)
    assert np.allclose(sampler(img), want, atol=1e-3)  # float32 weights on values 0..255
    vv, uu = np.mgrid[0:H, 0:W]
    centres = np.column_stack([uu.ravel(), vv.ravel()]).astype(float)
    assert np.allclose(sample_cubic(img, centres, interpolation="bspline"), img.ravel(), atol=1e-9)
    with pytest.raises(ValueError, match="interpolation"):
        sample_cubic(img, uv, interpolation="lanczos")
