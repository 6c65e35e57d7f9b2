"""The line-centre bias of a curved section, in closed form, and what the corrections leave.

Every point of a section is measured at the centroid of the stripe's image across the line.
The stripe is a *curved* line blurred in two ways:

* the image's point spread (thin-lens defocus, diffraction and the pixel box; isotropic,
  variance ``σ_psf²`` px² per axis), and
* the sheet's thickness: the band the sheet lights on the surface is the section's curve
  repeated at every height ``z`` of the sheet's Gaussian (σ_z mm), each copy translated in the
  image by ``∂u/∂z · z``.

Pulled back into the sheet plane (the image's local affine map ``J = [∂u/∂r, ∂u/∂θ / r]``;
the measurement searches along the image of the radial line, which pulls back to the radial
line), both are a blur of the section's circle whose *tangential* part moves the circle's
centroid toward its centre of curvature: a copy displaced by ``t`` along the curve crosses
the normal at ``κ t² / 2``, so to first order the profile across the line is shifted, not
reshaped, by ``κ σ_t² / 2`` (and the thresholded centroid reads that shift).  With
``κ = 1/r`` and ``σ_t²`` the tangential variance in the plane::

    δr = −σ_t² / (2 r),
    σ_t² = r² (σ_psf² |∂u/∂r|² + σ_z² (∂u/∂r × ∂u/∂z)²) / (∂u/∂r × ∂u/∂θ)².

``∂u/∂θ`` grows with ``r``, so ``δr ∝ 1/r``: the bias of a small section is the larger.  The
profile's part across the line (the sheet's width seen across it) only widens the line.

That holds for a stripe equally bright all along.  It is not: the light per unit of arc,
``w(θ) ∝ E σ_z |∂u/∂z × ∂u/∂θ|`` (the irradiance integrated over the sheet's height times the
band's image area; Lambertian: the image irradiance is the radiance's), changes along the
section (the laser's incidence and path, the view's obliquity).  A copy moved by ``(d_r, d_t)``
crosses the normal where the curve's point ``s = −d_t`` lies, with that point's weight
``w(1 − g d_t)``, ``g = ∂ ln w / ∂s``; and the blur pulled back into the plane correlates the
radial and tangential moves (``C_rt ≠ 0`` wherever the view is oblique), so the crossing's
mean moves by a second term of the same order::

    δr = −C_tt / (2 r) − g C_rt,   g = (1/r) ∂ ln w / ∂θ,
    C = σ_psf² (JᵀJ)⁻¹ + σ_z² v vᵀ,  J = [∂u/∂r, ∂u/∂θ / r],  v = J⁻¹ ∂u/∂z

(``C_tt`` is the ``σ_t²`` above).  Checked against the exact blurred section for oblique
affine maps and weights (``tests/design/test_bias.py``); :data:`WEIGHT_GRADIENT` switches the
second term (the closed form before it was found: ``False``).

What the corrections leave (:class:`~lts360.design.model.Conditions`):

* the §4.4 compensation (translations per view, a free circle) leaves the bias as it is;
* a master (the compensation's reference of known diameter, ``master=True``) fits a radial
  offset per view: each view's mean bias *at the master's diameter* is removed, what is left
  is ``δr − b_view(R_master)``;
* the digital twin (``bias_model="twin"``) renders the same physics and removes it; it leaves
  :data:`TWIN_RESIDUAL_FRACTION` of the bias (measured, not derived: STUDIES.md "Line-centre
  bias and the digital twin", twin-corrected |bias| ≤ 1.35 µm of 12.7 µm at Ø6 mm and
  ≤ 0.53 µm of 6.8 µm at Ø12–28 mm).

Not in the closed form: the projection's own curvature (perspective; ≲ r/Z of the bias), the
second-order terms of the blur (``(σ_t/r)⁴``), the thin lens's defocus beyond a blur of its
variance (a strongly defocused view reads more: STUDIES.md, "The design model's line-centre
bias"), pixel locking (zero-mean over a section) and the renderer's sampling.
"""

