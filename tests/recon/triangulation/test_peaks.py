import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lts360.recon.triangulation.peaks import (
    Quality,
    centroid,
    detect_peaks,
    gauss,
    main_run,
    steger,
)

STEP_MM = 0.005                       # the standard radial step (5 µm)
R_MM = 8.0 + np.arange(801) * STEP_MM
AMP, THR = 200.0, 20.0

#: Tolerances in radial samples, noise-free Gaussian profiles of σ >= 3 samples:
TOL = {
    # (I − T)+ has a kink where the profile crosses the threshold: the discrete first moment
    # misses a sliver of O(step²) there; measured <= 0.009 sample over σ in [3, 60] samples.
    "centroid": 0.02,
    # ln of a Gaussian is a parabola: the fit is exact up to rounding.
    "gauss": 1e-9,
    # Linear interpolation of the zero of g′: g′ is cubic-ish near the top, error ~ t³/σ²;
    # measured <= 0.0035 sample for σ_filter = 2 samples, 3e-4 for the default 11.5 samples.
    "steger": 0.01,
}


def _profiles(centres_mm, sigmas_mm, amp=AMP, background=0.0):
    c = np.asarray(centres_mm, dtype=float)[:, None]
    s = np.asarray(sigmas_mm, dtype=float)[:, None]
    return amp * np.exp(-0.5 * ((R_MM - c) / s) ** 2) + background


centre_st = st.tuples(st.integers(300, 500), st.floats(-0.5, 0.5))   # sample index, offset
width_st = st.floats(3.0, 60.0)                                        # σ in samples


@given(c=centre_st, w=width_st)
def test_centroid_is_unbiased_on_gaussian_profiles(c, w):
    centre = R_MM[c[0]] + c[1] * STEP_MM
    res = centroid(_profiles([centre], [w * STEP_MM]), R_MM, threshold=THR)
    assert res.quality[0] == Quality.FOUND
    assert abs(res.r_mm[0] - centre) / STEP_MM < TOL["centroid"]
    # The largest sample is at most half a sample off the top: 1 − exp(−0.125 / w²) below it.
    assert res.intensity[0] == pytest.approx(AMP, rel=0.13 / w**2)


@given(c=centre_st, w=width_st, fit=st.sampled_from(["lsq", "3point"]))
def test_gauss_fit_is_exact_on_gaussian_profiles(c, w, fit):
    centre = R_MM[c[0]] + c[1] * STEP_MM
    res = gauss(_profiles([centre], [w * STEP_MM]), R_MM, threshold=THR, fit=fit)
    assert abs(res.r_mm[0] - centre) / STEP_MM < TOL["gauss"]


@given(c=centre_st, w=width_st, sigma=st.floats(2.0, 20.0))
def test_steger_is_unbiased_on_gaussian_profiles(c, w, sigma):
    centre = R_MM[c[0]] + c[1] * STEP_MM
    res = steger(_profiles([centre], [w * STEP_MM]), R_MM, threshold=THR, sigma_mm=sigma * STEP_MM)
    assert abs(res.r_mm[0] - centre) / STEP_MM < TOL["steger"]


@pytest.mark.parametrize("method", ["centroid", "gauss", "steger"])
def test_detectors_are_unbiased_under_noise(method):
    """Moment test: with white noise the mean error over many profiles is zero within 4 SE."""
    rng = np.random.default_rng(7)
    n = 2000
    centre = 10.0 + 0.37 * STEP_MM
    prof = _profiles(np.full(n, centre), np.full(n, 0.1)) + rng.normal(0.0, 2.0, (n, R_MM.size))
    res = detect_peaks(method, prof, R_MM, threshold=THR)
    err = res.r_mm - centre
    assert np.all(res.quality == Quality.FOUND)
    assert abs(err.mean()) < 4 * err.std() / np.sqrt(n)
    assert err.std() < 0.5 * STEP_MM  # 1 % noise on a 20-sample-wide line: sub-sample scatter


def test_vectorised_over_a_batch():
    rng = np.random.default_rng(3)
    centres = 10.0 + rng.uniform(-1, 1, 500)
    sig = rng.uniform(0.02, 0.3, 500)
    prof = _profiles(centres, sig)
    for method in ("centroid", "gauss", "steger"):
        res = detect_peaks(method, prof, R_MM, threshold=THR)
        one = detect_peaks(method, prof[17:18], R_MM, threshold=THR)
        # The same result as alone, to rounding: numpy's SIMD paths differ with the array
        # length, so the last bit may (seen once in CI: 2e-15 mm).
        assert res.r_mm.shape == (500,) and abs(res.r_mm[17] - one.r_mm[0]) <= 1e-12
        assert np.max(np.abs(res.r_mm - centres)) / STEP_MM < max(TOL[method], 0.02)


