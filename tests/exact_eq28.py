"""Eq. (28) solved exactly: the reference the float solvers' rounding is measured against."""

from __future__ import annotations

from fractions import Fraction


def eq28_exact(jac, a, dt):
    """``(δx, δF)`` of eq. (28), ``J δx = d_t``, ``Jᵀ δF + A δx = 0`` (``A = H − K``), solved exactly in
    rational arithmetic from the given float64 entries (Gaussian elimination with the largest pivot
    on ``Fraction``): two lists of ``Fraction``."""
    m, n = jac.shape
    e = m + n
    rows = [[Fraction(0)] * (e + 1) for _ in range(e)]
    for r in range(m):
        for c in range(n):
            rows[r][m + c] = rows[m + c][r] = Fraction(float(jac[r, c]))
        rows[r][e] = Fraction(float(dt[r]))
    for i in range(n):
        for j in range(n):
            rows[m + i][m + j] = Fraction(float(a[i, j]))
    for k in range(e):
        p = max(range(k, e), key=lambda i: abs(rows[i][k]))
        rows[k], rows[p] = rows[p], rows[k]
        rk = rows[k]
        for i in range(k + 1, e):
            f = rows[i][k] / rk[k]
            if f:
                ri = rows[i]
                for j in range(k, e + 1):
                    ri[j] -= f * rk[j]
    sol = [Fraction(0)] * e
    for i in range(e - 1, -1, -1):
        sol[i] = (rows[i][e] - sum(rows[i][j] * sol[j] for j in range(i + 1, e))) / rows[i][i]
    return sol[m:], sol[:m]