from __future__ import annotations

import math

__all__ = ["TWIN_RESIDUAL_FRACTION", "BIAS_MODELS", "WEIGHT_GRADIENT", "bias_stage",
           "point_bias_mm", "plane_covariance"]

#: The share of the line-centre bias the twin leaves (measured with the true calibration at
#: 64 spp, STUDIES.md "Line-centre bias and the digital twin": ≤ 0.11 of it at every
#: diameter; the estimated calibration's twin differs from the true one's by ≤ 0.8 µm in 25
#: of 27 views, "Measuring with an estimated calibration").
TWIN_RESIDUAL_FRACTION = 0.1
#: The bias corrections of the measurement the model is evaluated for.
BIAS_MODELS = ("twin", "none")
#: The stripe's brightness gradient along the section in the bias (the ``− g C_rt`` term).
WEIGHT_GRADIENT = True
#: The largest ``|r g|`` (per radian of θ) the bias uses: the log-derivative of the stripe's
#: light is clipped where it leaves the lit or seen arc (a soft edge, not a gradient).
MAX_LOG_SLOPE = 5.0


def point_bias_mm(dr, r, jr, jt, jz, psf2_px2, sig_z_mm, g_per_mm=0.0):
    """The closed-form line-centre bias ``δr`` (mm, negative: toward the centre) of each
    element, from its image Jacobians ``jr`` (px/mm), ``jt`` (px/rad), ``jz`` (px/mm), the
    image's isotropic point-spread variance (px²), the sheet's σ (mm) and the stripe's light
    log-gradient along the section ``g`` (per mm of arc): ``−C_tt/(2r) − g C_rt``."""
    c_tt, c_rt = plane_covariance(dr, r, jr, jt, jz, psf2_px2, sig_z_mm)
    return -0.5 * c_tt / r - g_per_mm * c_rt


def plane_covariance(dr, r, jr, jt, jz, psf2_px2, sig_z_mm):
    """The tangential variance ``C_tt`` and the radial–tangential covariance ``C_rt`` (mm²) of
    the image's blur (isotropic, ``psf2_px2``) and the sheet's height (σ ``sig_z_mm``, moving
    the image by ``jz`` per mm) pulled back into the sheet plane through ``J = [jr, jt/r]``."""
    cross_rt = jr[0] * jt[1] - jr[1] * jt[0]
    inv2 = 1.0 / (cross_rt * cross_rt + 1e-24)
    cross_rz = jr[0] * jz[1] - jr[1] * jz[0]
    cross_zt = jz[0] * jt[1] - jz[1] * jt[0]
    jr2 = jr[0] * jr[0] + jr[1] * jr[1]
    dot_rt = jr[0] * jt[0] + jr[1] * jt[1]
    s2 = sig_z_mm * sig_z_mm
    c_tt = r * r * (psf2_px2 * jr2 + s2 * cross_rz * cross_rz) * inv2
    # (JᵀJ)⁻¹_rt = −r (jr·jt)/(jr×jt)²; v = J⁻¹ jz = ((jz×jt)/(jr×jt), r (jr×jz)/(jr×jt))
    c_rt = r * (-psf2_px2 * dot_rt + s2 * cross_zt * cross_rz) * inv2
    return c_tt, c_rt


def _log_slope(e, grid: dict, vw: dict, laser: dict):
    """``g`` (per mm of arc): the θ-derivative of the log of the stripe's light per unit of
    arc, ``E σ_z |jz × jt|``, by central differences over the element's θ neighbours, over
    ``r``; clipped to ``|r g| ≤`` :data:`MAX_LOG_SLOPE`."""
    o = e.o
    dr = o.dr
    jt, jz = vw["jt"], vw["jz"]
    area = dr.abs(jz[0] * jt[1] - jz[1] * jt[0])
    lw = dr.log(laser["E_sum"] * laser["sig_sheet_eff"] * area + 1e-30)
    dth = 2.0 * math.pi / e.n_th
    slope = (dr.gather(o.F, lw, grid["next"]) - dr.gather(o.F, lw, grid["prev"])) / (2.0 * dth)
    return dr.clip(slope, -MAX_LOG_SLOPE, MAX_LOG_SLOPE) / e.r


