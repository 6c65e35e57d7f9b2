"""The design model's laser stage: which paths light each section point, the irradiance
there and the sheet's σ (:mod:`lts360.design.model`)."""

from __future__ import annotations

import math

from lts360.design.elements import Elements
from lts360.design.paths import trace

__all__ = ["laser_stage"]


def laser_stage(e: Elements) -> dict:
    """Per element: ``lit_any`` (lit by any virtual laser), ``E_sum`` (irradiance, relative)
    and ``sig_sheet_eff`` (the sheet's Gaussian σ in mm, irradiance-weighted over the paths).

    Every mirror sequence is a virtual laser; its light reaches the point when the path is
    valid (:func:`lts360.design.paths.trace`), within the incidence limit and inside the fan;
    the sheet's σ is the Gaussian beam's at the path length, ``w(L) = w0 √(1 + ((L − L_w)/z_R)²)``,
    σ = w/2; the irradiance falls as ``ρ_mᵏ cos i / (L σ)``.
    """
    o, P = e.o, e.P
    dr = o.dr
    las = e.base.laser
    rho_m = float(e.base.design.mirror_reflectance)
    w0_mm = P["waist_um"] * 1e-3
    lam_mm = las.wavelength_nm * 1e-6
    z_r = math.pi / (lam_mm * las.m_squared) * w0_mm * w0_mm
    cos_half_fan = dr.cos(P["fan_angle_deg"] * (math.pi / 360.0))
    unlit = 1.0
    E_sum, Esig_sum = 0.0, 0.0
    for seq in e.seqs:
        s_lit, leave, arrive, L = trace(o, e.X, e.geo["laser"], seq, e.geo["mirrors"], e.cxy,
                                        e.r, e.w_mm, e.w_cos)
        cos_i = dr.dot(leave, e.normal)
        s_lit = s_lit * o.sig((cos_i - e.cos_max) / e.w_cos)
        s_lit = s_lit * o.sig((-arrive.y - cos_half_fan) / e.w_cos)  # emitted · (0, 1, 0)
        unlit = unlit * (1.0 - s_lit)
        zz = (L - P["laser_distance_mm"]) / z_r
        sig_sheet = 0.5 * w0_mm * dr.sqrt(1.0 + zz * zz)
        E = s_lit * (rho_m ** len(seq)) * dr.maximum(cos_i, 0.0) / (L * sig_sheet)
        E_sum = E_sum + E
        Esig_sum = Esig_sum + E * sig_sheet
    return dict(lit_any=1.0 - unlit, E_sum=E_sum, sig_sheet_eff=Esig_sum / (E_sum + 1e-30))
