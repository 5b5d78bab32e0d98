"""The Newton system's linear algebra on its arrow structure.

The unknowns of one particle are its joint angles theta (N, K) and a small change of the
object's pose (dp, dw), p <- p + dp, R <- R exp([dw]x). The Hessian is an arrow: finger
blocks A_i (K x K) coupled only through the object's block C (6 x 6) by B_i (K x 6). The
system is solved by the Schur complement, S = C - sum B_i^T A_i^-1 B_i: O(N K^3 + 6^3) per
particle instead of O((N K + 6)^3). `factor` keeps what further right-hand sides need
(`solve`), so that the stored tangent (three of them) costs little more than its products.
"""

from __future__ import annotations

import math

from numba import njit

from vlr.kernels.records import JOINTS


@njit(cache=True, _nrt=False)
def cholesky(M, n):
    """In-place lower Cholesky of the leading n x n block; False if not positive definite."""
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= M[j, k] * M[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        M[j, j] = d
        for i in range(j + 1, n):
            t = M[i, j]
            for k in range(j):
                t -= M[i, k] * M[j, k]
            M[i, j] = t / d
    return True


@njit(cache=True, _nrt=False)
def cholesky_solve(L, n, b):
    """Solve (L L^T) x = b in place, b a vector."""
    for i in range(n):
        t = b[i]
        for k in range(i):
            t -= L[i, k] * b[k]
        b[i] = t / L[i, i]
    for i in range(n - 1, -1, -1):
        t = b[i]
        for k in range(i + 1, n):
            t -= L[k, i] * b[k]
        b[i] = t / L[i, i]


@njit(cache=True, _nrt=False)
def factor(A, B, C, damping, Ainv, X, S, La):
    """Factor the arrow (A, B, C) + damping * diag(|H|) (Marquardt's scaling, so that the
    damping is free of radians and metres): Ainv (N, K, K) the finger blocks' inverses,
    X (N, K, 6) = Ainv B, S (6, 6) the Schur complement's Cholesky factor; La (K, K)
    scratch. False if a block is not positive definite."""
    n_f, k_n = A.shape[0], JOINTS
    for a in range(6):
        for b in range(6):
            S[a, b] = C[a, b]
        S[a, a] += damping * (abs(C[a, a]) + 1e-9)
    for i in range(n_f):
        if k_n == 2:  # the Model O's two joints: the inverse in closed form
            a00 = A[i, 0, 0] + damping * (abs(A[i, 0, 0]) + 1e-9)
            a11 = A[i, 1, 1] + damping * (abs(A[i, 1, 1]) + 1e-9)
            a01 = A[i, 0, 1]
            det = a00 * a11 - a01 * a01
            if not (a00 > 0.0 and det > 0.0):
                return False
            Ainv[i, 0, 0] = a11 / det
            Ainv[i, 0, 1] = -a01 / det
            Ainv[i, 1, 0] = -a01 / det
            Ainv[i, 1, 1] = a00 / det
        else:
            if not _invert_spd(A, i, k_n, damping, Ainv, La):
                return False
        for c in range(6):
            for a in range(k_n):
                t = 0.0
                for m in range(k_n):
                    t += Ainv[i, a, m] * B[i, m, c]
                X[i, a, c] = t
        for a in range(6):
            for b in range(a, 6):
                t = 0.0
                for m in range(k_n):
                    t += B[i, m, a] * X[i, m, b]
                S[a, b] -= t
                if b != a:
                    S[b, a] -= t
    return cholesky(S, 6)


@njit(cache=True, _nrt=False)
def _invert_spd(A, i, k_n, damping, Ainv, La):
    """Ainv[i] = (A[i] + damping diag(|A[i]|))^-1 by Cholesky in La (K, K); False if not
    positive definite."""
    for a in range(k_n):
        for b in range(k_n):
            La[a, b] = A[i, a, b]
        La[a, a] += damping * (abs(A[i, a, a]) + 1e-9)
    if not cholesky(La, k_n):
        return False
    for c in range(k_n):
        for a in range(k_n):  # L w = e_c
            t = 1.0 if a == c else 0.0
            for k in range(a):
                t -= La[a, k] * Ainv[i, k, c]
            Ainv[i, a, c] = t / La[a, a]
        for a in range(k_n - 1, -1, -1):  # L^T x = w
            t = Ainv[i, a, c]
            for k in range(a + 1, k_n):
                t -= La[k, a] * Ainv[i, k, c]
            Ainv[i, a, c] = t / La[a, a]
    return True


@njit(cache=True, _nrt=False)
def solve(gA, gC, B, fac, dth, dc, y):
    """The Newton step H d = -g from a factorisation (`factor`'s Ainv, X, S, as `fac`):
    dth (N, K), dc (6,); y (N, K) scratch."""
    Ainv, X, S = fac
    n_f, k_n = gA.shape[0], JOINTS
    for a in range(6):
        dc[a] = -gC[a]
    for i in range(n_f):
        for a in range(k_n):
            t = 0.0
            for m in range(k_n):
                t -= Ainv[i, a, m] * gA[i, m]
            y[i, a] = t
        for a in range(6):
            t = 0.0
            for m in range(k_n):
                t += B[i, m, a] * y[i, m]
            dc[a] -= t
    cholesky_solve(S, 6, dc)
    for i in range(n_f):
        for a in range(k_n):
            t = y[i, a]
            for c in range(6):
                t -= X[i, a, c] * dc[c]
            dth[i, a] = t
