"""The rig calibration's covariance predicted from the planned board poses (Fisher information).

The calibration from images (:mod:`lts360.recon.calibration.from_images`) runs in three
stages, and so does this model, each linearised at the true rig and the planned poses
(:func:`lts360.scenes.calib_plan.plan_calibration`), with independent image noise:

1. **camera** — Zhang's method on the ``camera`` shots: ``fx fy cx cy k1 k2`` free (``k3``
   fixed, tangential zero), one board pose per shot.  The poses are nuisance parameters:
   the intrinsics' information is the Schur complement
   ``Σ_i (A_i − B_i C_i⁻¹ B_iᵀ)`` of the Gauss–Newton normal matrix, with corner noise
   ``σ_c`` px (iid per coordinate).
2. **mirrors** — per mirror, the plane ``(a, b, δ)`` and one pose per shot from every real
   corner ``P X`` and virtual corner ``P T_π X`` of its ``mirror`` shots (and of the
   ``laser`` shots seen in it), K fixed; again a Schur complement over the poses.
3. **laser plane** — per ``laser`` shot, the board pose from its real and virtual corners
   (the mirror fixed) gives the board plane; the laser line's image points are
   back-projected onto it; an unweighted plane fit through every pose's points.  That fit
   is linear in the points' errors along the laser normal, ``e = n_L · δp``, so its
   covariance is the sandwich ``M⁻¹ Q M⁻¹`` (``M = Σ G Gᵀ``, ``G = (e1·p, e2·p, −1)``)
   with two independent sources in ``Q``: the pose error (shared by a pose's points,
   ``σ_c²``) and the line-centre error across the line (``σ_l`` px, independent per
   point).  Optionally the mirror planes' own covariance, shared by every pose seen in
   that mirror, is carried into the poses too.

Planes are ``n · X = d`` in the camera frame with ``d < 0`` (the calibration's orientation)
and are perturbed as ``n' = normalise(n + a e1 + b e2)``, ``d' = d + δ`` with the
calibration's tangent basis.  Board poses are perturbed in the camera frame,
``X' = X + ω × X + t``.

Where the model stops: corner errors are independent (a board whose corners share an error
— defocus, a detector's bias — spreads its fit more: the calibration's jackknife sees that,
this model does not); each stage conditions on the previous one's result (K fixed in the
mirror fit, as the calibration does; the intrinsics' error is not carried into the planes);
the laser boards' corners enter both their mirror's fit and their own pose, a correlation
left out; ``p1 p2 k3`` of the rig are taken as zero in the projection.

The core works on matrices as Python lists of lists of arrays (one matrix per element of
the arrays: a corner, a line point or a shot), with ``+ − * /`` and the few functions of
an ``ops`` object (:data:`NUMPY_OPS`, or :func:`drjit_ops` for ``drjit.llvm.ad.Float64``),
so that the same code runs in a Dr.Jit program for gradients.  The numpy front end
:func:`predict_calibration_covariance` builds its inputs from a rig and a plan.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lts360.design.shares import CAMERA_NAMES, tangent_basis_np

__all__ = ["NumpyOps", "NUMPY_OPS", "drjit_ops", "cholesky", "spd_solve", "spd_inverse",
           "mat_mul", "mat_transpose", "gram", "project_jacobians", "pose_jacobian",
           "reflect", "reflect_jacobians", "plane_residual", "plane_residual_jacobian",
           "board_shift_jacobian", "line_noise_gain", "camera_information",
           "mirror_information", "board_pose_information", "laser_plane_parts",
           "LaserLineSamples", "laser_line_samples", "CalibrationPrediction",
           "predict_calibration_covariance", "INTRINSIC_NAMES", "plan_covariance",
           "PLAN_SIGMA_CORNER_PX", "PLAN_SIGMA_TARGET_PX", "PLAN_SIGMA_LINE_PX",
           "CalibrationPlan"]

#: The intrinsics the camera stage estimates, in the order of its covariance.
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2")


# --------------------------------------------------------------------------- ops

class NumpyOps:
    """The array functions the core needs, for numpy arrays (float64)."""

    name = "numpy"

    @staticmethod
    def sqrt(x):
        return np.sqrt(x)

    @staticmethod
    def sin(x):
        return np.sin(x)

    @staticmethod
    def cos(x):
        return np.cos(x)

    @staticmethod
    def block_sum(x, n: int):
        """Sums of consecutive blocks of ``n`` elements: ``(m n,) → (m,)``."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 1 or x.size % n:
            raise ValueError(f"block_sum: need a 1-D array whose size is a multiple of {n}, "
                             f"got shape {x.shape}")
        return x.reshape(-1, n).sum(axis=1)

    @staticmethod
    def gather(x, index):
        """``x[index]``."""
        return np.asarray(x, dtype=float)[np.asarray(index)]


NUMPY_OPS = NumpyOps()


def drjit_ops():
    """The same functions for ``drjit.llvm.ad.Float64`` arrays (imports Dr.Jit on call)."""
    import drjit as dr

    class DrJitOps:
        name = "drjit"
        sqrt = staticmethod(dr.sqrt)
        sin = staticmethod(dr.sin)
        cos = staticmethod(dr.cos)

        @staticmethod
        def block_sum(x, n: int):
            return dr.block_sum(x, n)

        @staticmethod
        def gather(x, index):
            return dr.gather(type(x), x, index)

    return DrJitOps()


# --------------------------------------------------------------------------- small matrices

def mat_transpose(A: list) -> list:
    """Transpose of a list-of-rows matrix."""
    return [list(r) for r in zip(*A)]


def _dot(terms):
    it = iter(terms)
    s = next(it)
    for t in it:
        s = s + t
    return s


def mat_mul(A: list, B: list) -> list:
    """``A B`` for list-of-rows matrices of arrays (elementwise over the arrays)."""
    Bt = mat_transpose(B)
    return [[_dot(a * b for a, b in zip(row, col)) for col in Bt] for row in A]


def gram(J1: list, J2: list) -> list:
    """``J1ᵀ J2`` for ``J1`` (r × p) and ``J2`` (r × q), elementwise over the arrays."""
    return [[_dot(J1[r][i] * J2[r][j] for r in range(len(J1))) for j in range(len(J2[0]))]
            for i in range(len(J1[0]))]


