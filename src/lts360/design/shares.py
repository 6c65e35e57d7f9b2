"""The radius' shares from the §4.4 compensation and from the calibration, in closed form.

The measurement (paper §4.4, :mod:`lts360.recon.calibration.compensation`) fits, on an image
of a round reference (the plug gauge, centred), one circle and one translation per mirror
view; every later measurement moves each mirror view's points by its translation before the
circle fit.  Both steps are linear least squares in the points' radial errors δr_i, so for a
case (a section radius and centre) the radius error is a linear functional of them.

With ``a_i = (1, cos θ_i, sin θ_i)`` (θ about the case's centre) and the moment sums of each
single view ``v``

    A_v = Σ_{i∈v} m_i a_i a_iᵀ,    B_v = Σ_{i∈v} m_i c_i σ_i² a_i a_iᵀ

(``m`` the detected points, ``c`` the correlation factor, ``σ`` the per-point radius σ), the
case's circle fit gives ``δR = gᵀ Σ m a δr`` with ``g = (Σ_v A_v)⁻¹ e0``, and a translation
``t_v`` of view ``v`` adds ``h_vᵀ t_v`` with ``h_v = (gᵀ A_v[:, 1], gᵀ A_v[:, 2])``.

The reference fit's unknowns are ``q = (R, Cx, Cy, t_v1, t_v2, ...)`` with the rows
``b_i = (1, cos θ, sin θ, −[v = v1] cos θ, −[v = v1] sin θ, ...)``:
``M = Σ m b bᵀ`` and ``S = Σ m c σ² b bᵀ`` are made of the reference case's ``A_v`` and
``B_v``.  The translations' covariance from the reference image's own noise is
``[M⁻¹ S M⁻¹]_tt / shots``, and the *compensation share* of a case is ``hᵀ Cov_t h`` (the
reference and the measured image are different images: independent noise).

A calibration error ``δc_k`` moves each point by ``δr_i^k`` (computed by the model: the
stripe's pixel stays where the true rig puts it, the calibrated model maps it back to
another point of the laser plane).  Its translations are ``t^k = [M⁻¹ y^k]_t`` with
``y^k = Σ_ref m b δr^k``, and the case's radius moves by
``δR^k = gᵀ Σ m a δr^k + Σ_v h_vᵀ t_v^k``; the *calibration share* is
``Σ_kl δR^k C_kl δR^l`` for the calibration's covariance ``C``.

Everything here works on Python lists of arrays (numpy or Dr.Jit), so the model's
reverse-mode gradient runs through it.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from lts360.design.smallmat import spd_inverse_ridged

__all__ = ["CalibrationCovariance", "CAMERA_NAMES", "PLANE_NAMES",
           "compensation_shares", "tangent_basis_np"]

#: Camera parameters of a calibration's covariance (OpenCV's names and order).
CAMERA_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
#: A plane's minimal perturbation: n' = normalise(n + a e1 + b e2), d' = d + δ (rad, rad, mm),
#: (e1, e2) = tangent_basis(n) of the plane's normal in the camera frame.
PLANE_NAMES = ("a", "b", "delta")


def tangent_basis_np(n) -> tuple[np.ndarray, np.ndarray]:
    """The calibration's tangent basis of a plane normal (numpy; the rule of
    ``lts360.recon.calibration.uncertainty.tangent_basis``)."""
    n = np.asarray(n, dtype=float) / np.linalg.norm(n)
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, ref)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


@dataclasses.dataclass(frozen=True)
class CalibrationCovariance:
    """A calibration's covariance in the parameterisation of ``Calibration.uncertainty``.

    Attributes
    ----------
    names : tuple of str
        ``camera.<fx…k3>``, ``<mirror>.<a|b|delta>`` (mirror names of the rig, e.g. ``left``),
        ``laser.<a|b|delta>``.
    cov : tuple of tuples
        The covariance over ``names`` (px², rad², mm², …): hashable, so that a model recorded
        for one covariance is reused.
    normals_cam : tuple of (plane, (nx, ny, nz))
        The planes' normals in the camera frame as the calibration wrote them, when known:
        a normal of the opposite orientation to the model's flips ``a`` and ``δ``.
    source : str
        Where it came from (for reports).
    """

    names: tuple
    cov: tuple
    normals_cam: tuple = ()
    source: str = ""

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.cov, dtype=float).reshape(len(self.names), len(self.names))

    def scaled(self, factor: float) -> "CalibrationCovariance":
        """The covariance times ``factor`` (a calibration ``factor`` times as noisy in variance)."""
        c = self.matrix * float(factor)
        return dataclasses.replace(self, cov=tuple(map(tuple, c.tolist())))

    @classmethod
    def from_uncertainty(cls, unc: dict, planes: dict | None = None, *,
                         source: str = "") -> "CalibrationCovariance":
        """From a ``Calibration.uncertainty`` dict (the calibration file's layout).

        The camera block is the jackknife covariance when present, else the stds (diagonal);
        each plane its ``cov_abd``; the blocks independent of each other, as
        :func:`lts360.recon.calibration.uncertainty.sample_calibration` draws them.
        ``planes``: ``{name: normal_cam}`` (``laser`` for the laser plane), for orientation.

        Raises
        ------
        ValueError
            A block of the wrong shape, or a covariance not symmetric positive semidefinite.
        """
        names, blocks = [], []
        cam = (unc or {}).get("camera") or {}
        if cam.get("cov") is not None and cam.get("cov_names") is not None:
            c = np.asarray(cam["cov"], dtype=float)
            cn = list(cam["cov_names"])
            if c.shape != (len(cn), len(cn)) or not set(cn) <= set(CAMERA_NAMES):
                raise ValueError(f"camera.cov: must be square over {list(CAMERA_NAMES)}")
            names += [f"camera.{n}" for n in cn]
            blocks.append(c)
        elif cam.get("std"):
            std = cam["std"]
            cn = [n for n in CAMERA_NAMES if n in std]
            names += [f"camera.{n}" for n in cn]
            blocks.append(np.diag([float(std[n]) ** 2 for n in cn]))
        for name, m in sorted(((unc or {}).get("mirrors") or {}).items()):
            if m.get("cov_abd") is not None:
                names += [f"{name}.{p}" for p in PLANE_NAMES]
                blocks.append(_plane_block(m["cov_abd"], f"mirrors.{name}.cov_abd"))
        lp = (unc or {}).get("laser_plane") or {}
        if lp.get("cov_abd") is not None:
            names += [f"laser.{p}" for p in PLANE_NAMES]
            blocks.append(_plane_block(lp["cov_abd"], "laser_plane.cov_abd"))
        n = len(names)
        C = np.zeros((n, n))
        k = 0
        for b in blocks:
            C[k:k + len(b), k:k + len(b)] = b
            k += len(b)
        if n and (not np.allclose(C, C.T, atol=1e-15 + 1e-9 * np.abs(C).max())
                  or np.linalg.eigvalsh(0.5 * (C + C.T)).min() < -1e-9 * max(np.abs(C).max(), 1e-300)):
            raise ValueError("calibration covariance: not symmetric positive semidefinite")
        normals = tuple(sorted((k2, tuple(float(v) for v in np.asarray(v2, float)))
                               for k2, v2 in (planes or {}).items()))
        return cls(names=tuple(names), cov=tuple(map(tuple, C.tolist())), normals_cam=normals,
                   source=source)

    @classmethod
    def from_file(cls, path) -> "CalibrationCovariance":
        """From a calibration JSON written by ``lts360 calibrate``.

        Raises
        ------
        ValueError
            The file has no ``uncertainty``, or it is malformed.
        """
        data = json.loads(Path(path).read_text())
        unc = data.get("uncertainty")
        if not unc:
            raise ValueError(f"{path}: the calibration has no uncertainty block")
        planes = {}
        for m in data.get("mirrors") or []:
            if "n" in m and "name" in m:
                planes[m["name"]] = m["n"]
        lp = data.get("laser_plane")
        if isinstance(lp, dict) and "n" in lp:
            planes["laser"] = lp["n"]
        elif isinstance(lp, (list, tuple)) and len(lp) == 2:
            planes["laser"] = lp[0]
        return cls.from_uncertainty(unc, planes, source=str(path))

    def oriented(self, model_normals_cam: dict) -> np.ndarray:
        """The covariance in the model's plane orientations (``{plane: normal_cam}``): a plane
        whose stored normal points the other way has its ``a`` and ``δ`` negated."""
        C = self.matrix.copy()
        stored = dict(self.normals_cam)
        sign = np.ones(len(self.names))
        for i, nm in enumerate(self.names):
            plane, _, p = nm.partition(".")
            if plane in stored and plane in model_normals_cam and p in ("a", "delta"):
                if float(np.dot(stored[plane], model_normals_cam[plane])) < 0:
                    sign[i] = -1.0
        return C * np.outer(sign, sign)


def _plane_block(cov, what: str) -> np.ndarray:
    c = np.asarray(cov, dtype=float)
    if c.shape != (3, 3) or not np.all(np.isfinite(c)):
        raise ValueError(f"{what}: must be a finite 3×3 covariance")
    return c



def _moments(s6) -> list:
    """The 3×3 symmetric matrix of the six sums (1, c, s, c², cs, s²)."""
    one, c, s, cc, cs, ss = s6
    return [[one, c, s], [c, cc, cs], [s, cs, ss]]


def _regressors(views: list, mirror_views: list, master: bool) -> list:
    """The reference fit's unknowns as ``(view or None, basis index, sign)``: ``None`` for
    the section's own (radius and centre), else the view whose points it moves; the basis
    (0: 1, 1: cos θ, 2: sin θ) and its sign in the points' model.

    §4.4: ``(R, Cx, Cy)`` and a translation per mirror view (``−t·(cos, sin)``).  Mastered
    (the radius known): ``(Cx, Cy)``, a radial offset per view and a translation per mirror
    view."""
    regs = ([] if master else [(None, 0, 1.0)]) + [(None, 1, 1.0), (None, 2, 1.0)]
    if master:
        regs += [(v, 0, -1.0) for v in views]
    for v in mirror_views:
        regs += [(v, 1, -1.0), (v, 2, -1.0)]
    return regs


def _normal_matrix(regs: list, sums: dict, views: list, zero) -> list:
    """``Σ m b bᵀ`` (or the sandwich's ``S`` with the ``B`` sums) of the regressors."""
    mom = {v: _moments(sums[v]) for v in views}
    n = len(regs)
    M = [[zero] * n for _ in range(n)]
    for a, (va, fa, sa) in enumerate(regs):
        for b, (vb, fb, sb) in enumerate(regs):
            if b < a:
                M[a][b] = M[b][a]
                continue
            both = views if va is None and vb is None else \
                [v for v in views if (va is None or va == v) and (vb is None or vb == v)]
            M[a][b] = sum((mom[v][fa][fb] for v in both), zero) * (sa * sb)
    return M


def compensation_shares(case_A: dict, ref_A: dict, ref_B: dict, case_dr: dict, ref_dr: dict,
                        cov_cal, mirror_views: list, sqrt, *, shots: int, compensate: bool,
                        master: bool = False):
    """Variance of the radius from the compensation's noise and from the calibration.

    Parameters
    ----------
    case_A : {view: six arrays}
        The case's per-view moment sums of ``m`` (1, cos, sin, cos², cos sin, sin²).
    ref_A, ref_B : {view: six arrays}
        The reference case's moment sums of ``m`` and of ``m c σ²`` (mm²), aligned with the
        case's elements (each case's arrays hold its design's reference).
    case_dr, ref_dr : {view: list over k of three arrays}
        ``Σ m δr^k (1, cos, sin)`` per view (mm per unit of parameter k), in the case and in
        the reference.
    cov_cal : (K, K) numpy array, or K rows of K arrays (per case; None where zero), or None
    mirror_views : list of str
        The views that get a translation (every single view but the direct one).
    shots : int
        Reference images the compensation is fitted to (its noise falls as 1/shots).
    master : bool
        The reference's radius is known (a master): the fit has no radius and a radial
        offset per view (:func:`_regressors`).

    Returns
    -------
    (var_comp, var_cal) : arrays (mm²), per case.
    """
    views = list(case_A)
    zero = 0.0 * case_A[views[0]][0]
    Mc = [[zero] * 3 for _ in range(3)]
    for v in views:
        m = _moments(case_A[v])
        Mc = [[Mc[i][j] + m[i][j] for j in range(3)] for i in range(3)]
    Pc = spd_inverse_ridged(Mc, sqrt)
    g = [Pc[0][0], Pc[0][1], Pc[0][2]]  # (M_c⁻¹ e0)
    regs = _regressors(views, mirror_views, bool(master))
    # The case's radius per unit of each fitted unknown that moves a view's points (the
    # points are corrected by subtracting the unknown's part of the model): −sign · gᵀ A_v[:, f].
    resp = []
    for v, f, sgn in regs:
        if v is None:
            resp.append(zero)
            continue
        m = _moments(case_A[v])
        resp.append(-sgn * (g[0] * m[0][f] + g[1] * m[1][f] + g[2] * m[2][f]))
    nt = len(regs)
    var_comp, P = zero, None
    if compensate:
        P = spd_inverse_ridged(_normal_matrix(regs, ref_A, views, zero), sqrt)
        S = _normal_matrix(regs, ref_B, views, zero)
        # x = P r: the reference's response to the case's r; the share is xᵀ S x / shots.
        x = [sum((P[i][j] * resp[j] for j in range(nt)), zero) for i in range(nt)]
        Sx = [sum((S[i][j] * x[j] for j in range(nt)), zero) for i in range(nt)]
        var_comp = sum((x[i] * Sx[i] for i in range(nt)), zero) * (1.0 / shots)
    var_cal = zero
    if cov_cal is not None:
        K = len(cov_cal)
        dR = []
        for k in range(K):
            tot = [zero, zero, zero]
            for v in views:
                tot = [tot[c] + case_dr[v][k][c] for c in range(3)]
            val = g[0] * tot[0] + g[1] * tot[1] + g[2] * tot[2]
            if compensate:
                # y = Σ_ref m b δr^k, then the fitted unknowns P y move the case's radius
                y = [sum((ref_dr[u][k][f] for u in views if v is None or u == v), zero) * sgn
                     for v, f, sgn in regs]
                for a in range(nt):
                    if regs[a][0] is None:
                        continue
                    val = val + resp[a] * sum((P[a][i] * y[i] for i in range(nt)), zero)
            dR.append(val)
        for k in range(K):
            for l in range(K):
                if isinstance(cov_cal, np.ndarray):
                    c = float(cov_cal[k, l])
                    if c == 0.0 or not math.isfinite(c):
                        continue
                else:  # rows of arrays (one covariance per case), None where zero
                    c = cov_cal[k][l]
                    if c is None:
                        continue
                var_cal = var_cal + dR[k] * dR[l] * c
    return var_comp, var_cal
