"""The design model's coverage stage: smooth coverage of the section, the views' overlaps,
multiple reflections, and the penalties that keep a design within its constraints and its
rig valid (:mod:`lts360.design.model`)."""

from __future__ import annotations

import math

from lts360.design.elements import Elements

__all__ = ["OVERLAP_SAFETY_DEG", "coverage_stage"]

#: The smooth overlaps are held this much above the required overlap (the smooth and the hard
#: overlap differ by up to a sigmoid width at each end of a window).
OVERLAP_SAFETY_DEG = 2.0


def coverage_stage(e: Elements, views: dict, singles: list, doubles: list, at_user) -> dict:
    """Per case: coverage (deg, a point detected in any single view), the overlaps of the
    direct view with each mirror view and of the two mirror views (deg), the share of
    measured points that a double reflection also images (%), and ``rig_pen`` (the rig's own
    validity: mirrors clear the largest object, camera and laser in front of both mirrors,
    focus beyond the focal length) and ``pen`` (the conditions' penalties), both gathered to
    the reported cases."""
    o, cond, P, geo = e.o, e.cond, e.P, e.geo
    dr = o.dr
    n_th = e.n_th
    step_deg = math.degrees(2.0 * math.pi / n_th)
    none_single = 1.0
    for name in singles:
        none_single = none_single * (1.0 - views[name]["detected"])
    union1 = 1.0 - none_single
    none_double = 1.0
    for name in doubles:
        none_double = none_double * (1.0 - views[name]["measured"])
    cov = e.case_sum(union1 * step_deg)
    mir = [m.name for m in e.base.mirrors]
    md, ml, mr = (views[nm]["detected"] for nm in ("direct", mir[0], mir[1]))
    ov_dl, ov_dr, ov_lr = (e.case_sum(a * b * step_deg) for a, b in ((md, ml), (md, mr), (ml, mr)))
    multi = e.case_sum(union1 * (1.0 - none_double) * (100.0 / n_th))
    wpen = cond.penalty_um_per_deg2
    min_ov = cond.min_overlap_deg + OVERLAP_SAFETY_DEG if cond.min_overlap_deg > 0 else 0.0
    pen = wpen * (o.relu2(cond.min_coverage_deg - cov) + o.relu2(min_ov - ov_dl)
                  + o.relu2(min_ov - ov_dr) + o.relu2(min_ov - ov_lr)
                  + o.relu2(multi - cond.max_multi_reflection_pct))
    # The rig's own validity: mirrors clear the largest object, camera and laser in front.
    r_max = float(e.base.design.max_object_radius_mm)
    clear = P["mirror_corner_distance_mm"] * dr.sin(P["beta_deg"] * (math.pi / 360.0)) - r_max
    rig_pen = o.relu2(1.0 - clear) + o.relu2(r_max + 1.0 - P["laser_distance_mm"])
    for m in geo["mirrors"]:
        rig_pen = rig_pen + o.relu2(1.0 - (dr.dot(m.n, geo["pos"]) - m.d))
        rig_pen = rig_pen + o.relu2(1.0 - (dr.dot(m.n, geo["laser"]) - m.d))
    s_f, f_mm = P["focus_distance_mm"], P["focal_length_mm"]
    rig_pen = rig_pen + o.relu2(1.0 - (s_f - f_mm))
    rig_pen = e.case_sum(rig_pen * (1.0 / n_th))  # the same in every element: per case
    return dict(coverage_deg=at_user(cov), ov_dl=at_user(ov_dl), ov_dr=at_user(ov_dr),
                ov_lr=at_user(ov_lr), multi=at_user(multi), penalty_um=at_user(pen + 1e3 * rig_pen))
