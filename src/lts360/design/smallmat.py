"""Small matrices of arrays: one matrix per element of the arrays, written out by hand.

A matrix is a Python list of rows of arrays (numpy, or Dr.Jit ``Float64`` inside a recorded
model), so that the same unrolled algebra runs in numpy for checks and in Dr.Jit for the
design model's reverse-mode gradient.  Functions that need ``sqrt`` or a reduction take an
``ops`` object (:mod:`lts360.design.backend`).

Two inverses of a symmetric positive definite matrix live here, for two different jobs:
:func:`spd_inverse` (equilibrated Cholesky, no ridge: the calibration's information blocks,
whose units differ by orders of magnitude) and :func:`spd_inverse_ridged` (a small ridge on
the diagonal: the compensation's moment matrices, where a view that sees nothing gives a
singular block that must stay finite).
"""

from __future__ import annotations

__all__ = ["mat_transpose", "dot_sum", "mat_mul", "gram", "mat_add", "mat_sub",
           "block_sum_mat", "cholesky", "spd_solve", "spd_inverse", "spd_inverse_ridged",
           "trace_mul"]


def mat_transpose(A: list) -> list:
    """Transpose of a list-of-rows matrix."""
    return [list(r) for r in zip(*A)]


def dot_sum(terms):
    """The sum of an iterable of arrays (no 0 start: keeps the arrays' type)."""
    it = iter(terms)
    s = next(it)
    for t in it:
        s = s + t
    return s


def mat_mul(A: list, B: list) -> list:
    """``A B`` for list-of-rows matrices of arrays (elementwise over the arrays)."""
    Bt = mat_transpose(B)
    return [[dot_sum(a * b for a, b in zip(row, col)) for col in Bt] for row in A]


def gram(J1: list, J2: list) -> list:
    """``J1ᵀ J2`` for ``J1`` (r × p) and ``J2`` (r × q), elementwise over the arrays."""
    return [[dot_sum(J1[r][i] * J2[r][j] for r in range(len(J1))) for j in range(len(J2[0]))]
            for i in range(len(J1[0]))]


def mat_add(A: list, B: list) -> list:
    return [[a + b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def mat_sub(A: list, B: list) -> list:
    return [[a - b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def block_sum_mat(ops, A: list, n: int) -> list:
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


def trace_mul(A: list, B: list):
    """``tr(A B)`` for square matrices of arrays."""
    n = len(A)
    return dot_sum(A[i][k] * B[k][i] for i in range(n) for k in range(n))



def spd_inverse_ridged(A: list, sqrt, ridge: float = 1e-9) -> list:
    """Inverse of a small symmetric positive (semi)definite matrix of arrays, by Cholesky.

    ``A`` is a list of rows of arrays (numpy or Dr.Jit, one matrix per element); only the
    lower triangle is read.  A ridge of ``ridge × (1 + mean diagonal)`` on the diagonal keeps
    a singular block (a view that sees nothing) finite; it changes a well-posed inverse by a
    relative ~``ridge``.
    """
    n = len(A)
    tr = A[0][0]
    for i in range(1, n):
        tr = tr + A[i][i]
    eps = ridge * (1.0 + tr * (1.0 / n))
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        s = A[j][j] + eps
        for k in range(j):
            s = s - L[j][k] * L[j][k]
        d = sqrt(s)
        L[j][j] = d
        inv_d = 1.0 / d
        for i in range(j + 1, n):
            s = A[i][j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = s * inv_d
    # W = L⁻¹ (lower triangular), then A⁻¹ = Wᵀ W.
    W = [[None] * n for _ in range(n)]
    for i in range(n):
        W[i][i] = 1.0 / L[i][i]
        for j in range(i):
            s = L[i][j] * W[j][j]
            for k in range(j + 1, i):
                s = s + L[i][k] * W[k][j]
            W[i][j] = -s * W[i][i]
    inv = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = W[i][i] * W[i][j]
            for k in range(i + 1, n):
                s = s + W[k][i] * W[k][j]
            inv[i][j] = s
            inv[j][i] = s
    return inv
