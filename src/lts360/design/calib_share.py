"""The design model's shares stage: the §4.4 compensation's and the calibration's shares of
the radius' variance (:mod:`lts360.design.shares` holds the closed forms), and the
calibration covariance the model predicts per design from a board plan."""

from __future__ import annotations

import numpy as np

from lts360.design.backend import DrJitOps, drjit_ops
from lts360.design.calib_covariance import CalibrationPlan
from lts360.design.camera import Distortion, camera_frame_normals, rig_geometry, rot
from lts360.design.elements import Elements
from lts360.design.params import PARAMETERS
from lts360.design.shares import compensation_shares

__all__ = ["calibration_dr", "plan_covariance_dr", "plan_covariance_at", "shares_stage"]


def plan_covariance_dr(o, space, plan: CalibrationPlan, grid: dict, p_all):
    """The plan's calibration covariance of every design (per-design arrays)."""
    dr, F = o.dr, o.F
    A = {k[5:]: v for k, v in grid.items() if k.startswith("plan_")}
    designs = dr.width(A["one"])
    ops = drjit_ops()
    npar = len(PARAMETERS)
    cam = space.base.camera
    k1, k2 = float(cam.distortion[0]), float(cam.distortion[1])

    def view(di):
        P = {prm.name: dr.gather(F, p_all, di * npar + i) for i, prm in enumerate(PARAMETERS)}
        geo = rig_geometry(o, P, space)
        R, pos = geo["R"], geo["pos"]

        def rot_list(v):
            x, y, z = v
            return [x + 0.0 * pos.x, R[1][1] * y + R[1][2] * z, R[2][1] * y + R[2][2] * z]

        def to_cam(X):
            return rot_list([X[0] - pos.x, X[1] - pos.y, X[2] - pos.z])

        return {"rot": rot_list, "to_cam": to_cam, "pos": [pos.x, pos.y, pos.z],
                "intr": (geo["f_px"], geo["f_px"], geo["cx"], geo["cy"], k1, k2),
                "mirrors": [([m.n.x, m.n.y, m.n.z], m.d) for m in geo["mirrors"]]}

    return plan.covariance(ops, A, view, designs)


def plan_covariance_at(space, plan: CalibrationPlan, x=None) -> np.ndarray:
    """The covariance the model predicts for ``plan`` at one design (numpy, over
    ``plan.names``; for checks and reports)."""
    o = DrJitOps()
    values = space.values(x)
    p_all = o.F(np.array([values[p.name] for p in PARAMETERS]))
    A = {f"plan_{k}": v for k, v in plan.arrays(o.F, o.U, 1).items()}
    rows = plan_covariance_dr(o, space, plan, A, p_all)
    K = len(plan.names)
    out = np.zeros((K, K))
    for i in range(K):
        for j in range(K):
            if rows[i][j] is not None:
                out[i, j] = float(np.asarray(o.dr.detach(rows[i][j]).numpy()).reshape(-1)[0])
    return out


def _tangent_world(o, R, n_world):
    """The calibration's tangent basis (``tangent_basis`` of the plane's camera-frame normal)
    carried back to the world.  Every normal of the design space has |n_cam.x| < 0.9 (the
    laser's is 0, a mirror's cos(β/2) ≤ 0.87), so the reference axis is always x."""
    dr, V3 = o.dr, o.V3
    n = V3(*rot(R, n_world))
    e1 = dr.normalize(dr.cross(n, V3(1.0, 0.0, 0.0)))
    e2 = dr.cross(n, e1)

    def back(e):  # Rᵀ e
        return V3(e.x, R[1][1] * e.y + R[2][1] * e.z, R[1][2] * e.y + R[2][2] * e.z)

    return back(e1), back(e2)


