"""The Fisher-information blocks of a rig calibration's three stages (camera, mirrors, laser
plane), on small matrices of arrays.

Each block is the Gauss–Newton normal matrix of one stage, linearised at the true rig and
the planned board poses, with the board poses as nuisance parameters eliminated by a Schur
complement; :mod:`lts360.design.calib_covariance` assembles them into the predicted
covariance and states the model and where it stops.  Everything works on Python lists of
arrays and an ``ops`` object (:mod:`lts360.design.backend`), so the same code runs in numpy
for checks and in Dr.Jit inside the design model.
"""

from __future__ import annotations

from lts360.design.smallmat import (
    block_sum_mat,
    dot_sum,
    gram,
    mat_add,
    mat_mul,
    mat_sub,
    mat_transpose,
    spd_inverse,
    spd_solve,
    trace_mul,
)

__all__ = ["project_jacobians", "pose_jacobian", "reflect", "reflect_jacobians", "plane_residual",
           "plane_residual_jacobian", "board_shift_jacobian", "line_noise_gain",
           "camera_information", "mirror_information", "board_pose_information", "laser_plane_parts"]


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
    h = dot_sum(a * b for a, b in zip(n, X_mm)) - d_mm
    return [x - 2.0 * h * c for x, c in zip(X_mm, n)]


def reflect_jacobians(X_mm: list, n: list, d_mm, e1: list, e2: list) -> tuple[list, list]:
    """Jacobians of :func:`reflect`: ``∂Xv/∂X = I − 2 n nᵀ`` and ``∂Xv/∂(a, b, δ)``.

    With ``n' = n + a e1 + b e2`` (normalising changes nothing to first order, ``e ⊥ n``):
    ``∂Xv/∂a = −2 ((e1·X) n + (n·X − d) e1)``, likewise ``b``; ``∂Xv/∂δ = 2 n``.
    """
    h = dot_sum(a * b for a, b in zip(n, X_mm)) - d_mm
    p1 = dot_sum(a * b for a, b in zip(e1, X_mm))
    p2 = dot_sum(a * b for a, b in zip(e2, X_mm))
    dX = [[(1.0 if i == j else 0.0) - 2.0 * n[i] * n[j] for j in range(3)] for i in range(3)]
    dm = [[-2.0 * (p1 * n[i] + h * e1[i]), -2.0 * (p2 * n[i] + h * e2[i]), 2.0 * n[i]]
          for i in range(3)]
    return dX, dm


def plane_residual(ops, p_mm: list, n: list, d_mm, e1: list, e2: list, abd: list):
    """``n' · p − d'`` of the plane moved by ``(a, b, δ)`` (exact, for checks)."""
    a, b, delta = abd
    m = [ni + a * u + b * v for ni, u, v in zip(n, e1, e2)]
    norm = ops.sqrt(dot_sum(c * c for c in m))
    return dot_sum(c * q for c, q in zip(m, p_mm)) / norm - (d_mm + delta)


