"""Small dense linear algebra of the compiled kernel (loops numba compiles): Cholesky factor and solve,
matrix product.  Used by the filter step and the smoothers."""
from __future__ import annotations

import math

import numpy as np

def cholesky(A, n, L):
    """Lower Cholesky factor of ``A[:n, :n]`` into ``L[:n, :n]``; False when ``A`` is not positive
    definite or not finite (the filter's innovation covariance and the smoother's prediction covariance)."""
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j]
            for m in range(j):
                s -= L[i, m] * L[j, m]
            if i == j:
                if not s > 0.0:
                    return False
                L[i, i] = math.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
    return True


def chol_solve(L, n, X, w, a):
    """Solve ``L L^T [X | a] = [X | a]`` in place for the first ``n`` rows (``X`` ``w`` columns wide,
    ``a`` a vector), by forward then backward substitution a row at a time: the filter's gain
    ``[K^T, S^-1 e]`` and the smoother's ``[K^T, S^-1 e]`` and ``S^-1``."""
    for i in range(n):
        s = a[i]
        for m in range(i):
            lim = L[i, m]
            s -= lim * a[m]
            for j in range(w):
                X[i, j] -= lim * X[m, j]
        lii = L[i, i]
        a[i] = s / lii
        for j in range(w):
            X[i, j] = X[i, j] / lii
    for i in range(n - 1, -1, -1):
        s = a[i]
        for m in range(i + 1, n):
            lmi = L[m, i]
            s -= lmi * a[m]
            for j in range(w):
                X[i, j] -= lmi * X[m, j]
        lii = L[i, i]
        a[i] = s / lii
        for j in range(w):
            X[i, j] = X[i, j] / lii


def mat_mul(A, B, out):
    """``out = A @ B`` (small matrices; loops)."""
    n, m = A.shape
    k = B.shape[1]
    for i in range(n):
        for j in range(k):
            s = 0.0
            for a in range(m):
                s += A[i, a] * B[a, j]
            out[i, j] = s