def _fit_row(dr, cs: dict):
    """The first row of the inverse normal matrix of the fit ``r_i = R + a cos θ + b sin θ``."""
    a_, b_, c_, d_, e_, f_ = (cs[key] for key in "abcdef")
    det = a_ * (d_ * f_ - e_ * e_) - b_ * (b_ * f_ - c_ * e_) + c_ * (b_ * e_ - c_ * d_)
    det = dr.maximum(det, 1e-30)
    return (d_ * f_ - e_ * e_) / det, (c_ * e_ - b_ * f_) / det, (b_ * e_ - c_ * d_) / det


def bias_stage(e, views: dict, singles: list, laser: dict, noise: dict, grid: dict,
               at_user) -> dict:
    """Per reported case (µm): ``bias_um`` the whole line-centre bias of the fitted radius
    (no correction), ``biasv_<view>_um`` each view's mean, and ``bias_left_um`` what the
    conditions' corrections (master, twin) leave of the fitted radius.

    Reads each single view's ``jr``, ``jt``, ``jz``, ``sig_opt``, ``sig_geo`` and ``m`` (the
    measured points' weights of the noise stage)."""
    o, cond = e.o, e.cond
    dr = o.dr
    ct, st = e.ct, e.st
    master = bool(cond.compensate and cond.master)
    n_case = len(cond.model_cases())
    # each element's design's reference case (the last model case of its design)
    ref_of_element = grid["di"] * n_case + (n_case - 1)
    keep = TWIN_RESIDUAL_FRACTION if cond.bias_model == "twin" else 1.0
    out = {}
    sums = {key: 0.0 for key in ("d0", "d1", "d2", "l0", "l1", "l2")}
    for name in singles:
        vw = views[name]
        # σ_opt² = sheet-across-line² + defocus² + diffraction²; the pixel box adds 1/12 px².
        psf2 = dr.maximum(vw["sig_opt"] * vw["sig_opt"] - vw["sig_geo"] * vw["sig_geo"], 0.0) \
            + 1.0 / 12.0
        g = _log_slope(e, grid, vw, laser) if WEIGHT_GRADIENT else 0.0
        db = point_bias_mm(dr, e.r, vw["jr"], vw["jt"], vw["jz"], psf2, laser["sig_sheet_eff"],
                           g)
        # the two parts, per unit variance: ∂δr/∂σ_psf² (mm/px²) and ∂δr/∂σ_z² (1/mm)
        vw["bias_mm"] = db
        vw["bias_per_psf2"] = point_bias_mm(dr, e.r, vw["jr"], vw["jt"], vw["jz"], 1.0, 0.0, g)
        vw["bias_per_sheet2"] = point_bias_mm(dr, e.r, vw["jr"], vw["jt"], vw["jz"], 0.0, 1.0, g)
        m = vw["m"]
        m_sum = e.case_sum(m)
        mean_view = e.case_sum(m * db) / (m_sum + 1e-30)  # per model case
        out[f"biasv_{name}_um"] = at_user(mean_view) * 1e3
        left = db - dr.gather(o.F, mean_view, ref_of_element) if master else db
        for k, basis in enumerate((1.0, ct, st)):
            sums[f"d{k}"] = sums[f"d{k}"] + m * db * basis
            sums[f"l{k}"] = sums[f"l{k}"] + m * left * basis
    g = _fit_row(dr, noise["cs"])
    per_case = {key: e.case_sum(val + 0.0 * ct) for key, val in sums.items()}
    whole = g[0] * per_case["d0"] + g[1] * per_case["d1"] + g[2] * per_case["d2"]
    left = g[0] * per_case["l0"] + g[1] * per_case["l1"] + g[2] * per_case["l2"]
    out["bias_um"] = at_user(whole) * 1e3
    out["bias_left_um"] = at_user(left) * keep * 1e3
    return out
