"""The Dr.Jit hot path agrees with the numpy reference on a rendered, noisy image."""

from __future__ import annotations

import json

import numpy as np
import pytest

dr = pytest.importorskip("drjit", reason="the fast path needs Dr.Jit")


@pytest.fixture(scope="module")
def case():
    mi = pytest.importorskip("mitsuba", reason="rendering the test image needs Mitsuba 3")
    if not dr.has_backend(dr.JitBackend.LLVM):
        pytest.skip("Dr.Jit's LLVM backend is not available")
    mi.set_variant("llvm_ad_mono")
    from lts360.recon.model import calibration_from_frame_truth
    from lts360.recon.triangulation.grid import CylGrid
    from lts360.recon.triangulation.inverse import plan_inverse
    from lts360.scenes.objects import build_object
    from lts360.scenes.rig_io import load_rig
    from lts360.simulator.frame import simulate_frame

    frame = simulate_frame(load_rig("paper"), build_object("plug-gauge:x=0.3"), spp=4, seed=2,
                           noise="realistic")
    cal = calibration_from_frame_truth(json.loads(json.dumps(frame.truth, default=lambda v: v.tolist())))
    grid = CylGrid.from_ranges((8.0, 12.5), theta_step_deg=0.25, r_step_mm=0.005)
    return frame.image, cal, grid, plan_inverse(cal, grid, precompute=False)


@pytest.fixture(scope="module")
def fast(case):
    from lts360.recon.triangulation.fast import FastInverse

    return FastInverse(case[3], backend="llvm")


def _compare(ref, fast_result, *, min_found=100):
    for name, a in ref.views.items():
        b = fast_result.views[name]
        assert np.array_equal(a.quality, b.quality), name
        both = np.isfinite(a.r_mm)
        assert np.array_equal(both, np.isfinite(b.r_mm))
        assert both.sum() > min_found
        # float32 on the device vs float64: measured 9e-7 mm on the standard grid.
        assert np.max(np.abs(a.r_mm[both] - b.r_mm[both])) < 2e-5
        # Peak grey values: float32 Keys weights on the device, float64 in the reference.
        np.testing.assert_allclose(b.intensity[a.window], a.intensity[a.window], rtol=1e-4)
        # the second run's maximum (multipeak's input) the same way, NaN where there is none
        np.testing.assert_array_equal(np.isnan(a.second), np.isnan(b.second))
        ok = ~np.isnan(a.second)
        np.testing.assert_allclose(b.second[ok], a.second[ok], rtol=1e-4)


def test_fast_path_matches_the_numpy_reference(case, fast):
    from lts360.recon.triangulation.inverse import inverse_triangulate

    image, cal, grid, plan = case
    _compare(inverse_triangulate(image, cal, grid, plan=plan), fast(image))


def test_fast_path_flags_match_on_several_peaks_and_saturation(case, fast):
    """A second, weaker stripe (SEVERAL_PEAKS), an over-exposed copy (SATURATED), a strongly
    over-exposed one (SATURATED_PLATEAU) and a float image with NaN pixels and a threshold the
    kernel has not seen (it is not a literal): runs that border a NaN sample are TRUNCATED."""
    from lts360.recon.triangulation.inverse import inverse_triangulate
    from lts360.recon.triangulation.peaks import Quality

    image, cal, grid, plan = case
    img = image.astype(float)
    double = np.clip(img + 0.8 * np.roll(img, 9, axis=0), 0, 255).astype(np.uint8)
    bright = np.clip(3.0 * img, 0, 255).astype(np.uint8)
    holes = img.copy()
    holes[::7, ::5] = np.nan
    blinding = np.clip(20.0 * img, 0, 255).astype(np.uint8)
    for test_image, kwargs, flag, n in [(double, {}, Quality.SEVERAL_PEAKS, 50),
                                        (bright, {}, Quality.SATURATED, 50),
                                        (blinding, {}, Quality.SATURATED_PLATEAU, 0),
                                        (holes, {"threshold": 17.25}, Quality.TRUNCATED, 10)]:
        ref = inverse_triangulate(test_image, cal, grid, plan=plan, **kwargs)
        _compare(ref, fast(test_image, **kwargs), min_found=n)
        if flag is not None:
            assert sum(int(np.sum(v.quality == flag)) for v in ref.views.values()) > 20


def test_fast_path_with_bspline_interpolation(case):
    from lts360.recon.triangulation.fast import FastInverse
    from lts360.recon.triangulation.inverse import inverse_triangulate, plan_inverse

    image, cal, grid, _ = case
    plan = plan_inverse(cal, grid, precompute=False, interpolation="bspline")
    _compare(inverse_triangulate(image, cal, grid, plan=plan), FastInverse(plan)(image))