def plane_residual_jacobian(p_mm: list, e1: list, e2: list) -> list:
    """``∂(n'·p − d')/∂(a, b, δ)`` at 0: the row ``(e1·p, e2·p, −1)``."""
    zero = p_mm[0] * 0.0
    return [dot_sum(a * b for a, b in zip(e1, p_mm)), dot_sum(a * b for a, b in zip(e2, p_mm)),
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
    m = [[dot_sum(J[r][k] * b[k] for k in range(3)) for b in (b1, b2)] for r in range(2)]
    det = m[0][0] * m[1][1] - m[0][1] * m[1][0]
    c1 = dot_sum(a * b for a, b in zip(n_laser, b1))
    c2 = dot_sum(a * b for a, b in zip(n_laser, b2))
    # c (1×2) times the inverse of m.
    return [(c1 * m[1][1] - c2 * m[1][0]) / det, (c2 * m[0][0] - c1 * m[0][1]) / det]


# --------------------------------------------------------------------------- information

def _schur_over_shots(ops, A: list, B: list, C: list, shots: int | None = None) -> list:
    """``Σ_i (A_i − B_i C_i⁻¹ B_iᵀ)`` for per-shot arrays: the parameters' information with
    each shot's pose eliminated (summed over blocks of ``shots`` shots: one block per design;
    default all)."""
    S = mat_sub(A, mat_mul(B, spd_solve(ops, C, mat_transpose(B))))
    m = shots or _array_len(S[0][0])
    return block_sum_mat(ops, S, m)


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
    A = block_sum_mat(ops, gram(Ji, Ji), n_corners)
    B = block_sum_mat(ops, gram(Ji, Jp), n_corners)
    C = block_sum_mat(ops, gram(Jp, Jp), n_corners)
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
    C = mat_add(gram(real, real), gram(virt, virt))
    return (block_sum_mat(ops, C, n_corners), block_sum_mat(ops, gram(virt, vm), n_corners),
            block_sum_mat(ops, gram(vm, vm), n_corners))


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
    return dot_sum(a * b for a, b in zip(direction, p_mm))


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
    M = block_sum_mat(ops, gram(wG, G), n_all)
    Minv = spd_inverse(ops, M)
    Q_line = block_sum_mat(ops, gram([[c * g2 for c in wG[0]]], G), n_all)
    h = block_sum_mat(ops, gram(wG, a), n_line)  # per shot, 3 × 6
    Cinv_hT = spd_solve(ops, pose_C, mat_transpose(h))  # 6 × 3
    m_shots = _array_len(h[0][0]) // designs  # shots per design
    Q_pose = block_sum_mat(ops, mat_mul(h, Cinv_hT), m_shots)
    Aaa = block_sum_mat(ops, gram([[w * c for c in a[0]]], a), n_line)  # per shot Σ w a aᵀ
    n_points = ops.block_sum(w, n_all)
    # The calibration moves each pose's centres onto a straight line before the plane fit:
    # the line noise left in its residuals is the part along (1, s) per pose (s along the
    # line; G and the pose shifts are affine in s, so the plane itself does not change).
    s_along = _along(p, line["n_board"], n_laser)
    phi = [[w * 0.0 + 1.0, s_along]]
    Pw = block_sum_mat(ops, gram([[w * f for f in phi[0]]], phi), n_line)
    Pg = block_sum_mat(ops, gram([[w * g2 * f for f in phi[0]]], phi), n_line)
    tr_fit = ops.block_sum(trace_mul(spd_inverse(ops, Pw), Pg), m_shots)
    out = {"M": M, "n_points": n_points,
           "cov_line": mat_mul(mat_mul(Minv, Q_line), Minv),
           "cov_pose": mat_mul(mat_mul(Minv, Q_pose), Minv),
           "ms_line": (ops.block_sum(w * g2, n_all) - trace_mul(Minv, Q_line))
           / n_points,
           "ms_line_fitted": (tr_fit - trace_mul(Minv, Q_line)) / n_points,
           "ms_pose": (ops.block_sum(trace_mul(spd_inverse(ops, pose_C), Aaa), m_shots)
                       - trace_mul(Minv, Q_pose)) / n_points}
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
            Fm = block_sum_mat(ops, [[f * mask for f in row] for row in F], m_shots)
            q = mat_mul(mat_mul(Fm, cov), mat_transpose(Fm))
            t = ops.block_sum(trace_mul([[v * mask for v in row] for row in BtCAC], cov_shot),
                              m_shots)
            Q_m = q if Q_m is None else mat_add(Q_m, q)
            tr_m = t if tr_m is None else tr_m + t
        out["cov_mirror"] = mat_mul(mat_mul(Minv, Q_m), Minv)
        out["ms_mirror"] = (tr_m - trace_mul(Minv, Q_m)) / n_points
    return out
