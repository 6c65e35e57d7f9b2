"""Residual compensation of paper §4.4 with one joint circle.

The paper fits a circle to each view's points and translates each mirror view's centre onto
the direct view's centre.  Here one circle (centre, radius) and one translation per mirror
view are fitted to all the points together (the reference view's translation is zero).

The two trade off (tests/recon/calibration/test_compensation.py): a free-radius circle on a ~150° arc
has a poorly conditioned centre (with 5 µm point noise the joint fit's offsets scatter
0.74× as much as the paper's), but it ignores a view's own radius error, which the joint fit turns
into a translation (a view reading 5 µm large gets a ~3.8 µm offset).  On rendered gauges the
two gave offsets within 10 µm of each other and radius biases within 0.3 µm (STUDIES.md);
both are available.

Mastering (:func:`master_fit`): the same joint fit with references of known diameter, as
industrial gauges are mastered.  The known radius makes the size a measured quantity: per view
a radial offset along the rays (the reference view's too), and with two or more masters of
different diameters a scale per view; their uncertainty is the fit's and the masters' own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from lts360.geometry.fit import fit_circle
from lts360.recon.view_points import raw_view_points

__all__ = ["joint_view_offsets", "master_fit", "MasterFit", "MIN_MASTER_SPREAD_MM",
           "DEFAULT_REFERENCE_RADIUS_MM", "DEFAULT_REFERENCE_HALF_WIDTH_MM"]

#: The round reference of the §4.4 compensation: its nominal radius (the plug gauge's, Ø
#: 19.9987 mm) and the radial band ± about it its images are measured in.
DEFAULT_REFERENCE_RADIUS_MM = 10.0
DEFAULT_REFERENCE_HALF_WIDTH_MM = 1.0


def _as_shots(result, empty_message: str) -> list:
    """One measurement or a sequence of them, as a list; ``ValueError`` if there is none."""
    results = list(result) if isinstance(result, (list, tuple)) else [result]
    if not results:
        raise ValueError(empty_message)
    return results


def _shot_views(results, *, reference: str, min_points: int, what: str):
    """Each shot's raw view points (:func:`raw_view_points`) and the views they share.

    Returns ``(shots, names, col)``: per shot, view name → (n, 2) points; the view names (the
    first shot's order); each non-reference view's column among the translations.
    ``ValueError`` (``what`` names the shots) when the shots do not have the same views.
    """
    shots = [raw_view_points(r, reference=reference, min_points=min_points) for r in results]
    names = list(shots[0])
    if any(set(s) != set(names) for s in shots[1:]):
        raise ValueError(f"{what} have different views: {[sorted(s) for s in shots]}")
    col = {n: i for i, n in enumerate(n for n in names if n != reference)}
    return shots, names, col


def joint_view_offsets(result, *, reference: str = "direct", min_points: int = 10
                       ) -> dict[str, np.ndarray]:
    """Absolute (x, y) offsets (mm, measurement frame) of each non-reference view.

    Parameters
    ----------
    result : lts360.recon.triangulation.inverse.InverseResult, or a sequence of them
        Measurements of a round section; their raw (uncompensated) points are used.  Several
        measurements (the reference cylinder turned or moved between shots: new speckle, new
        sensor noise) are fitted together, each with its own circle and every one with the
        same view offsets: the offsets' random error falls as ``1/√k`` for ``k`` shots.

    Returns
    -------
    dict
        View name → (2,) offset, for ``Calibration.view_offsets_mm``.

    Raises
    ------
    ValueError
        No measurement, no reference view, a view with fewer than ``min_points`` valid
        points, or measurements that do not share their views.
    """
    results = _as_shots(result, "joint_view_offsets: no measurement")
    shots, names, col = _shot_views(results, reference=reference, min_points=min_points,
                                    what="joint_view_offsets: the measurements")
    others = list(col)
    pts, shot, idx = [], [], []
    for k, s in enumerate(shots):
        for n in names:
            pts.append(s[n])
            shot.append(np.full(len(s[n]), k))
            idx.append(np.full(len(s[n]), col.get(n, -1)))
    allp, shot, idx = np.concatenate(pts), np.concatenate(shot), np.concatenate(idx)
    m = len(shots)

    def q(x):
        c, t = x[:2 * m].reshape(m, 2), x[3 * m:].reshape(-1, 2)
        return allp + np.where(idx[:, None] >= 0, t[np.maximum(idx, 0)], 0.0) - c[shot]

    def residual(x):
        return np.hypot(*q(x).T) - x[2 * m:3 * m][shot]

    def jacobian(x):  # d|q|/dq = q/|q|: −it for the shot's centre, +it for the translation
        v = q(x)
        n = v / np.hypot(*v.T)[:, None]
        J = np.zeros((len(v), x.size))
        rows = np.arange(len(v))
        J[rows, 2 * shot], J[rows, 2 * shot + 1] = -n[:, 0], -n[:, 1]
        J[rows, 2 * m + shot] = -1.0
        at = idx >= 0
        J[rows[at], 3 * m + 2 * idx[at]] = n[at, 0]
        J[rows[at], 3 * m + 2 * idx[at] + 1] = n[at, 1]
        return J

    starts = [fit_circle(np.concatenate(list(s.values()))) for s in shots]
    x0 = np.concatenate([np.concatenate([f.center_mm for f in starts]),
                         [f.radius_mm for f in starts], np.zeros(2 * len(others))])
    sol = least_squares(residual, x0, jac=jacobian, method="lm", xtol=1e-14, ftol=1e-14)
    t = sol.x[3 * m:].reshape(-1, 2)
    return {n: t[col[n]].copy() for n in others}


# -- mastering with references of known diameter --------------------------------------------

#: Two masters closer than this in diameter (mm) do not set a scale (it is then the ratio of
#: two radial offsets read 0.5 mm apart in radius: ill conditioned).
MIN_MASTER_SPREAD_MM = 1.0
#: Mastering drops points whose residual exceeds this many robust σ (1.4826·MAD), refitting
#: up to :data:`OUTLIER_ROUNDS` times.
OUTLIER_K = 4.0
OUTLIER_ROUNDS = 5


@dataclass(frozen=True, eq=False)
class MasterFit:
    """The joint §4.4 fit with references of known diameter (:func:`master_fit`).

    Each view's raw points are corrected as ``r' = scale·r + radial_offset`` along their ray
    (radius from the measurement origin, the axis), then a mirror view is translated by its
    offset (:attr:`Calibration.view_offsets_mm`); the reference view is not translated.

    Attributes
    ----------
    offsets_mm : dict str → (2,) float
        Per mirror view, the translation.
    radial_offset_mm, scale : dict str → float
        Per view (the reference view included); ``scale`` 1 with a single master diameter.
    u_radial_offset_mm, u_scale : dict str → float
        Standard uncertainties: the fit's (from its residuals) and the masters' diameters'
        (their ``u``, each master's shots moved together) in quadrature.
    u_radius_mm : dict str → float
        Per view, the standard uncertainty of a corrected radius at the masters' mean radius
        (offset, scale and their correlation, the masters' diameters).
    u_fit_radial_offset_mm, u_master_radial_offset_mm : dict str → float
        The two parts of ``u_radial_offset_mm``.
    diameters_mm, u_diameters_mm : tuple of float
        The masters (distinct diameters) and their standard uncertainties.
    shots_per_master : tuple of int
    rms_mm : float
        RMS of the fit's residuals (outliers dropped).
    fitted_scale : bool
    n_points, n_outliers : int
        Points fitted, and dropped as outliers.
    """

    offsets_mm: dict
    radial_offset_mm: dict
    scale: dict
    u_radial_offset_mm: dict
    u_scale: dict
    u_radius_mm: dict
    u_fit_radial_offset_mm: dict
    u_master_radial_offset_mm: dict
    diameters_mm: tuple
    u_diameters_mm: tuple
    shots_per_master: tuple
    rms_mm: float
    fitted_scale: bool
    n_points: int = 0
    n_outliers: int = 0

    def to_dict(self) -> dict:
        """The JSON record stored in ``calibration.json`` (``master``)."""
        return {"diameters_mm": list(self.diameters_mm),
                "u_diameters_mm": list(self.u_diameters_mm),
                "shots_per_master": list(self.shots_per_master),
                "fitted_scale": self.fitted_scale, "rms_um": 1e3 * self.rms_mm,
                "n_points": self.n_points, "n_outliers": self.n_outliers,
                "radial_offset_mm": dict(self.radial_offset_mm), "scale": dict(self.scale),
                "u_radial_offset_mm": dict(self.u_radial_offset_mm),
                "u_fit_radial_offset_mm": dict(self.u_fit_radial_offset_mm),
                "u_master_radial_offset_mm": dict(self.u_master_radial_offset_mm),
                "u_scale": dict(self.u_scale), "u_radius_mm": dict(self.u_radius_mm)}


def master_fit(result, diameters_mm, *, u_diameters_mm=None, reference: str = "direct",
               min_points: int = 10) -> MasterFit:
    """Mastering: the joint §4.4 fit with round references of known diameter.

    Parameters
    ----------
    result : InverseResult or sequence of them
        Shots of the masters (raw points used, as :func:`joint_view_offsets`).
    diameters_mm : float or sequence of float, > 0
        Each shot's master diameter (one value: every shot).
    u_diameters_mm : float or sequence of float, >= 0, optional
        The masters' diameters' standard uncertainties (the calibration certificate's),
        per shot as ``diameters_mm`` (shots of one master must give the same); default 0.
    reference : str
        The view whose translation is zero (the circles' centres are free per shot).

    One master diameter: per shot a centre (its radius known), per mirror view a translation,
    per view (the reference view too) a radial offset.  Two or more distinct diameters (at
    least :data:`MIN_MASTER_SPREAD_MM` apart): also a scale per view.  Residual: the corrected
    point's distance from its shot's centre minus the master's radius.

    Raises
    ------
    ValueError
        No shot, a diameter ≤ 0, shots and diameters of different counts, masters of the same
        nominal diameter with different ``u``, masters less than :data:`MIN_MASTER_SPREAD_MM`
        apart, too few points in a view.
    """
    results = _as_shots(result, "master_fit: no shot")
    D, masters, group, u_master = _master_diameters(diameters_mm, u_diameters_mm, len(results))
    fit_scale = len(masters) > 1
    shots, names, col = _shot_views(results, reference=reference, min_points=min_points,
                                    what="master_fit: the shots")
    problem = _master_problem(shots, names, col, fit_scale)
    R = 0.5 * D
    sol, keep = _fit_dropping_outliers(problem, R, _master_start(problem, shots, R), min_points)
    moves = _master_diameter_moves(problem, R, group, u_master, sol.x, keep)
    out = _per_view_results(problem, names, sol.x, _fit_covariance(sol), moves, masters)
    t = problem.unpack(sol.x)[1]
    return MasterFit(offsets_mm={n: t[col[n]].copy() for n in col},
                     radial_offset_mm=out["dr"], scale=out["s"], u_radial_offset_mm=out["u_dr"],
                     u_scale=out["u_s"], u_radius_mm=out["u_r"],
                     u_fit_radial_offset_mm=out["u_fit"],
                     u_master_radial_offset_mm=out["u_master"],
                     diameters_mm=tuple(float(v) for v in masters),
                     u_diameters_mm=tuple(float(v) for v in u_master),
                     shots_per_master=tuple(int(np.sum(group == g)) for g in range(len(masters))),
                     rms_mm=float(np.sqrt(np.mean(sol.fun ** 2))), fitted_scale=fit_scale,
                     n_points=int(keep.sum()), n_outliers=int((~keep).sum()))


def _master_diameters(diameters_mm, u_diameters_mm, m: int):
    """The ``m`` shots' master diameters and their ``u``, checked, and the masters.

    Returns ``(D, masters, group, u_master)``: per shot its diameter; the distinct diameters
    (ascending, to 1e-9 mm); per shot the index of its master; per master its ``u``.
    ``ValueError`` as :func:`master_fit` says.
    """
    D = np.broadcast_to(np.asarray(diameters_mm, float).ravel(), (m,)) \
        if np.size(diameters_mm) in (1, m) else None
    if D is None:
        raise ValueError(f"master_fit: {np.size(diameters_mm)} diameters for {m} shots")
    if not np.all(np.isfinite(D) & (D > 0)):
        raise ValueError(f"master diameter: must be > 0, got {D.tolist()}")
    uD = np.zeros(m) if u_diameters_mm is None else np.broadcast_to(
        np.asarray(u_diameters_mm, float).ravel(), (m,))
    if not np.all(np.isfinite(uD) & (uD >= 0)):
        raise ValueError(f"master diameter u: must be >= 0, got {uD.tolist()}")
    masters = sorted(set(np.round(D, 9).tolist()))
    group = np.array([masters.index(round(float(d), 9)) for d in D])
    u_master = []
    for g in range(len(masters)):
        us = set(np.round(uD[group == g], 12).tolist())
        if len(us) != 1:
            raise ValueError(f"master Ø{masters[g]:g} mm: its shots give different u {sorted(us)}")
        u_master.append(us.pop())
    if len(masters) > 1 and np.min(np.diff(masters)) < MIN_MASTER_SPREAD_MM:
        raise ValueError(f"masters: diameters {masters} mm are less than "
                         f"{MIN_MASTER_SPREAD_MM:g} mm apart: they set no scale")
    return D, masters, group, u_master


@dataclass(frozen=True, eq=False)
class _MasterProblem:
    """The mastering least squares: every point's ray and the parameters' layout.

    Per point: its raw radius ``r0`` and unit ray ``u0`` (from the measurement origin), its
    shot, its translation's column ``tix`` (-1: the reference view) and its view ``vix``.
    Parameters: per shot a centre (``2m``), per mirror view a translation (``2·no``), per view
    a radial offset (``nv``) and, with ``fit_scale``, a scale − 1 (``nv``).
    """

    r0: np.ndarray
    u0: np.ndarray
    shot: np.ndarray
    tix: np.ndarray
    vix: np.ndarray
    m: int
    no: int
    nv: int
    fit_scale: bool

    @property
    def i_dr(self) -> int:
        """Index of the first radial offset in the parameters."""
        return 2 * self.m + 2 * self.no

    def unpack(self, x):
        """``(centres, translations, radial offsets, scales − 1)`` from the parameters."""
        m, no, nv = self.m, self.no, self.nv
        c = x[:2 * m].reshape(m, 2)
        t = x[2 * m:2 * m + 2 * no].reshape(no, 2)
        dr = x[2 * m + 2 * no:2 * m + 2 * no + nv]
        ds = x[2 * m + 2 * no + nv:] if self.fit_scale else np.zeros(nv)
        return c, t, dr, ds

    def _q(self, x):
        """The corrected points relative to their shot's centre, (n, 2)."""
        c, t, dr, ds = self.unpack(x)
        rr = (1.0 + ds[self.vix]) * self.r0 + dr[self.vix]
        shift = np.where(self.tix[:, None] >= 0, t[np.maximum(self.tix, 0)], 0.0)
        return rr[:, None] * self.u0 + shift - c[self.shot]

    def residual(self, R, sel=None):
        """The residual function for shot radii ``R``: the corrected point's distance from its
        shot's centre minus the radius (the points ``sel`` only, if given)."""
        def residual(x):
            res = np.hypot(*self._q(x).T) - R[self.shot]
            return res if sel is None else res[sel]
        return residual

    def jacobian(self, sel=None):
        """The residuals' Jacobian (exact): with ``n = q/|q|`` the unit vector of a corrected
        point from its centre, −n for the centre, +n for its view's translation, ``n·u0`` for
        its radial offset and ``r0 n·u0`` for its scale − 1 (the points ``sel`` only)."""
        def jacobian(x):
            q = self._q(x)
            n = q / np.hypot(*q.T)[:, None]
            nu = np.einsum("ij,ij->i", n, self.u0)
            J = np.zeros((len(q), x.size))
            rows = np.arange(len(q))
            J[rows, 2 * self.shot], J[rows, 2 * self.shot + 1] = -n[:, 0], -n[:, 1]
            at = self.tix >= 0
            col = 2 * self.m + 2 * self.tix[at]
            J[rows[at], col], J[rows[at], col + 1] = n[at, 0], n[at, 1]
            J[rows, self.i_dr + self.vix] = nu
            if self.fit_scale:
                J[rows, self.i_dr + self.nv + self.vix] = self.r0 * nu
            return J if sel is None else J[sel]
        return jacobian

    def solve(self, R, x_start, keep):
        """Levenberg–Marquardt on the points ``keep``, from ``x_start``."""
        return least_squares(self.residual(R, keep), x_start, jac=self.jacobian(keep),
                             method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)


def _master_problem(shots, names, col, fit_scale: bool) -> _MasterProblem:
    """Every shot's and view's points as rays, in shot then view order."""
    vcol = {n: i for i, n in enumerate(names)}
    r_l, u_l, shot_l, t_l, v_l = [], [], [], [], []
    for k, s in enumerate(shots):
        for n in names:
            p = s[n]
            r = np.hypot(*p.T)
            r_l.append(r)
            u_l.append(p / r[:, None])
            shot_l.append(np.full(len(p), k))
            t_l.append(np.full(len(p), col.get(n, -1)))
            v_l.append(np.full(len(p), vcol[n]))
    return _MasterProblem(r0=np.concatenate(r_l), u0=np.concatenate(u_l),
                          shot=np.concatenate(shot_l), tix=np.concatenate(t_l),
                          vix=np.concatenate(v_l), m=len(shots), no=len(col), nv=len(names),
                          fit_scale=fit_scale)


def _master_start(problem: _MasterProblem, shots, R) -> np.ndarray:
    """Starting parameters: each shot's free circle's centre, no translation, one radial
    offset for all views (the circles' mean radius error), no scale."""
    no, nv = problem.no, problem.nv
    starts = [fit_circle(np.concatenate(list(s.values()))) for s in shots]
    return np.concatenate([np.concatenate([f.center_mm for f in starts]), np.zeros(2 * no),
                           np.array([np.mean([R[k] - f.radius_mm for k, f in enumerate(starts)])]
                                    * nv), np.zeros(nv if problem.fit_scale else 0)])


def _fit_dropping_outliers(problem: _MasterProblem, R, x0, min_points: int):
    """The fit, outliers dropped: returns the solution and the points kept.

    Outliers (a stray peak in the reference's band) are dropped: beyond OUTLIER_K robust σ of
    the residuals, refitted until none is left (at most OUTLIER_ROUNDS times).
    """
    keep = np.ones(problem.r0.size, bool)
    sol = problem.solve(R, x0, keep)
    for _ in range(OUTLIER_ROUNDS):
        res = problem.residual(R)(sol.x)
        sigma = 1.4826 * np.median(np.abs(res[keep]))
        new = np.abs(res) <= OUTLIER_K * max(sigma, 1e-9)
        if np.array_equal(new, keep):
            break
        keep = new
        if np.bincount(problem.vix[keep], minlength=problem.nv).min() < min_points:
            raise ValueError("master_fit: too few points left in a view after dropping "
                             "outliers")
        sol = problem.solve(R, sol.x, keep)
    return sol, keep


def _fit_covariance(sol) -> np.ndarray:
    """The parameters' covariance from the fit's residuals (``s²·(JᵀJ)⁺``)."""
    n_par = sol.x.size
    dof = max(sol.fun.size - n_par, 1)
    s2 = float(sol.fun @ sol.fun) / dof
    J = sol.jac
    return s2 * np.linalg.pinv(J.T @ J)


def _master_diameter_moves(problem: _MasterProblem, R, group, u_master, x, keep) -> list:
    """The masters' diameters (type B): per master with ``u`` > 0, the parameters' change when
    its shots' radii all move by ``u/2``."""
    moves = []
    for g, u in enumerate(u_master):
        if u > 0:
            Rg = R + np.where(group == g, 0.5 * u, 0.0)
            moves.append(problem.solve(Rg, x, keep).x - x)
    return moves


def _per_view_results(problem: _MasterProblem, names, x, cov, moves, masters) -> dict:
    """Per view its radial offset, scale and their uncertainties (the fit's, the masters'),
    and the uncertainty of a corrected radius at the masters' mean radius: quantity → view →
    value, the quantities ``dr``, ``s``, ``u_dr``, ``u_s``, ``u_r``, ``u_fit``, ``u_master``."""
    fit_scale = problem.fit_scale
    _, _, dr, ds = problem.unpack(x)
    i_dr = problem.i_dr
    i_ds = i_dr + problem.nv
    r_mean = float(np.mean(0.5 * np.asarray(masters)))
    out = {k: {} for k in ("dr", "s", "u_dr", "u_s", "u_r", "u_fit", "u_master")}
    for j, n in enumerate(names):
        idx = [i_dr + j] + ([i_ds + j] if fit_scale else [])
        g = np.array([1.0, r_mean][:len(idx)])  # d(radius at r_mean)/d(dr, ds)
        C = cov[np.ix_(idx, idx)]
        u_fit_r = float(np.sqrt(g @ C @ g))
        u_mst_r = float(np.sqrt(sum((g @ mv[idx]) ** 2 for mv in moves)))
        out["dr"][n] = float(dr[j])
        out["s"][n] = float(1.0 + ds[j])
        out["u_fit"][n] = float(np.sqrt(cov[i_dr + j, i_dr + j]))
        out["u_master"][n] = float(np.sqrt(sum(mv[i_dr + j] ** 2 for mv in moves)))
        out["u_dr"][n] = float(np.hypot(out["u_fit"][n], out["u_master"][n]))
        out["u_s"][n] = float(np.sqrt(cov[i_ds + j, i_ds + j] + sum(mv[i_ds + j] ** 2
                                                                    for mv in moves))) \
            if fit_scale else 0.0
        out["u_r"][n] = float(np.hypot(u_fit_r, u_mst_r))
    return out