def test_window_layout_reproduces_the_cubic_sampler():
    from lts360.recon.triangulation.fast import window_layout
    from lts360.recon.triangulation.interp import CubicSampler, interpolation_weights, prefilter

    rng = np.random.default_rng(5)
    h, w = 23, 31
    img = rng.random((h, w))
    uv = np.column_stack([rng.uniform(-2, w + 1, 500), rng.uniform(-2, h + 1, 500)])
    uv[::50] = np.nan
    uv[1:5] = [[0, 0], [w - 1, h - 1], [0.2, h - 1], [w - 1, 0.7]]  # taps beyond the border
    for interpolation, boundary in [("keys", "edge"), ("bspline", "mirror")]:
        window, fx, fy, taps = window_layout(uv, (h, w), boundary=boundary)
        inside = np.isfinite(fx)
        wts = interpolation_weights(np.nan_to_num(fy.astype(float)), interpolation)[:, :, None] \
            * interpolation_weights(np.nan_to_num(fx.astype(float)), interpolation)[:, None, :]
        data = prefilter(img, interpolation).ravel()
        got = np.einsum("pk,pk->p", data[taps[window]], wts.reshape(-1, 16))
        ref = CubicSampler.from_points(uv, (h, w), interpolation=interpolation)(img)
        assert np.array_equal(inside, np.isfinite(ref))
        # fx, fy are float32: ~1e-7 px of position.
        np.testing.assert_allclose(got[inside], ref[inside], rtol=0, atol=1e-6)


def test_fast_path_rejects_a_wrong_image_size(fast):
    with pytest.raises(ValueError, match="shape"):
        fast(np.zeros((10, 10), np.uint8))


def test_profile_walk_matches_main_run_and_centroid():
    """The one-pass run logic of the kernel against :func:`lts360.recon.triangulation.peaks.centroid` on
    random profiles: several runs, equal maxima, runs touching either end or NaN (truncated),
    saturation and saturated plateaus wider than 2 samples."""
    import drjit.llvm as mod

    from lts360.recon.triangulation.fast import _walk_profiles
    from lts360.recon.triangulation.peaks import centroid

    if not dr.has_backend(dr.JitBackend.LLVM):
        pytest.skip("Dr.Jit's LLVM backend is not available")
    rng = np.random.default_rng(7)
    n, nr = 400, 40
    prof = np.round(rng.normal(0.0, 1.0, (n, nr)).cumsum(axis=1), 1).astype(np.float32)
    prof[::9, :5] = np.nan
    prof[1::9, -3:] = 9.0                       # a run at the outer end
    prof[2::9, :2] = 9.0                        # ... and at the inner end
    prof[3::9, 10:13] = prof[3::9, 25:28] = 7.5  # two runs with the same maximum
    prof[4::9] = np.nan                         # all NaN
    threshold, saturation = 1.5, 6.0
    flat = mod.Float(prof.ravel())
    base = dr.arange(mod.UInt32, n) * nr
    centre, q, peak, other = _walk_profiles(
        dr, mod, lambda j: dr.gather(mod.Float, flat, base + j), n, nr, threshold, saturation,
        0.5, 2)
    ref = centroid(prof.astype(float), np.arange(nr, dtype=float), threshold=threshold,
                   saturation=saturation, max_plateau_mm=2.0)
    assert np.array_equal(np.asarray(q, dtype=np.uint8), ref.quality)
    got = np.asarray(centre, dtype=float)
    found = np.isfinite(ref.r_mm)
    assert np.array_equal(found, np.isfinite(got))
    assert np.max(np.abs(got[found] - ref.r_mm[found])) < 1e-4  # float32 sums, in samples
    pk = np.asarray(peak, dtype=float)
    assert np.array_equal(np.isfinite(pk), np.isfinite(ref.intensity))
    assert np.allclose(pk[np.isfinite(pk)], ref.intensity[np.isfinite(pk)])
    ot = np.asarray(other, dtype=float)  # the other runs' largest maximum, as main_run's
    assert np.array_equal(np.isfinite(ot), np.isfinite(ref.second))
    assert np.allclose(ot[np.isfinite(ot)], ref.second[np.isfinite(ot)])
    assert {int(v) for v in np.unique(ref.quality)} == {0, 1, 2, 3, 5, 6}


def test_fast_path_reads_an_image_already_on_the_device(case, fast):
    """A frame kept on the device (a Dr.Jit tensor of the plan's backend, uint8 or float) gives
    the result of the same image from the host, bit for bit: the same kernel on the same
    numbers; a tensor of the wrong shape is refused."""
    from drjit.llvm import TensorXf, TensorXu8

    image = case[0]
    ref = fast(image)
    for dev, host in ((TensorXu8(image), image),
                      (TensorXf(image.astype(np.float32)), image.astype(np.float32))):
        got, want = fast(dev), fast(host)
        assert got.threshold == want.threshold and got.saturation == want.saturation
        for name, a in want.views.items():
            b = got.views[name]
            assert np.array_equal(a.quality, b.quality), name
            assert np.array_equal(a.r_mm, b.r_mm, equal_nan=True), name
    assert fast(TensorXu8(image)).threshold == ref.threshold
    with pytest.raises(ValueError, match="shape"):
        fast(TensorXu8(image[:-1]))