def _mat_add(A: list, B: list) -> list:
    return [[a + b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def _mat_sub(A: list, B: list) -> list:
    return [[a - b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def _block_sum_mat(ops, A: list, n: int) -> list:
    return [[ops.block_sum(a, n) for a in row] for row in A]


def cholesky(ops, A: list) -> list:
    """Lower Cholesky factor ``L`` (``L Lᵀ = A``) of a small SPD matrix of arrays, unrolled.

    Only the lower triangle of ``A`` is read; the strict upper triangle of ``L`` is 0.0.
    """
    n = len(A)
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        s = A[j][j]
        for k in range(j):
            s = s - L[j][k] * L[j][k]
        L[j][j] = ops.sqrt(s)
        inv = 1.0 / L[j][j]
        for i in range(j + 1, n):
            s = A[i][j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = s * inv
    return L


def spd_solve(ops, A: list, B: list) -> list:
    """``A⁻¹ B`` for a small SPD ``A`` (n × n) and ``B`` (n × m), by an equilibrated Cholesky.

    ``A`` is scaled to unit diagonal first (``D A D``, ``D = diag(A)^-1/2``) so that blocks
    of very different units (px and px/rad², mm and rad) factor as well as a correlation
    matrix does; no ridge is added, a singular ``A`` gives inf or NaN.
    """
    n, m = len(A), len(B[0])
    s = [1.0 / ops.sqrt(A[i][i]) for i in range(n)]
    As = [[A[i][j] * s[i] * s[j] for j in range(n)] for i in range(n)]
    L = cholesky(ops, As)
    X = [[None] * m for _ in range(n)]
    for c in range(m):
        y = [None] * n
        for i in range(n):  # L y = D b
            v = B[i][c] * s[i]
            for k in range(i):
                v = v - L[i][k] * y[k]
            y[i] = v / L[i][i]
        for i in reversed(range(n)):  # Lᵀ z = y, x = D z
            v = y[i]
            for k in range(i + 1, n):
                v = v - L[k][i] * X[k][c]
            X[i][c] = v / L[i][i]
    return [[X[i][c] * s[i] for c in range(m)] for i in range(n)]


def spd_inverse(ops, A: list) -> list:
    """``A⁻¹`` of a small SPD matrix of arrays (see :func:`spd_solve`)."""
    n = len(A)
    eye = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    return spd_solve(ops, A, eye)


def _trace_mul(A: list, B: list):
    """``tr(A B)`` for square matrices of arrays."""
    n = len(A)
    return _dot(A[i][k] * B[k][i] for i in range(n) for k in range(n))


# --------------------------------------------------------------------------- Jacobians

def project_jacobians(X_cam_mm: list, intrinsics) -> tuple[list, list, list]:
    """Pinhole + radial (k1, k2) projection and its Jacobians.

    ``u = fx x (1 + k1 r² + k2 r⁴) + cx`` (and ``v`` with ``fy, y, cy``), ``x = X/Z``,
    ``y = Y/Z``, ``r² = x² + y²``.

    Parameters
    ----------
    X_cam_mm : list of 3 arrays
        Points in the camera frame (mm), ``Z > 0``.
    intrinsics : sequence of 6
        ``(fx, fy, cx, cy, k1, k2)`` (px, px, px, px, 1, 1), scalars or arrays.

    Returns
    -------
    uv : list of 2 arrays
        Pixels.
    J_intr : 2 × 6 list of arrays
        ``∂(u, v)/∂(fx, fy, cx, cy, k1, k2)``.
    J_X : 2 × 3 list of arrays
        ``∂(u, v)/∂X`` (px/mm).
    """
    X, Y, Z = X_cam_mm
    fx, fy, cx, cy, k1, k2 = intrinsics
    iz = 1.0 / Z
    x, y = X * iz, Y * iz
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * k2)
    drad = k1 + 2.0 * k2 * r2  # ∂rad/∂r²
    uv = [fx * x * rad + cx, fy * y * rad + cy]
    zero, one = Z * 0.0, Z * 0.0 + 1.0
    J_intr = [[x * rad, zero, one, zero, fx * x * r2, fx * x * r2 * r2],
              [zero, y * rad, zero, one, fy * y * r2, fy * y * r2 * r2]]
    du_dx = fx * (rad + 2.0 * x * x * drad)
    du_dy = fx * 2.0 * x * y * drad
    dv_dx = fy * 2.0 * x * y * drad
    dv_dy = fy * (rad + 2.0 * y * y * drad)
    J_X = [[du_dx * iz, du_dy * iz, -(du_dx * x + du_dy * y) * iz],
           [dv_dx * iz, dv_dy * iz, -(dv_dx * x + dv_dy * y) * iz]]
    return uv, J_intr, J_X


def pose_jacobian(X_cam_mm: list) -> list:
    """``∂X/∂(ω, t)`` (3 × 6) of a board point moved by ``X' = X + ω × X + t`` at 0."""
    X, Y, Z = X_cam_mm
    zero, one = Z * 0.0, Z * 0.0 + 1.0
    return [[zero, Z, -Y, one, zero, zero],
            [-Z, zero, X, zero, one, zero],
            [Y, -X, zero, zero, zero, one]]


def reflect(X_mm: list, n: list, d_mm) -> list:
    """Mirror image ``X − 2 (n·X − d) n`` of points in the plane ``n · X = d``."""
    h = _dot(a * b for a, b in zip(n, X_mm)) - d_mm
    return [x - 2.0 * h * c for x, c in zip(X_mm, n)]


def reflect_jacobians(X_mm: list, n: list, d_mm, e1: list, e2: list) -> tuple[list, list]:
    """Jacobians of :func:`reflect`: ``∂Xv/∂X = I − 2 n nᵀ`` and ``∂Xv/∂(a, b, δ)``.

    With ``n' = n + a e1 + b e2`` (normalising changes nothing to first order, ``e ⊥ n``):
    ``∂Xv/∂a = −2 ((e1·X) n + (n·X − d) e1)``, likewise ``b``; ``∂Xv/∂δ = 2 n``.
    """
    h = _dot(a * b for a, b in zip(n, X_mm)) - d_mm
    p1 = _dot(a * b for a, b in zip(e1, X_mm))
    p2 = _dot(a * b for a, b in zip(e2, X_mm))
    dX = [[(1.0 if i == j else 0.0) - 2.0 * n[i] * n[j] for j in range(3)] for i in range(3)]
    dm = [[-2.0 * (p1 * n[i] + h * e1[i]), -2.0 * (p2 * n[i] + h * e2[i]), 2.0 * n[i]]
          for i in range(3)]
    return dX, dm


def plane_residual(ops, p_mm: list, n: list, d_mm, e1: list, e2: list, abd: list):
    """``n' · p − d'`` of the plane moved by ``(a, b, δ)`` (exact, for checks)."""
    a, b, delta = abd
    m = [ni + a * u + b * v for ni, u, v in zip(n, e1, e2)]
    norm = ops.sqrt(_dot(c * c for c in m))
    return _dot(c * q for c, q in zip(m, p_mm)) / norm - (d_mm + delta)


def plane_residual_jacobian(p_mm: list, e1: list, e2: list) -> list:
    """``∂(n'·p − d')/∂(a, b, δ)`` at 0: the row ``(e1·p, e2·p, −1)``."""
    zero = p_mm[0] * 0.0
    return [_dot(a * b for a, b in zip(e1, p_mm)), _dot(a * b for a, b in zip(e2, p_mm)),
            zero - 1.0]


def board_shift_jacobian(p_mm: list, n_board: list, d_board_mm, d_laser_mm) -> list:
    """``∂(n_L · p)/∂(ω, t)`` (6) of a laser point ``p`` back-projected onto the board plane.

    The image point stays; the board plane moves with its pose (``δn_b = ω × n_b``,
    ``δd_b = n_b · t``), so ``p`` slides along its ray by ``p (δd_b − δn_b · p) / d_b`` and,
    since ``n_L · p = d_L``, ``δ(n_L · p) = (d_L / d_b) (n_b · t − ω · (n_b × p))``.
    """
    k = d_laser_mm / d_board_mm
    nx, ny, nz = n_board
    px, py, pz = p_mm
    c = [ny * pz - nz * py, nz * px - nx * pz, nx * py - ny * px]  # n_b × p
    return [-k * c[0], -k * c[1], -k * c[2], k * nx, k * ny, k * nz]


def line_noise_gain(p_mm: list, b1: list, b2: list, n_laser: list, intrinsics) -> list:
    """``∂(n_L · p)/∂(u, v)`` (mm/px, 2) of a point back-projected onto the board plane.

    The point moves in the board plane (axes ``b1, b2``): ``δp = B (J B)⁻¹ δuv`` with ``J``
    the projection's ``∂uv/∂X``.  An image shift along the line moves the point along the
    line, within the laser plane, so the gain is across the line and its norm is what a
    line-centre error ``σ_l`` (across the line) does.
    """
    _, _, J = project_jacobians(p_mm, intrinsics)
    m = [[_dot(J[r][k] * b[k] for k in range(3)) for b in (b1, b2)] for r in range(2)]
    det = m[0][0] * m[1][1] - m[0][1] * m[1][0]
    c1 = _dot(a * b for a, b in zip(n_laser, b1))
    c2 = _dot(a * b for a, b in zip(n_laser, b2))
    # c (1×2) times the inverse of m.
    return [(c1 * m[1][1] - c2 * m[1][0]) / det, (c2 * m[0][0] - c1 * m[0][1]) / det]


# --------------------------------------------------------------------------- information

def _schur_over_shots(ops, A: list, B: list, C: list, shots: int | None = None) -> list:
    """``Σ_i (A_i − B_i C_i⁻¹ B_iᵀ)`` for per-shot arrays: the parameters' information with
    each shot's pose eliminated (summed over blocks of ``shots`` shots: one block per design;
    default all)."""
    S = _mat_sub(A, mat_mul(B, spd_solve(ops, C, mat_transpose(B))))
    m = shots or _array_len(S[0][0])
    return _block_sum_mat(ops, S, m)


def _array_len(x) -> int:
    return len(x) if hasattr(x, "__len__") else 1


def camera_information(ops, X_cam_mm: list, intrinsics, n_corners: int,
                       shots: int | None = None) -> list:
    """Fisher information (6 × 6, per unit σ_c², px⁻²) of ``fx fy cx cy k1 k2``.

    Parameters
    ----------
    X_cam_mm : list of 3 arrays, (m n,)
        The corners of ``m`` camera shots in the camera frame, ``n_corners`` per shot.
    """
    _, Ji, JX = project_jacobians(X_cam_mm, intrinsics)
    Jp = mat_mul(JX, pose_jacobian(X_cam_mm))
    A = _block_sum_mat(ops, gram(Ji, Ji), n_corners)
    B = _block_sum_mat(ops, gram(Ji, Jp), n_corners)
    C = _block_sum_mat(ops, gram(Jp, Jp), n_corners)
    return _schur_over_shots(ops, A, B, C, shots)


def _real_virtual_rows(X_cam_mm, intrinsics, n, d_mm, e1, e2):
    """Per corner: the pose Jacobians of the real and the virtual corner (2 × 6 each) and
    the virtual corner's mirror Jacobian (2 × 3)."""
    Jpose = pose_jacobian(X_cam_mm)
    _, _, JX = project_jacobians(X_cam_mm, intrinsics)
    Xv = reflect(X_cam_mm, n, d_mm)
    _, _, JXv = project_jacobians(Xv, intrinsics)
    dX, dm = reflect_jacobians(X_cam_mm, n, d_mm, e1, e2)
    real = mat_mul(JX, Jpose)
    JvX = mat_mul(JXv, dX)
    virt = mat_mul(JvX, Jpose)
    virt_m = mat_mul(JXv, dm)
    return real, virt, virt_m


def board_pose_information(ops, X_cam_mm: list, intrinsics, n: list, d_mm, e1: list,
                           e2: list, n_corners: int) -> tuple[list, list, list]:
    """Per shot, the information of a board seen directly and in a mirror (unit σ_c²).

    Returns
    -------
    C : 6 × 6 of (m,) arrays
        Pose–pose (``ω, t``).
    B : 6 × 3 of (m,) arrays
        Pose–mirror ``(a, b, δ)``.
    D : 3 × 3 of (m,) arrays
        Mirror–mirror.
    ``n, d_mm, e1, e2`` (the mirror, camera frame) may be arrays over the corners (a mirror
    per shot).
    """
    real, virt, vm = _real_virtual_rows(X_cam_mm, intrinsics, n, d_mm, e1, e2)
    C = _mat_add(gram(real, real), gram(virt, virt))
    return (_block_sum_mat(ops, C, n_corners), _block_sum_mat(ops, gram(virt, vm), n_corners),
            _block_sum_mat(ops, gram(vm, vm), n_corners))


def mirror_information(ops, X_cam_mm: list, intrinsics, n: list, d_mm, e1: list, e2: list,
                       n_corners: int, shots: int | None = None) -> list:
    """Fisher information (3 × 3, unit σ_c²) of a mirror's ``(a, b, δ)`` from its shots'
    real and virtual corners, the board poses eliminated (K fixed)."""
    C, B, D = board_pose_information(ops, X_cam_mm, intrinsics, n, d_mm, e1, e2, n_corners)
    return _schur_over_shots(ops, D, mat_transpose(B), C, shots)


def _along(p_mm: list, n_board: list, n_laser: list):
    """A coordinate along each pose's line: ``(n_b × n_L) · p`` (mm; affine along the line,
    its origin differs per pose)."""
    bx, by, bz = n_board
    lx, ly, lz = n_laser
    direction = [by * lz - bz * ly, bz * lx - bx * lz, bx * ly - by * lx]
    return _dot(a * b for a, b in zip(direction, p_mm))


def laser_plane_parts(ops, line: dict, pose_C: list, pose_B: list, n_laser: list, d_laser_mm,
                      e1: list, e2: list, intrinsics, n_line: int,
                      mirror_terms: list | None = None, designs: int = 1) -> dict:
    """The laser-plane fit's covariance and mean-square residual, split by source.

    Parameters
    ----------
    line : dict of arrays over the line samples (``m`` shots × ``n_line``)
        ``p`` (3 arrays, camera mm, on the laser plane), ``w`` (points of the real line each
        sample stands for), ``n_board`` (3), ``d_board`` (mm), ``b1``, ``b2`` (3 each, the
        board's axes).
    pose_C, pose_B : per-shot arrays from :func:`board_pose_information`
        The laser boards' pose information (6 × 6) and pose–mirror coupling (6 × 3).
    n_laser, d_laser_mm, e1, e2
        The laser plane (camera frame) and its tangent basis.
    mirror_terms : list of (mask, cov_abd), optional
        Per mirror: a (m,) array, 1 for the shots seen in it, and its 3 × 3 covariance; the
        mirrors' error is then carried into the poses (shared by the shots of one mirror).

    Returns
    -------
    dict
        ``M`` (3 × 3, Σ w G Gᵀ); ``cov_line``, ``cov_pose`` (per unit σ_l², σ_c²) and
        ``cov_mirror`` (absolute) of ``(a, b, δ)``; ``ms_line``, ``ms_pose``, ``ms_mirror``:
        the expected mean-square fit residual (mm²) likewise, of the points as detected;
        ``ms_line_fitted``: of the line noise once each pose's points are moved onto
        their straight line, as the calibration does (its residuals hold only each line's
        offset and tilt); ``n_points`` (Σ w).
    """
    p, w = line["p"], line["w"]
    n_all = _array_len(w) // designs  # line samples per design
    G = [plane_residual_jacobian(p, e1, e2)]  # 1 × 3
    a = [board_shift_jacobian(p, line["n_board"], line["d_board"], d_laser_mm)]  # 1 × 6
    g = line_noise_gain(p, line["b1"], line["b2"], n_laser, intrinsics)
    g2 = g[0] * g[0] + g[1] * g[1]
    wG = [[w * c for c in G[0]]]
    M = _block_sum_mat(ops, gram(wG, G), n_all)
    Minv = spd_inverse(ops, M)
    Q_line = _block_sum_mat(ops, gram([[c * g2 for c in wG[0]]], G), n_all)
    h = _block_sum_mat(ops, gram(wG, a), n_line)  # per shot, 3 × 6
    Cinv_hT = spd_solve(ops, pose_C, mat_transpose(h))  # 6 × 3
    m_shots = _array_len(h[0][0]) // designs  # shots per design
    Q_pose = _block_sum_mat(ops, mat_mul(h, Cinv_hT), m_shots)
    Aaa = _block_sum_mat(ops, gram([[w * c for c in a[0]]], a), n_line)  # per shot Σ w a aᵀ
    n_points = ops.block_sum(w, n_all)
    # The calibration moves each pose's centres onto a straight line before the plane fit:
    # the line noise left in its residuals is the part along (1, s) per pose (s along the
    # line; G and the pose shifts are affine in s, so the plane itself does not change).
    s_along = _along(p, line["n_board"], n_laser)
    phi = [[w * 0.0 + 1.0, s_along]]
    Pw = _block_sum_mat(ops, gram([[w * f for f in phi[0]]], phi), n_line)
    Pg = _block_sum_mat(ops, gram([[w * g2 * f for f in phi[0]]], phi), n_line)
    tr_fit = ops.block_sum(_trace_mul(spd_inverse(ops, Pw), Pg), m_shots)
    out = {"M": M, "n_points": n_points,
           "cov_line": mat_mul(mat_mul(Minv, Q_line), Minv),
           "cov_pose": mat_mul(mat_mul(Minv, Q_pose), Minv),
           "ms_line": (ops.block_sum(w * g2, n_all) - _trace_mul(Minv, Q_line))
           / n_points,
           "ms_line_fitted": (tr_fit - _trace_mul(Minv, Q_line)) / n_points,
           "ms_pose": (ops.block_sum(_trace_mul(spd_inverse(ops, pose_C), Aaa), m_shots)
                       - _trace_mul(Minv, Q_pose)) / n_points}
    if mirror_terms:
        # δpose_i = −C_i⁻¹ B_i δm: the fit's Σ w G e moves by F_i δm, F_i = −h_i C_i⁻¹ B_i.
        CinvB = spd_solve(ops, pose_C, pose_B)  # 6 × 3
        F = [[-f for f in row] for row in mat_mul(h, CinvB)]
        BtCAC = gram(CinvB, mat_mul(Aaa, CinvB))  # per shot: (C⁻¹B)ᵀ Aaa (C⁻¹B)
        Q_m, tr_m = None, None
        for term in mirror_terms:
            # (mask, cov) or (mask, cov per design, cov per shot) when designs > 1
            mask, cov = term[0], term[1]
            cov_shot = term[2] if len(term) > 2 else cov
            Fm = _block_sum_mat(ops, [[f * mask for f in row] for row in F], m_shots)
            q = mat_mul(mat_mul(Fm, cov), mat_transpose(Fm))
            t = ops.block_sum(_trace_mul([[v * mask for v in row] for row in BtCAC], cov_shot),
                              m_shots)
            Q_m = q if Q_m is None else _mat_add(Q_m, q)
            tr_m = t if tr_m is None else tr_m + t
        out["cov_mirror"] = mat_mul(mat_mul(Minv, Q_m), Minv)
        out["ms_mirror"] = (tr_m - _trace_mul(Minv, Q_m)) / n_points
    return out


# --------------------------------------------------------------------------- numpy front end

@dataclass(frozen=True)
class LaserLineSamples:
    """The laser line on each laser board, sampled for the plane fit (numpy, camera frame).

    ``p_mm`` (m, k, 3) sample points, ``w`` (m, k) points of the real line each stands for
    (one detected centre per pixel along the line's major image axis), ``n_points`` (m,).
    """

    p_mm: np.ndarray
    w: np.ndarray
    n_points: np.ndarray


def _clip_line(foot, direction, lo, hi):
    """Parameter range of ``foot + s direction`` inside the box ``lo ≤ q ≤ hi`` (2-D)."""
    s0, s1 = -np.inf, np.inf
    for k in range(2):
        if abs(direction[k]) < 1e-12:
            if not lo[k] <= foot[k] <= hi[k]:
                return None
            continue
        a, b = (lo[k] - foot[k]) / direction[k], (hi[k] - foot[k]) / direction[k]
        s0, s1 = max(s0, min(a, b)), min(s1, max(a, b))
    return (s0, s1) if s1 > s0 else None


def laser_line_samples(R_board, t_board_mm, pattern_size, square_mm, n_laser, d_laser_mm, K,
                       *, n_line: int = 32, inset_squares: float = 0.25
                       ) -> tuple[np.ndarray, float] | None:
    """The laser line on one board (camera frame): ``n_line`` sample points and their weight.

    The line is the laser plane ∩ the board plane, clipped to the printed squares shrunk by
    ``inset_squares`` (as :func:`lts360.recon.calibration.laser_plane.laser_line_points`
    keeps its centres); the samples are the midpoints of ``n_line`` equal pieces, each
    weighted by the detected centres it stands for (pixels along the line's major image
    axis / ``n_line``).  ``None`` where the plane misses the board.
    """
    R, t = np.asarray(R_board, float), np.asarray(t_board_mm, float)
    nx, ny = pattern_size
    m = R.T @ np.asarray(n_laser, float)  # the plane in board coordinates: m · q = c
    c = float(d_laser_mm - np.asarray(n_laser, float) @ t)
    m2 = m[:2]
    if np.linalg.norm(m2) < 1e-9:
        return None
    foot = m2 * c / (m2 @ m2)
    direction = np.array([-m2[1], m2[0]]) / np.linalg.norm(m2)
    lo = np.array([(inset_squares - 1.0) * square_mm] * 2)
    hi = np.array([(nx - inset_squares) * square_mm, (ny - inset_squares) * square_mm])
    rng = _clip_line(foot, direction, lo, hi)
    if rng is None:
        return None
    s = rng[0] + (np.arange(n_line) + 0.5) / n_line * (rng[1] - rng[0])
    q = foot + np.outer(s, direction)
    p = np.column_stack([q, np.zeros(n_line)]) @ R.T + t
    ends = np.column_stack([foot + np.outer(rng, direction), np.zeros(2)]) @ R.T + t
    uv = ends[:, :2] / ends[:, 2:3] * np.diag(K)[:2]
    n_px = float(np.max(np.abs(uv[1] - uv[0])))
    return p, n_px / n_line


def _plane_cam(n_world, d_world, R, t):
    """A world plane in the camera frame, oriented with ``d < 0`` (camera on the + side)."""
    n = R @ np.asarray(n_world, float)
    d = float(d_world + n @ t)
    return (-n, -d) if d > 0 else (n, d)


def _cols(P):
    """(k, 3) → list of 3 arrays."""
    P = np.asarray(P, float)
    return [P[:, 0].copy(), P[:, 1].copy(), P[:, 2].copy()]


def _rep(v, k):
    """A per-shot (m, 3) or (m,) array repeated ``k`` times per shot, as columns."""
    v = np.repeat(np.asarray(v, float), k, axis=0)
    return _cols(v) if v.ndim == 2 else v


def _np(A) -> np.ndarray:
    return np.array([[np.asarray(v, float).reshape(-1)[0] for v in row] for row in A])


@dataclass(frozen=True)
class CalibrationPrediction:
    """The predicted covariance of a rig calibration (see the module docstring).

    Attributes
    ----------
    camera_cov : (6, 6) float
        Of ``fx fy cx cy k1 k2`` (px², px², px², px², 1, 1).
    mirror_cov : dict of name → (3, 3) float
        ``(a, b, δ)`` (rad, rad, mm) of each mirror, camera frame, ``d < 0``.
    laser_cov : (3, 3) float
        ``(a, b, δ)`` of the laser plane: the sum of ``laser_parts``.
    laser_parts : dict of name → (3, 3) float
        ``line`` (σ_l), ``pose`` (σ_c through the board poses), ``mirror`` (the mirrors'
        covariance through the poses; zero unless asked for).
    laser_residual_rms_mm : float
        The laser-plane fit's expected residual RMS (all sources), of the points as the
        calibration fits them (each pose's moved onto its straight line): comparable with
        ``LaserPlaneEstimate.rms_mm``.
    laser_points : (m,) float
        Line points per laser pose (centres along the line's major image axis).
    planes_cam : dict of name → ((3,) float, float)
        The planes (``laser`` and the mirrors) the covariances refer to.
    sigma_corner_px, sigma_target_px, sigma_line_px : float
        The noise levels used (camera board corners, mirror/laser board corners, line).
    """

    camera_cov: np.ndarray
    mirror_cov: dict
    laser_cov: np.ndarray
    laser_parts: dict
    laser_residual_rms_mm: float
    laser_points: np.ndarray
    planes_cam: dict
    sigma_corner_px: float
    sigma_target_px: float
    sigma_line_px: float
    notes: dict = field(default_factory=dict)

    @property
    def camera_std(self) -> dict:
        """Standard deviations of the intrinsics, by name (p1 p2 k3: 0, fixed)."""
        out = dict.fromkeys(CAMERA_NAMES, 0.0)
        out.update(zip(INTRINSIC_NAMES, np.sqrt(np.diag(self.camera_cov)).tolist()))
        return out

    def sigma_line_for_residual_rms(self, residual_rms_mm: float) -> float:
        """The line noise ``σ_l`` (px) at which the laser fit's expected residual RMS (points
        on their per-pose lines, as the calibration fits them) is ``residual_rms_mm``, the
        other sources as predicted; 0 where those alone explain it."""
        u = self.notes["laser_ms_per_unit"]
        rest = self.laser_residual_rms_mm ** 2 - u["line_fitted_mm2_per_px2"] * \
            self.sigma_line_px ** 2
        return float(np.sqrt(max(residual_rms_mm ** 2 - rest, 0.0) /
                             u["line_fitted_mm2_per_px2"]))

    def to_uncertainty(self) -> dict:
        """The layout of ``Calibration.uncertainty`` (camera std + cov over the nine names,
        ``mirrors.<name>.cov_abd``, ``laser_plane.cov_abd``), so that a prediction can be
        compared with a calibration file and drawn from like one."""
        cov9 = np.zeros((9, 9))
        cov9[:6, :6] = self.camera_cov

        def plane(c):
            c = np.asarray(c, float)
            return {"cov_abd": c.tolist(),
                    "std_angle_deg": float(np.degrees(np.sqrt(np.trace(c[:2, :2])))),
                    "std_offset_mm": float(np.sqrt(c[2, 2]))}

        return {"camera": {"std": self.camera_std, "std_method": "fisher (predicted)",
                           "cov": cov9.tolist(), "cov_names": list(CAMERA_NAMES),
                           "rms_px": self.sigma_corner_px},
                "mirrors": {k: plane(v) for k, v in self.mirror_cov.items()},
                "laser_plane": plane(self.laser_cov),
                "parameterisation": "planes: n' = normalise(n + a e1 + b e2), d' = d + delta; "
                                    "lts360.recon.calibration.uncertainty.tangent_basis(n) "
                                    "gives e1, e2"}


def predict_calibration_covariance(rig, shots, *, sigma_corner_px: float,
                                   sigma_line_px: float, sigma_target_px: float | None = None,
                                   laser_boards_in_mirror_fit: bool = True,
                                   mirror_into_laser: bool = False,
                                   mirror_cov_for_laser: dict | None = None, n_line: int = 32,
                                   ops=NUMPY_OPS) -> CalibrationPrediction:
    """Predict the calibration's covariance for ``rig`` and a plan (numpy front end).

    Parameters
    ----------
    rig : lts360.scenes.rig.Rig
        The true rig (camera K and k1, k2, pose; mirrors; laser sheet).
    shots : list of BoardShot
        :func:`lts360.scenes.calib_plan.plan_calibration`'s plan.
    sigma_corner_px : float, > 0
        Corner noise of the camera board (px, per coordinate).
    sigma_line_px : float, >= 0
        Line-centre noise across the line, per detected centre (px).
    sigma_target_px : float, > 0, optional
        Corner noise of the mirror/laser board (default ``sigma_corner_px``).
    laser_boards_in_mirror_fit : bool
        Laser shots seen in a mirror join that mirror's fit (the calibration's default).
    mirror_into_laser : bool
        Carry the mirror covariance into the laser boards' poses (shared by the boards seen
        in one mirror): the predicted one, or ``mirror_cov_for_laser``.
    mirror_cov_for_laser : dict of name → (3, 3), optional
        Mirror covariances to carry instead of the predicted ones (e.g. a calibration's
        jackknife), in this module's orientation (``d < 0``).
    n_line : int
        Samples per laser line.

    Raises
    ------
    ValueError
        A stage without shots, a noise level out of range, or a laser board the sheet
        does not cross.
    """
    if not sigma_corner_px > 0 or not sigma_line_px >= 0:
        raise ValueError(f"sigma_corner_px must be > 0 and sigma_line_px >= 0, got "
                         f"{sigma_corner_px}, {sigma_line_px}")
    s_t = sigma_corner_px if sigma_target_px is None else float(sigma_target_px)
    cam = rig.camera
    R, t = np.asarray(cam.R, float), np.asarray(cam.t_mm, float)
    K = np.asarray(cam.K, float)
    dist = np.asarray(cam.distortion, float)
    intr = (K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist[0], dist[1])

    def corners_cam(sel):
        pts = [s.board.corners_world_mm() @ R.T + t for s in sel]
        return _cols(np.concatenate(pts)), len(pts[0])

    cam_shots = [s for s in shots if s.kind == "camera"]
    if len(cam_shots) < 3:
        raise ValueError(f"predict_calibration_covariance: {len(cam_shots)} camera shots, "
                         "need at least 3")
    Xc, nc = corners_cam(cam_shots)
    camera_cov = np.linalg.inv(_np(camera_information(ops, Xc, intr, nc))) * sigma_corner_px ** 2

    planes = {m.name: _plane_cam(*m.plane, R, t) for m in rig.mirrors}
    planes["laser"] = _plane_cam(*rig.laser.plane, R, t)
    basis = {k: tangent_basis_np(n) for k, (n, _) in planes.items()}
    mirror_cov = {}
    for name in (m.name for m in rig.mirrors):
        sel = [s for s in shots if s.mirror == name and
               (s.kind == "mirror" or (s.kind == "laser" and laser_boards_in_mirror_fit))]
        if not sel:
            raise ValueError(f"predict_calibration_covariance: no shot for mirror {name!r}")
        Xm, nm = corners_cam(sel)
        (n, d), (e1, e2) = planes[name], basis[name]
        info = _np(mirror_information(ops, Xm, intr, list(n), d, list(e1), list(e2), nm))
        mirror_cov[name] = np.linalg.inv(info) * s_t ** 2

    laser_shots = [s for s in shots if s.kind == "laser"]
    if len(laser_shots) < 2:
        raise ValueError("predict_calibration_covariance: need at least 2 laser shots")
    if any(s.mirror not in planes for s in laser_shots):
        raise ValueError("predict_calibration_covariance: every laser shot must be seen in a "
                         "mirror (plan_calibration(laser_in_mirror=True)); direct-only poses "
                         "are not modelled")
    nL, dL = planes["laser"]
    eL1, eL2 = basis["laser"]
    Xl, nl = corners_cam(laser_shots)
    mir_n = np.array([planes[s.mirror][0] for s in laser_shots])
    mir_d = np.array([planes[s.mirror][1] for s in laser_shots])
    mir_e1 = np.array([basis[s.mirror][0] for s in laser_shots])
    mir_e2 = np.array([basis[s.mirror][1] for s in laser_shots])
    C, B, _ = board_pose_information(ops, Xl, intr, _rep(mir_n, nl), _rep(mir_d, nl),
                                     _rep(mir_e1, nl), _rep(mir_e2, nl), nl)
    P, W, NB, DB, B1, B2, counts = [], [], [], [], [], [], []
    for s in laser_shots:
        T = s.board.T_world_board
        Rb, tb = R @ T[:3, :3], R @ T[:3, 3] + t
        got = laser_line_samples(Rb, tb, s.board.pattern_size, s.board.square_mm, nL, dL, K,
                                 n_line=n_line)
        if got is None:
            raise ValueError(f"predict_calibration_covariance: the laser sheet misses the "
                             f"board of {s.name}")
        P.append(got[0])
        W.append(np.full(n_line, got[1]))
        counts.append(got[1] * n_line)
        NB.append(Rb[:, 2])
        DB.append(float(Rb[:, 2] @ tb))
        B1.append(Rb[:, 0])
        B2.append(Rb[:, 1])
    line = {"p": _cols(np.concatenate(P)), "w": np.concatenate(W),
            "n_board": _rep(NB, n_line), "d_board": _rep(DB, n_line),
            "b1": _rep(B1, n_line), "b2": _rep(B2, n_line)}
    terms = None
    if mirror_into_laser:
        terms = [((np.array([s.mirror == k for s in laser_shots], float)),
                  [[float(v) for v in row] for row in (mirror_cov_for_laser or mirror_cov)[k]])
                 for k in mirror_cov]
    parts = laser_plane_parts(ops, line, C, B, list(nL), dL, list(eL1), list(eL2), intr,
                              n_line, mirror_terms=terms)
    lp = {"line": _np(parts["cov_line"]) * sigma_line_px ** 2,
          "pose": _np(parts["cov_pose"]) * s_t ** 2,
          "mirror": _np(parts["cov_mirror"]) if terms else np.zeros((3, 3))}
    ms = (float(parts["ms_line_fitted"][0]) * sigma_line_px ** 2
          + float(parts["ms_pose"][0]) * s_t ** 2
          + (float(parts["ms_mirror"][0]) if terms else 0.0))
    return CalibrationPrediction(
        camera_cov=camera_cov, mirror_cov=mirror_cov, laser_cov=sum(lp.values()),
        laser_parts=lp, laser_residual_rms_mm=float(np.sqrt(max(ms, 0.0))),
        laser_points=np.array(counts), planes_cam={k: (np.asarray(n), float(d))
                                                   for k, (n, d) in planes.items()},
        sigma_corner_px=float(sigma_corner_px), sigma_target_px=s_t,
        sigma_line_px=float(sigma_line_px),
        notes={"laser_ms_per_unit": {"line_mm2_per_px2": float(parts["ms_line"][0]),
                                     "line_fitted_mm2_per_px2":
                                         float(parts["ms_line_fitted"][0]),
                                     "pose_mm2_per_px2": float(parts["ms_pose"][0])}})


# --------------------------------------------------------------------------- the plan's covariance

#: Noise levels of the rendered calibration (the demo's ``lts360 calibrate``, paper rig, 64 spp,
#: measured 2026-12-03): the camera board's corners, σ per coordinate = OpenCV's per-corner
#: RMS 0.045 px / √2; the small mirror/laser board's corners (its mirror fits' per-coordinate
#: RMS); the line centres, per detected centre, the σ at which this model's laser-fit residual
#: (each pose's points moved onto their straight line, as the calibration fits them) equals
#: the demo's 5.56 µm.
PLAN_SIGMA_CORNER_PX = 0.0317
PLAN_SIGMA_TARGET_PX = 0.0089
PLAN_SIGMA_LINE_PX = 0.54


def plan_covariance(rig, *, n_camera: int = 30, n_mirror: int = 6, n_laser: int = 6,
                    seed: int = 0, sigma_corner_px: float = PLAN_SIGMA_CORNER_PX,
                    sigma_target_px: float = PLAN_SIGMA_TARGET_PX,
                    sigma_line_px: float = PLAN_SIGMA_LINE_PX):
    """The covariance ``lts360 calibrate``'s plan for ``rig`` is predicted to give, as a
    :class:`lts360.design.shares.CalibrationCovariance` the design model propagates.

    The plan is :func:`lts360.scenes.calib_plan.plan_calibration` with ``lts360 calibrate``'s
    defaults (30 camera shots, 6 per mirror, 6 laser shots, seed 0, the default boards); the
    mirrors' covariance is carried into the laser boards' poses.  The prediction assumes
    independent corner errors: the calibration's jackknife, which sees errors shared by a
    board, is 1–7× larger on the demo (STUDIES.md).

    Raises
    ------
    ValueError
        The plan cannot be made for this rig, or a stage has too few shots.
    """
    from lts360.design.shares import CalibrationCovariance
    from lts360.scenes.calib_plan import plan_calibration

    shots = plan_calibration(rig, n_camera=n_camera, n_mirror=n_mirror, n_laser=n_laser,
                             seed=seed)
    pred = predict_calibration_covariance(rig, shots, sigma_corner_px=sigma_corner_px,
                                          sigma_target_px=sigma_target_px,
                                          sigma_line_px=sigma_line_px, mirror_into_laser=True)
    planes = {k: n for k, (n, _) in pred.planes_cam.items()}
    return CalibrationCovariance.from_uncertainty(
        pred.to_uncertainty(), planes,
        source=f"plan of {rig.name} ({n_camera} camera, {n_mirror} per mirror, {n_laser} "
               f"laser shots; σ corner {sigma_corner_px:g}/{sigma_target_px:g} px, line "
               f"{sigma_line_px:g} px)")


# --------------------------------------------------------------------------- in the design model

@dataclass(frozen=True, eq=False)
class CalibrationPlan:
    """A calibration plan the design model re-predicts for every design (with gradients).

    The plan is made once, for the base rig (:func:`plan_calibration` with ``lts360
    calibrate``'s defaults).  As the design changes, the camera boards keep their image:
    relative to the camera, each board keeps its orientation and the lateral position of its
    centre, and the centre's depth scales with the focal length (the same pixels, the same
    size in the image, the same tilts); the mirror and laser
    boards stay where they were *in the world* (in the measurement volume); every
    covariance (intrinsics, mirrors, laser plane, with the mirrors' carried into the laser
    boards' poses) is recomputed from the design's camera, mirrors and laser.  The laser
    line's sample points on each board stay in the world (the sheet is the plane z = 0 of
    every design) with the base rig's weights.  Compared by identity (one recording of the
    model per plan).
    """

    names: tuple
    mirror_names: tuple
    cam_X: np.ndarray        # (S_c n_c, 3) camera frame, base rig
    n_cam_corners: int
    cam_centre_z: np.ndarray  # (S_c n_c,) depth of each corner's board centre, base rig
    f_px_base: float
    mirror_X: tuple          # per mirror (S_m n, 3) world
    mirror_corners: tuple    # per mirror: corners per shot
    laser_X: np.ndarray      # (S_l n_l, 3) world
    n_laser_corners: int
    laser_mirror: np.ndarray  # (S_l,) index into mirror_names
    line_p: np.ndarray       # (S_l n_line, 3) world
    line_w: np.ndarray       # (S_l n_line,)
    line_nb: np.ndarray      # (S_l, 3) board normal, world
    line_db: np.ndarray      # (S_l,) board offset, world
    line_b1: np.ndarray      # (S_l, 3)
    line_b2: np.ndarray      # (S_l, 3)
    n_line: int
    sigma_corner_px: float
    sigma_target_px: float
    sigma_line_px: float
    source: str = ""

    @classmethod
    def from_rig(cls, rig, *, n_camera: int = 30, n_mirror: int = 6, n_laser: int = 6,
                 seed: int = 0, sigma_corner_px: float = PLAN_SIGMA_CORNER_PX,
                 sigma_target_px: float = PLAN_SIGMA_TARGET_PX,
                 sigma_line_px: float = PLAN_SIGMA_LINE_PX, n_line: int = 32
                 ) -> "CalibrationPlan":
        """The plan of ``rig`` (raises ValueError as :func:`predict_calibration_covariance`)."""
        from lts360.scenes.calib_plan import plan_calibration

        shots = plan_calibration(rig, n_camera=n_camera, n_mirror=n_mirror, n_laser=n_laser,
                                 seed=seed)
        cam = rig.camera
        R, t = np.asarray(cam.R, float), np.asarray(cam.t_mm, float)
        K = np.asarray(cam.K, float)
        mnames = tuple(m.name for m in rig.mirrors)
        cam_shots = [s for s in shots if s.kind == "camera"]
        if len(cam_shots) < 3:
            raise ValueError(f"calibration plan: {len(cam_shots)} camera shots, need 3")
        cam_X = np.concatenate([s.board.corners_world_mm() @ R.T + t for s in cam_shots])
        n_c = len(cam_shots[0].board.corners_world_mm())
        centre_z = np.repeat(cam_X[:, 2].reshape(-1, n_c).mean(axis=1), n_c)
        mX, mC = [], []
        for name in mnames:
            sel = [s for s in shots if s.mirror == name and s.kind in ("mirror", "laser")]
            if not sel:
                raise ValueError(f"calibration plan: no shot for mirror {name!r}")
            mX.append(np.concatenate([s.board.corners_world_mm() for s in sel]))
            mC.append(len(sel[0].board.corners_world_mm()))
        lshots = [s for s in shots if s.kind == "laser"]
        if len(lshots) < 2 or any(s.mirror not in mnames for s in lshots):
            raise ValueError("calibration plan: needs ≥ 2 laser shots, each seen in a mirror")
        nL, dL = _plane_cam(*rig.laser.plane, R, t)
        P, W, NB, DB, B1, B2 = [], [], [], [], [], []
        for s in lshots:
            T = s.board.T_world_board
            Rb, tb = R @ T[:3, :3], R @ T[:3, 3] + t
            got = laser_line_samples(Rb, tb, s.board.pattern_size, s.board.square_mm, nL, dL,
                                     K, n_line=n_line)
            if got is None:
                raise ValueError(f"calibration plan: the laser sheet misses {s.name}")
            P.append((got[0] - t) @ R)  # back to the world
            W.append(np.full(n_line, got[1]))
            NB.append(T[:3, 2])
            DB.append(float(T[:3, 2] @ T[:3, 3]))
            B1.append(T[:3, 0])
            B2.append(T[:3, 1])
        names = tuple([f"camera.{n}" for n in CAMERA_NAMES]
                      + [f"{m}.{p}" for m in sorted(mnames) for p in ("a", "b", "delta")]
                      + [f"laser.{p}" for p in ("a", "b", "delta")])
        return cls(names=names, mirror_names=mnames, cam_X=cam_X,
                   n_cam_corners=n_c, cam_centre_z=centre_z, f_px_base=float(K[0, 0]),
                   mirror_X=tuple(mX), mirror_corners=tuple(mC),
                   laser_X=np.concatenate([s.board.corners_world_mm() for s in lshots]),
                   n_laser_corners=len(lshots[0].board.corners_world_mm()),
                   laser_mirror=np.array([mnames.index(s.mirror) for s in lshots]),
                   line_p=np.concatenate(P), line_w=np.concatenate(W), line_nb=np.array(NB),
                   line_db=np.array(DB), line_b1=np.array(B1), line_b2=np.array(B2),
                   n_line=n_line, sigma_corner_px=float(sigma_corner_px),
                   sigma_target_px=float(sigma_target_px), sigma_line_px=float(sigma_line_px),
                   source=f"plan of {rig.name} per design ({n_camera} camera, {n_mirror} per "
                          f"mirror, {n_laser} laser shots; σ corner {sigma_corner_px:g}/"
                          f"{sigma_target_px:g} px, line {sigma_line_px:g} px)")

    def arrays(self, F, U, designs: int) -> dict:
        """The plan's constants as Dr.Jit arrays for ``designs`` designs (tiled), with the
        design index of every element (made outside the model's recorded function)."""
        def cols(a, key, out):
            a = np.tile(np.asarray(a, float), (designs, 1)) if np.ndim(a) == 2 else \
                np.tile(np.asarray(a, float), designs)
            if a.ndim == 2:
                for j in range(a.shape[1]):
                    out[f"{key}{j}"] = F(a[:, j].copy())
            else:
                out[key] = F(a)
            return out

        def di(n):
            return U(np.repeat(np.arange(designs), n))

        out: dict = {}
        cols(self.cam_X, "camX", out)
        cols(self.cam_centre_z, "camZ", out)
        out["camdi"] = di(len(self.cam_X))
        for k, X in enumerate(self.mirror_X):
            cols(X, f"m{k}X", out)
            out[f"m{k}di"] = di(len(X))
        cols(self.laser_X, "lX", out)
        out["ldi"] = di(len(self.laser_X))
        nl = self.n_laser_corners
        for k in range(len(self.mirror_names)):
            sel = (self.laser_mirror == k).astype(float)
            cols(np.repeat(sel, nl), f"lmask{k}_c", out)
            cols(sel, f"lmask{k}_s", out)
        cols(self.line_p, "pX", out)
        cols(self.line_w, "pw", out)
        out["pdi"] = di(len(self.line_p))
        for key, a in (("nb", self.line_nb), ("b1", self.line_b1), ("b2", self.line_b2)):
            cols(np.repeat(a, self.n_line, axis=0), key, out)
        cols(np.repeat(self.line_db, self.n_line), "db", out)
        out["sdi"] = di(len(self.laser_mirror))  # per laser shot
        out["one"] = di(1)  # per design
        return out

    def covariance(self, ops, A: dict, view, designs: int) -> list:
        """The predicted covariance over :attr:`names` (lists of rows of per-design arrays;
        ``None`` where it is zero by construction).

        ``view(di)`` returns the design's camera and planes gathered at the design indices
        ``di``: ``to_cam(X)``, ``rot(v)``, ``pos`` (3 arrays each), ``intr`` (fx, fy, cx,
        cy, k1, k2) and ``mirrors`` (list of (n_world, d_world)).
        """
        sc, st, sl = self.sigma_corner_px, self.sigma_target_px, self.sigma_line_px

        def x3(key):
            return [A[f"{key}{j}"] for j in range(3)]

        def dot(a, b):
            return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

        def plane_cam(v, n_w, d_w):
            n = v["rot"](n_w)
            d = d_w - dot(n_w, v["pos"])
            # tangent_basis: e1 = normalise(n × x̂), e2 = n × e1 (|n_x| < 0.9 here)
            e1 = [0.0 * n[0], n[2], -n[1]]
            norm = ops.sqrt(e1[1] * e1[1] + e1[2] * e1[2])
            e1 = [e1[0], e1[1] / norm, e1[2] / norm]
            e2 = [n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2],
                  n[0] * e1[1] - n[1] * e1[0]]
            return n, d, e1, e2

        def scaled(M, s2):
            return [[v * s2 for v in row] for row in M]

        n_cam_shots = len(self.cam_X) // self.n_cam_corners
        v = view(A["camdi"])
        Xc = x3("camX")
        # each board's centre moves in depth by f / f_base (the board keeps its image)
        Xc[2] = Xc[2] + A["camZ"] * (v["intr"][0] * (1.0 / self.f_px_base) - 1.0)
        cam_info = camera_information(ops, Xc, v["intr"], self.n_cam_corners,
                                      shots=n_cam_shots)
        cov_cam = scaled(spd_inverse(ops, cam_info), sc * sc)
        cov_m = []
        for k in range(len(self.mirror_names)):
            v = view(A[f"m{k}di"])
            n, d, e1, e2 = plane_cam(v, *v["mirrors"][k])
            nc = self.mirror_corners[k]
            info = mirror_information(ops, v["to_cam"](x3(f"m{k}X")), v["intr"], n, d, e1, e2,
                                      nc, shots=len(self.mirror_X[k]) // nc)
            cov_m.append(scaled(spd_inverse(ops, info), st * st))
        # laser boards: each seen directly and in its mirror
        v = view(A["ldi"])
        planes = [plane_cam(v, *m) for m in v["mirrors"]]
        masks = [A[f"lmask{k}_c"] for k in range(len(planes))]

        def pick(i):
            out = None
            for mk, pl in zip(masks, planes):
                val = pl[i]
                term = [c * mk for c in val] if isinstance(val, list) else val * mk
                out = term if out is None else (
                    [a + b for a, b in zip(out, term)] if isinstance(term, list) else out + term)
            return out

        C, B, _ = board_pose_information(ops, v["to_cam"](x3("lX")), v["intr"], pick(0),
                                         pick(1), pick(2), pick(3), self.n_laser_corners)
        v = view(A["pdi"])
        nL, dL, eL1, eL2 = plane_cam(v, [0.0, 0.0, 1.0], 0.0)
        nb_w = x3("nb")
        line = {"p": v["to_cam"](x3("pX")), "w": A["pw"], "n_board": v["rot"](nb_w),
                "d_board": A["db"] - dot(nb_w, v["pos"]), "b1": v["rot"](x3("b1")),
                "b2": v["rot"](x3("b2"))}
        terms = []
        for k in range(len(self.mirror_names)):
            per_shot = [[ops.gather(c, A["sdi"]) for c in row] for row in cov_m[k]]
            terms.append((A[f"lmask{k}_s"], cov_m[k], per_shot))
        parts = laser_plane_parts(ops, line, C, B, nL, dL, eL1, eL2, v["intr"], self.n_line,
                                  mirror_terms=terms, designs=designs)
        cov_l = [[parts["cov_line"][i][j] * (sl * sl) + parts["cov_pose"][i][j] * (st * st)
                  + parts["cov_mirror"][i][j] for j in range(3)] for i in range(3)]
        # assemble over names
        K = len(self.names)
        out = [[None] * K for _ in range(K)]
        for i in range(6):
            for j in range(6):
                out[i][j] = cov_cam[i][j]
        order = sorted(range(len(self.mirror_names)), key=lambda k: self.mirror_names[k])
        o = 9
        for k in order:
            for i in range(3):
                for j in range(3):
                    out[o + i][o + j] = cov_m[k][i][j]
            o += 3
        for i in range(3):
            for j in range(3):
                out[o + i][o + j] = cov_l[i][j]
        return out
