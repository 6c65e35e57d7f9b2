"""The design model's noise stage: the auto-exposure, the line-position noise of the paper's
detector (speckle, shot and read noise, pixel locking) and the σ of the radius after the
circle fit (:mod:`lts360.design.model`)."""

from __future__ import annotations

import math

from lts360.design.elements import Elements
from lts360.design.locking import LOCKING_COEFFS, SIGMA_MAX, SIGMA_MIN

__all__ = ["SPECKLE_MODELS", "CORRELATION_PX", "EXPOSURE_POWER", "EXPOSURE_TARGET",
           "THRESHOLD_FRACTION", "DETECT_MARGIN", "DETECT_WIDTH", "pixel_speckle_contrast",
           "exposure_reference", "noise_stage"]

#: ``"pixel"``: the simulator's speckle — a multiplicative pattern of pixel-integrated contrast
#: ``C_px`` (independent between pixels) on a Gaussian line of σ_w px, whose threshold centroid
#: then scatters by ``σ² = C_px² σ_w N2 / D1²`` (``C_px² σ_w / (4 √π)`` without threshold;
#: see :func:`noise_stage` and docs/design.md).  ``"dorsch"``: the optical limit of Dorsch,
#: Häusler and Herrmann (Appl. Opt. 33(7) 1994), ``δx = C λ / (2π sin u)`` in the object with
#: ``C = 1`` (fully developed speckle as the lens images it) and ``sin u = A / (2 L)`` the
#: aperture seen along the view's own path ``L``; in the image that is ``λ N / (π p)`` px for
#: every view.
SPECKLE_MODELS = ("pixel", "dorsch")
#: Stripe length (px) over which the errors of neighbouring points are correlated (they share
#: pixels): a point's weight in the circle fit's covariance grows by ``1 + ℓ / arc_px``.
CORRELATION_PX = 1.0
#: Auto-exposure: the stripe's brightness reference is a power mean of this order over the
#: measured points (a smooth stand-in for the simulator's 99.9th percentile).
EXPOSURE_POWER = 16.0
#: Auto-exposure target, as a fraction of the full well.
EXPOSURE_TARGET = 0.8
#: Threshold of the peak detector (fraction of full scale) — sets the centroid's window, and
#: a point counts as detected when its peak exceeds it by DETECT_MARGIN (a smooth step of
#: width DETECT_WIDTH / sharpness in that ratio).
THRESHOLD_FRACTION = 0.1
DETECT_MARGIN = 0.25
DETECT_WIDTH = 0.25


def pixel_speckle_contrast(pixel_pitch_um: float, wavelength_nm: float, f_number: float) -> float:
    """Contrast of fully developed speckle integrated by a square pixel (the model's formula).

    The speckle's intensity correlation ``[2 J1(x)/x]²`` is replaced by the Gaussian of the same
    area ``A_c = 4 λ² N² / π``; then per axis
    ``1/M₁ = (2/p²) ∫₀^p (p − Δ) exp(−π Δ²/A_c) dΔ`` in closed form, ``C = 1/M₁`` (``M = M₁²``).
    For 5.3 µm, 660 nm: f/2.8 0.344, f/8 0.726, f/1.4 0.184; the simulator's exact integral
    (:func:`lts360.simulator.speckle.speckle_contrast_theory`, at N(1 + m)): 0.340, 0.726, 0.185.
    """
    lam = wavelength_nm * 1e-3
    a = math.pi / (4.0 * lam * lam * f_number * f_number / math.pi)
    p = pixel_pitch_um
    inv_m1 = (2.0 / (p * p)) * (p * math.sqrt(math.pi) / (2.0 * math.sqrt(a))
                                * math.erf(math.sqrt(a) * p) - (1.0 - math.exp(-a * p * p)) / (2.0 * a))
    return min(inv_m1, 1.0)