def test_quality_flags():
    base = _profiles([10.0], [0.1])[0]
    second = base + 0.8 * AMP * np.exp(-0.5 * ((R_MM - 11.0) / 0.05) ** 2)
    small = base + 0.3 * AMP * np.exp(-0.5 * ((R_MM - 11.0) / 0.05) ** 2)
    saturated = np.minimum(base * 1.5, 255.0)
    dark = np.full(R_MM.size, 5.0)
    nan_row = np.full(R_MM.size, np.nan)
    half_nan = np.where(R_MM < 9.5, np.nan, base)
    prof = np.stack([base, second, small, saturated, dark, nan_row, half_nan])
    for method in ("centroid", "gauss", "steger"):
        res = detect_peaks(method, prof, R_MM, threshold=THR, saturation=255.0)
        q = [Quality(v) for v in res.quality]
        assert q == [Quality.FOUND, Quality.SEVERAL_PEAKS, Quality.FOUND, Quality.SATURATED,
                     Quality.NO_PEAK, Quality.NO_PEAK, Quality.FOUND], method
        assert np.isnan(res.r_mm[4:6]).all() and np.isfinite(res.r_mm[[0, 1, 2, 3, 6]]).all()
        # The strongest peak wins; a saturated plateau is still centred.
        assert abs(res.r_mm[1] - 10.0) < 0.01 and abs(res.r_mm[3] - 10.0) < 0.01
        assert np.isnan(res.intensity[5]) and res.intensity[0] == pytest.approx(AMP, rel=1e-3)


def test_main_run_is_the_connected_run_around_the_maximum():
    prof = np.array([[0, 30, 0, 10, 50, 60, 40, 0, 25, 0.0]])
    mr = main_run(prof, 20.0)
    assert np.flatnonzero(mr.run[0]).tolist() == [4, 5, 6]
    assert mr.quality[0] == Quality.SEVERAL_PEAKS  # 30 >= 0.5 * 60
    assert main_run(prof, 20.0, second_peak_fraction=0.6).quality[0] == Quality.FOUND


def test_bad_arguments():
    prof = _profiles([10.0], [0.1])
    with pytest.raises(ValueError, match="r_mm"):
        centroid(prof, R_MM[:-1], threshold=THR)
    with pytest.raises(ValueError, match="saturation"):
        centroid(prof, R_MM, threshold=THR, saturation=10.0)
    with pytest.raises(ValueError, match="uniformly"):
        gauss(prof, np.r_[R_MM[:-1], R_MM[-1] + 1.0], threshold=THR)
    with pytest.raises(ValueError, match="peak must be"):
        detect_peaks("parabola", prof, R_MM, threshold=THR)


def test_a_line_cut_by_the_band_or_a_nan_sample_is_truncated():
    """A line at the band's inner or outer end, or against NaN samples (outside the image or
    beyond the view's mirror), is TRUNCATED in every detector, and never FOUND; a line clear of
    both is not, even with NaN samples beyond a gap below the threshold."""
    inner = _profiles([R_MM[0] + 0.05], [0.1])[0]         # the run starts at sample 0
    outer = _profiles([R_MM[-1] - 0.02], [0.1])[0]        # ... ends at the last sample
    cut = np.where(R_MM > 10.05, np.nan, _profiles([10.0], [0.1])[0])   # NaN inside the run
    clear = np.where(R_MM > 10.6, np.nan, _profiles([10.0], [0.1])[0])  # NaN beyond a gap
    prof = np.stack([inner, outer, cut, clear])
    for method in ("centroid", "gauss", "steger"):
        res = detect_peaks(method, prof, R_MM, threshold=THR)
        assert [Quality(q) for q in res.quality] == [Quality.TRUNCATED] * 3 + [Quality.FOUND], \
            method


def test_a_wide_saturated_plateau_has_its_own_flag():
    """Clipped at full scale: a narrow top stays SATURATED (still located), a plateau wider than
    ``max_plateau_mm`` is SATURATED_PLATEAU; ``None`` lifts the limit."""
    line = _profiles([10.0], [0.1], amp=1.0)[0]
    narrow = np.minimum(300.0 * line, 255.0)               # top above 255 over ~0.06 mm
    wide = np.minimum(3000.0 * line, 255.0)                # ... over ~0.48 mm
    prof = np.stack([narrow, wide])
    width = lambda p: (p >= 255.0).sum() * STEP_MM  # noqa: E731
    assert width(narrow) < 0.15 < width(wide)
    for method in ("centroid", "gauss", "steger"):
        res = detect_peaks(method, prof, R_MM, threshold=THR, saturation=255.0)
        assert [Quality(q) for q in res.quality] == [Quality.SATURATED,
                                                     Quality.SATURATED_PLATEAU], method
    res = centroid(prof, R_MM, threshold=THR, saturation=255.0, max_plateau_mm=None)
    assert (res.quality == Quality.SATURATED).all()
    assert abs(res.r_mm[1] - 10.0) < 1e-3  # symmetric: the clipped centre is still right


def test_quality_codes_are_stable():
    """Codes are stored as uint8 in the PLY: new ones are appended, never renumbered."""
    assert [(q.name, int(q)) for q in Quality] == [
        ("FOUND", 0), ("NO_PEAK", 1), ("SATURATED", 2), ("SEVERAL_PEAKS", 3),
        ("OUTSIDE_WINDOW", 4), ("TRUNCATED", 5), ("SATURATED_PLATEAU", 6), ("DISCONTINUOUS", 7),
        ("NOTCH", 8), ("FADING", 9), ("HIDDEN", 10), ("FLANK", 11),
        ("NEIGHBOURS", 12)]