def calibration_dr(o, geo: dict, vw: dict, mirrors, mirror_names, names, X, ct, st,
                   dist: Distortion):
    """Per element, the radius change ``δr^k`` (mm per unit) of every calibration parameter.

    The stripe stays at the pixel ``u`` where the true rig images ``X``; the reconstruction,
    with the calibration moved by ``δc_k``, finds the point ``X'`` of its laser plane whose
    (mirrored) projection is ``u``.  For the intrinsics and the mirrors
    ``[∂u/∂r ∂u/∂θ] (δr, δθ) = −δu_k`` (``δu_k`` the change of the projection of the fixed
    ``X``); for the laser plane ``X'`` slides along the (virtual) camera ray to the moved
    plane, ``δr = r̂ · w (δd − δn·X)/(n·w)``.  A plane's ``(a, b, δ)`` turns its camera-frame
    normal and shifts its camera-frame offset: in the world ``δn = Rᵀ e``, ``δd = δ + δn·C``
    (C the camera centre).
    """
    dr = o.dr
    jt = vw["jt"]
    cross = vw["cross"]
    seq = vw["seq"]
    xn, yn, zs = vw["xn"], vw["yn"], vw["zs"]
    f = geo["f_px"]
    xd, yd = dist.apply(xn, yn)
    r2 = xn * xn + yn * yn
    pos, R = geo["pos"], geo["R"]

    def from_du(du0, du1):
        # jr δr + jt δθ = −δu  →  δr = (δu × jt) / (jt × jr), with a × b = a0 b1 − a1 b0.
        return (du0 * jt[1] - du1 * jt[0]) / cross

    def jac_world(e):  # ∂u/∂Y · e at the view's (virtual) point Y
        dxc, dyc, dzc = rot(R, e)
        dxn = (dxc - xn * dzc) / zs
        dyn = (dyc - yn * dzc) / zs
        ddx, ddy = dist.jacobian_apply(xn, yn, dxn, dyn)
        return f * ddx, f * ddy

    zero = 0.0 * ct
    cam = {"fx": (xd, zero), "fy": (zero, yd), "cx": (1.0 + zero, zero),
           "cy": (zero, 1.0 + zero), "k1": (f * xn * r2, f * yn * r2),
           "k2": (f * xn * r2 * r2, f * yn * r2 * r2),
           "k3": (f * xn * r2 * r2 * r2, f * yn * r2 * r2 * r2),
           "p1": (f * 2.0 * xn * yn, f * (r2 + 2.0 * yn * yn)),
           "p2": (f * (r2 + 2.0 * xn * xn), f * 2.0 * xn * yn)}
    # The (virtual) camera centre of the view, and the ray direction to X.
    c_v = pos
    for kk in seq:
        c_v = o.reflect_point(c_v, mirrors[kk].n, mirrors[kk].d)
    w = X - c_v
    w_r = w.x * ct + w.y * st
    bases = {}
    out = []
    for full in names:
        plane, _, p = full.partition(".")
        if plane == "camera":
            out.append(from_du(*cam[p]))
            continue
        if plane not in bases:
            n_w = o.V3(0.0, 0.0, 1.0) if plane == "laser" else mirrors[mirror_names.index(plane)].n
            bases[plane] = _tangent_world(o, R, n_w)
        if p == "delta":
            dn, dd = None, 1.0
        else:
            e = bases[plane][0 if p == "a" else 1]
            dn, dd = e, dr.dot(e, pos)
        if plane == "laser":
            t = (dd - (0.0 if dn is None else dr.dot(dn, X))) / w.z
            out.append(t * w_r)
            continue
        k = mirror_names.index(plane)
        if k not in seq:  # this view does not reflect in that mirror
            out.append(zero)
            continue
        m = mirrors[k]
        s_m = dr.dot(m.n, X) - m.d
        if dn is None:
            dY = m.n * (2.0 * dd)
        else:
            dY = dn * (-2.0 * s_m) - m.n * (2.0 * (dr.dot(dn, X) - dd))
        out.append(from_du(*jac_world(dY)))
    return out


def shares_stage(e: Elements, space, views: dict, singles: list, noise: dict, grid: dict,
                 p_all, at_user, at_ref):
    """The §4.4 compensation's and the calibration's variance of the radius (mm²) of each
    reported case; zeros when the conditions ask for neither.  Sets ``cal_dr`` in each
    single view when a calibration is given."""
    o, cond = e.o, e.cond
    dr, F = o.dr, o.F
    cal = cond.calibration
    cal_names = list(cal.names) if cal is not None else []
    mir_names = [m_.name for m_ in e.base.mirrors]
    view_dr = {}
    if cal_names:
        for name in singles:
            vw = views[name]
            vw["cal_dr"] = calibration_dr(o, e.geo, vw, e.geo["mirrors"], mir_names, cal_names,
                                          e.X, e.ct, e.st, e.dist)
            m = vw["m"]
            view_dr[name] = [[m * dk, m * dk * e.ct, m * dk * e.st] for dk in vw["cal_dr"]]
    zero = 0.0 * at_user(noise["var_R"])
    if not (cond.compensate or cal_names):
        return zero, zero
    case_sum = e.case_sum
    A_sums = {nm: [case_sum(v) for v in noise["view_A"][nm]] for nm in singles}
    B_sums = {nm: [case_sum(v) for v in noise["view_B"][nm]] for nm in singles}
    dr_sums = {nm: [[case_sum(v) for v in trio] for trio in view_dr[nm]] for nm in view_dr}
    if isinstance(cal, CalibrationPlan):
        cov = [[None if c is None else dr.gather(F, c, grid["udi"]) for c in row]
               for row in plan_covariance_dr(o, space, cal, grid, p_all)]
    else:
        cov = cal.oriented(camera_frame_normals(space)) if cal is not None else None
    return compensation_shares(
        {nm: [at_user(v) for v in A_sums[nm]] for nm in singles},
        {nm: [at_ref(v) for v in A_sums[nm]] for nm in singles},
        {nm: [at_ref(v) for v in B_sums[nm]] for nm in singles},
        {nm: [[at_user(v) for v in trio] for trio in dr_sums[nm]] for nm in dr_sums},
        {nm: [[at_ref(v) for v in trio] for trio in dr_sums[nm]] for nm in dr_sums},
        cov, [nm for nm in singles if nm != "direct"], dr.sqrt,
        shots=int(cond.compensation_shots), compensate=bool(cond.compensate),
        master=bool(cond.master))