def exposure_reference(e: Elements, views: dict, singles: list):
    """Per element, its case's brightness reference: a power mean (order
    :data:`EXPOSURE_POWER`) of the measured points' brightness (one image per case)."""
    dr = e.o.dr
    q = EXPOSURE_POWER
    num, den = 0.0, 0.0
    for name in singles:
        vw = views[name]
        num = num + e.case_sum(vw["measured"] * dr.exp(q * dr.log(vw["bright"] + 1e-300)))
        den = den + e.case_sum(vw["measured"])
    return dr.gather(e.o.F, dr.exp(dr.log(num / (den + 1e-30) + 1e-300) / q), e.ci)


def noise_stage(e: Elements, views: dict, singles: list, b_ref) -> dict:
    """Line-position noise (px across the line) per view and point, σ_r (mm), the detected
    points, and the circle fit's radius variance per case.

    Sets in each single view: ``noise`` (px, by source), ``sigma_r_mm``, ``e_peak``
    (electrons), ``detected`` and ``m`` (measured points per model sample).  Returns
    ``cs`` (per-case moment sums), ``var_R`` (mm², per case, before gathering to the
    reported cases), ``view_A`` and ``view_B`` (per view, the six moment terms of
    :func:`lts360.design.shares.compensation_shares`).
    """
    o, cond = e.o, e.cond
    dr = o.dr
    ct, st = e.ct, e.st
    cam, las, sensor = e.base.camera, e.base.laser, e.base.sensor
    N = e.P["f_number"]
    lam_um = las.wavelength_nm * 1e-3
    fw = float(sensor.full_well_e)
    K = float(sensor.system_gain)
    read2 = float(sensor.dark_noise_e) ** 2 + 1.0 / (12.0 * K * K)
    # The threshold in electrons (10 % of full scale, less the black level).
    thr_e = (THRESHOLD_FRACTION * (2 ** int(sensor.bit_depth) - 1)
             - float(sensor.dark_offset_dn)) / K
    a_c = 4.0 * lam_um * lam_um * N * N / math.pi  # speckle correlation area (µm²)
    a_g = math.pi / a_c
    p_um = cam.pixel_pitch_um
    sa = dr.sqrt(a_g)
    inv_m1 = (2.0 / (p_um * p_um)) * (p_um * math.sqrt(math.pi) / (2.0 * sa) * dr.erf(sa * p_um)
                                      - (1.0 - dr.exp(-a_g * p_um * p_um)) / (2.0 * a_g))
    c_px2 = dr.minimum(inv_m1 * inv_m1, 1.0)  # pixel-integrated speckle contrast²
    c0, c1, c2, c3 = LOCKING_COEFFS
    sums = {key: 0.0 for key in ("a", "b", "c", "d", "e", "f", "Sa", "Sb", "Sc", "Sd", "Se",
                                 "Sf", "m", "msr2", "msp2")}
    step = 2.0 * math.pi / e.n_th
    nu = math.degrees(step) / cond.theta_step_meas_deg  # measured points per model sample
    view_A, view_B = {}, {}
    for name in singles:
        vw = views[name]
        sw = vw["sig_w"]
        # At least one electron: an unlit point then has a large but finite σ (and weight 0).
        e_peak = dr.maximum(EXPOSURE_TARGET * fw * vw["bright"] / b_ref, 1.0)
        # Centroid of I − t over the run above the threshold t = τ·peak, in units of σ_w:
        # window ±a, a = √(2 ln 1/τ); D1 = ∫(g − τ), N1 = ∫x² g, N2 = ∫x² g² (g = e^{−x²/2}).
        tau = dr.clip(thr_e / e_peak, 1e-3, 0.95)
        a = dr.sqrt(2.0 * dr.log(1.0 / tau))
        erf_a2 = dr.erf(a * (1.0 / math.sqrt(2.0)))
        ea2 = dr.exp(-0.5 * a * a)
        d1 = math.sqrt(2.0 * math.pi) * erf_a2 - 2.0 * a * tau
        n1 = math.sqrt(2.0 * math.pi) * erf_a2 - 2.0 * a * ea2
        n2 = 0.5 * math.sqrt(math.pi) * dr.erf(a) - a * ea2 * ea2
        n_shot2 = sw * n1 / (e_peak * d1 * d1)
        n_read2 = read2 * sw * (2.0 * a * a * a / 3.0) / (e_peak * e_peak * d1 * d1)
        if cond.speckle == "pixel":
            n_sp2 = c_px2 * sw * n2 / (d1 * d1)
        else:
            n_sp = lam_um * N / (math.pi * p_um)
            n_sp2 = n_sp * n_sp + 0.0 * sw
        so = dr.clip(vw["sig_opt"], SIGMA_MIN, SIGMA_MAX)
        n_lock = dr.exp(c0 + so * (c1 + so * (c2 + so * c3)))
        n_lock2 = n_lock * n_lock
        noise2 = n_sp2 + n_shot2 + n_read2 + n_lock2
        sr_mm = dr.sqrt(noise2) * vw["sens"]
        vw.update(noise=dict(speckle=dr.sqrt(n_sp2), shot=dr.sqrt(n_shot2),
                             read=dr.sqrt(n_read2), locking=n_lock), sigma_r_mm=sr_mm,
                  e_peak=e_peak)
        # The peak detector's threshold: a line whose peak falls under it (dim, or blurred
        # by defocus) is lost.
        ratio = e_peak / thr_e
        vw["detected"] = vw["measured"] * o.sig((ratio - 1.0 - DETECT_MARGIN)
                                                / (DETECT_WIDTH / e.k))
        m = vw["detected"] * nu
        vw["m"] = m
        corr = 1.0 + CORRELATION_PX / (vw["arc_px"] + 1e-12)
        w2 = m * corr * sr_mm * sr_mm
        basis6 = (1.0, ct, st, ct * ct, ct * st, st * st)
        view_A[name] = [m * b for b in basis6]
        view_B[name] = [w2 * b for b in basis6]
        for key, val in (("a", 1.0), ("b", ct), ("c", st), ("d", ct * ct), ("e", ct * st),
                         ("f", st * st)):
            sums[key] = sums[key] + m * val
            sums["S" + key] = sums["S" + key] + w2 * val
        sums["m"] = sums["m"] + m
        sums["msr2"] = sums["msr2"] + m * sr_mm * sr_mm
        sums["msp2"] = sums["msp2"] + m * n_sp2 * vw["sens"] * vw["sens"]
    cs = {key: e.case_sum(val + 0.0 * ct) for key, val in sums.items()}
    return dict(cs=cs, var_R=_fit_variance(dr, cs), view_A=view_A, view_B=view_B)


def _fit_variance(dr, cs: dict):
    """The variance of ``R`` in the weighted least-squares fit of
    ``r_i = R + a cos θ_i + b sin θ_i`` (sandwich ``g ᵀ S g`` with ``g`` the first row of the
    normal matrix's inverse), per case."""
    a_, b_, c_, d_, e_, f_ = (cs[key] for key in "abcdef")
    det = a_ * (d_ * f_ - e_ * e_) - b_ * (b_ * f_ - c_ * e_) + c_ * (b_ * e_ - c_ * d_)
    det = dr.maximum(det, 1e-30)
    g0, g1, g2 = (d_ * f_ - e_ * e_) / det, (c_ * e_ - b_ * f_) / det, (b_ * e_ - c_ * d_) / det
    var_R = (g0 * (cs["Sa"] * g0 + cs["Sb"] * g1 + cs["Sc"] * g2)
             + g1 * (cs["Sb"] * g0 + cs["Sd"] * g1 + cs["Se"] * g2)
             + g2 * (cs["Sc"] * g0 + cs["Se"] * g1 + cs["Sf"] * g2))
    return dr.maximum(var_R, 0.0)
