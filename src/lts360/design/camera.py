"""The design model's camera stage: the rig's geometry in Dr.Jit, where each view images the
section (paper Eq. 4, ``g = P · T_π · G``, with the base rig's Brown distortion), the
Jacobians through ``T_π`` and the projection, and the line's image width.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from lts360.design.elements import Elements
from lts360.design.paths import trace

__all__ = ["Mirror", "rig_geometry", "to_cam", "rot", "Distortion", "camera_frame_normals",
           "view_stage", "line_stage"]


@dataclasses.dataclass
class Mirror:
    """A mirror rectangle: plane ``n·X = d``, centre ``c``, in-plane axes ``u``, ``v`` and
    half sizes (mm)."""

    n: object
    d: object
    c: object
    u: object
    v: object
    half_w: object
    half_h: object


def rig_geometry(o, P: dict, space) -> dict:
    """Camera pose, intrinsics, mirrors and laser as Dr.Jit values of the parameters ``P``."""
    dr, V3 = o.dr, o.V3
    base = space.base
    deg = math.pi / 180.0
    a = P["alpha_deg"] * deg
    sa, ca = dr.sin(a), dr.cos(a)
    D = P["camera_distance_mm"]
    pos = V3(0.0, P["camera_target_y_mm"] - D * ca, D * sa)
    # look_at(pos, (0, ty, 0), up=+Z): rows x = (1, 0, 0), y = (0, −sin a, −cos a),
    # z = (0, cos a, −sin a).
    R = ((1.0, 0.0, 0.0), (0.0, -sa, -ca), (0.0, ca, -sa))
    cam = base.camera
    f_px = P["focal_length_mm"] / (cam.pixel_pitch_um * 1e-3)
    cx = (cam.width_px - 1) / 2.0 + float(cam.principal_point_offset_px[0])
    cy = (cam.height_px - 1) / 2.0 + float(cam.principal_point_offset_px[1])
    half = P["beta_deg"] * (deg / 2.0)
    sh, ch = dr.sin(half), dr.cos(half)
    des = base.design
    corner = V3(0.0, P["mirror_corner_distance_mm"], float(des.mirror_center_z_mm))
    mirrors = []
    for sx in (-1.0, 1.0):  # left, right (lts360.scenes.rig._mirrors)
        u = V3(sx * sh, -ch, 0.0 * sh)
        n = V3(-sx * ch, -sh, 0.0 * sh)
        c = corner + u * (P["mirror_width_mm"] / 2.0)
        mirrors.append(Mirror(n=n, d=dr.dot(n, c), c=c, u=u, v=V3(0.0, 0.0, 1.0),
                              half_w=P["mirror_width_mm"] / 2.0,
                              half_h=float(des.mirror_height_mm) / 2.0))
    laser = V3(0.0, -P["laser_distance_mm"], 0.0 * D)
    return dict(pos=pos, R=R, f_px=f_px, cx=cx, cy=cy, mirrors=mirrors, laser=laser)


def to_cam(o, R, pos, Y):
    """Camera coordinates of world points ``Y`` for the look-at rotation ``R``."""
    q = Y - pos
    return (q.x, R[1][1] * q.y + R[1][2] * q.z, R[2][1] * q.y + R[2][2] * q.z)


def rot(R, v):
    """``R v`` for the look-at rotation ``R`` (its first row is (1, 0, 0))."""
    return (v.x, R[1][1] * v.y + R[1][2] * v.z, R[2][1] * v.y + R[2][2] * v.z)


class Distortion:
    """Brown distortion of the base camera (constants) and its Jacobian."""

    def __init__(self, dist):
        self.k1, self.k2, self.p1, self.p2, self.k3 = (float(v) for v in dist)
        self.zero = not any((self.k1, self.k2, self.p1, self.p2, self.k3))

    def apply(self, x, y):
        if self.zero:
            return x, y
        k1, k2, p1, p2, k3 = self.k1, self.k2, self.p1, self.p2, self.k3
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)

    def jacobian_apply(self, x, y, dx, dy):
        if self.zero:
            return dx, dy
        k1, k2, p1, p2, k3 = self.k1, self.k2, self.p1, self.p2, self.k3
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        j00 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
        j01 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
        j11 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
        return j00 * dx + j01 * dy, j01 * dx + j11 * dy


def camera_frame_normals(space) -> dict:
    """The model's plane normals in the base design's camera frame (``{plane: n}``), to
    orient a stored calibration covariance (:meth:`CalibrationCovariance.oriented`)."""
    v = space.values()
    a = math.radians(v["alpha_deg"])
    R = np.array([[1.0, 0.0, 0.0], [0.0, -math.sin(a), -math.cos(a)],
                  [0.0, math.cos(a), -math.sin(a)]])
    half = math.radians(v["beta_deg"]) / 2.0
    out = {"laser": R @ np.array([0.0, 0.0, 1.0])}
    for sx, m in zip((-1.0, 1.0), space.base.mirrors):
        out[m.name] = R @ np.array([-sx * math.cos(half), -math.sin(half), 0.0])
    return out


def view_stage(e: Elements, lit_any) -> dict:
    """Per view (every mirror sequence): where it images each element (``u``, ``v`` px, the
    normalised ``xn``, ``yn`` and depth ``zs``) and whether it sees it (``seen``: valid path,
    incidence, in front of the camera, inside the image with the margin; ``measured``: seen
    and lit)."""
    o, geo, cond = e.o, e.geo, e.cond
    dr = o.dr
    cam = e.base.camera
    W, H = cam.width_px, cam.height_px
    margin = cond.margin_px
    mirrors = geo["mirrors"]
    views = {}
    for seq, name in zip(e.seqs, e.names):
        s_seen, leave, _, _ = trace(o, e.X, geo["pos"], seq, mirrors, e.cxy, e.r, e.w_mm, e.w_cos)
        s_seen = s_seen * o.sig((dr.dot(leave, e.normal) - e.cos_max) / e.w_cos)
        Y = e.X
        for kk in seq:
            Y = o.reflect_point(Y, mirrors[kk].n, mirrors[kk].d)
        xc, yc, zc = to_cam(o, geo["R"], geo["pos"], Y)
        s_seen = s_seen * o.sig(zc / e.w_mm)
        zs = dr.select(zc > 1e-9, zc, 1e-9)
        xn, yn = xc / zs, yc / zs
        xd, yd = e.dist.apply(xn, yn)
        u = geo["f_px"] * xd + geo["cx"]
        v = geo["f_px"] * yd + geo["cy"]
        w_px = e.w_px
        s_seen = s_seen * (o.sig((u + 0.5 - margin) / w_px) * o.sig((W - 0.5 - margin - u) / w_px)
                           * o.sig((v + 0.5 - margin) / w_px)
                           * o.sig((H - 0.5 - margin - v) / w_px))
        views[name] = dict(seq=seq, seen=s_seen, measured=s_seen * lit_any, u=u, v=v, zc=zc,
                           xn=xn, yn=yn, zs=zs)
    return views


def line_stage(e: Elements, views: dict, singles: list, laser: dict) -> None:
    """Per single view, in place: the Jacobians ``jr``, ``jt``, ``jz`` (px per mm, per rad, per
    mm of height), the
    sensitivity ``sens`` (mm of radius per px across the line), the line's image width
    (``sig_geo`` the sheet projected across the line, ``sig_blur`` thin-lens defocus,
    ``sig_opt`` with diffraction, ``sig_w`` with the pixel box), ``arc_px`` (px per measured
    θ step) and ``bright`` (the stripe's peak brightness, relative)."""
    o, geo, P, dist = e.o, e.geo, e.P, e.dist
    dr, V3 = o.dr, o.V3
    ct, st, r = e.ct, e.st, e.r
    mirrors = geo["mirrors"]
    cam, las = e.base.camera, e.base.laser
    rho_m = float(e.base.design.mirror_reflectance)
    f_mm, N = P["focal_length_mm"], P["f_number"]
    s_f = P["focus_distance_mm"]
    aperture = f_mm / N
    pitch_mm = cam.pixel_pitch_um * 1e-3
    lam_um = las.wavelength_nm * 1e-3
    sig_sheet_eff, E_sum = laser["sig_sheet_eff"], laser["E_sum"]
    for name in singles:
        vw = views[name]
        seq = vw["seq"]

        def jac(d, seq=seq, vw=vw):
            for kk in seq:
                d = o.reflect_dir(d, mirrors[kk].n)
            dxc, dyc, dzc = rot(geo["R"], d)
            dxn = (dxc - vw["xn"] * dzc) / vw["zs"]
            dyn = (dyc - vw["yn"] * dzc) / vw["zs"]
            ddx, ddy = dist.jacobian_apply(vw["xn"], vw["yn"], dxn, dyn)
            return geo["f_px"] * ddx, geo["f_px"] * ddy

        jr = jac(V3(ct, st, 0.0 * ct))
        jt = jac(V3(-r * st, r * ct, 0.0 * ct))
        jz = jac(V3(0.0 * ct, 0.0 * ct, 1.0 + 0.0 * ct))
        jt_norm = dr.sqrt(jt[0] * jt[0] + jt[1] * jt[1] + 1e-24)
        cross = jt[0] * jr[1] - jt[1] * jr[0]
        vw.update(jr=jr, jt=jt, jz=jz, cross=dr.select(dr.abs(cross) > 1e-12, cross, 1e-12))
        sens = jt_norm / dr.sqrt(cross * cross + 1e-24)  # mm per px across the line
        nz = (-jt[1] * jz[0] + jt[0] * jz[1]) / jt_norm
        sig_geo = sig_sheet_eff * dr.sqrt(nz * nz + 1e-24)
        dz = vw["zs"] - s_f
        blur_mm = aperture * f_mm * dr.sqrt(dz * dz + 1e-12) / (vw["zs"] * (s_f - f_mm))
        sig_blur = blur_mm / (4.0 * pitch_mm)
        sig_diff = 0.42 * lam_um * 1e-3 * N / pitch_mm
        sig_opt = dr.sqrt(sig_geo * sig_geo + sig_blur * sig_blur + sig_diff * sig_diff)
        sig_w = dr.sqrt(sig_opt * sig_opt + 1.0 / 12.0)
        vw.update(sens=sens, sig_geo=sig_geo, sig_blur=sig_blur, sig_opt=sig_opt, sig_w=sig_w,
                  arc_px=jt_norm * math.radians(e.cond.theta_step_meas_deg),
                  bright=E_sum * (rho_m ** len(seq)) * sig_geo / sig_w)
