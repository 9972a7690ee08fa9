"""The loops of the chain kernels rearranged for speed (independent sums side by side, a reused
work array) against the loops as they were before (copied here): every result the same bits, on
random block-quasiseparable inputs whose sizes leave every remainder of the grouping (blocks of 1 to
5 rows, 1 to 8 generator columns, 1 to 4 right-hand sides), interpreted and, with numba, compiled;
including a singular pivot block (the early return)."""

import math

import numpy as np
import pytest

from vjm_pin.solver import chain_algebra as ca
from vjm_pin.solver import chain_kernel as ck
from vjm_pin.solver.chain_algebra import RHO_FACTOR

SIZES = [(1, 5, 1, 5, 2, 3, 4, 1), (5, 5, 1, 2), (3, 1, 1, 4, 5)]
GENS = [(1, 1), (2, 5), (3, 3), (4, 7), (6, 6), (8, 2)]


def _bits(a, b):
    if isinstance(a, tuple):
        return len(a) == len(b) and all(_bits(x, y) for x, y in zip(a, b))
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind != "f":
        return a.shape == b.shape and np.array_equal(a, b)
    return (a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
            and np.array_equal(np.signbit(a), np.signbit(b)))


def _problem(seed, sizes, r, s, symmetric=False, singular=False):
    rng = np.random.default_rng(seed)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n, b = int(starts[-1]), max(sizes)
    diag = np.zeros((n, b))
    for k in range(len(sizes)):
        a, e = starts[k], starts[k + 1]
        blk = rng.standard_normal((e - a, e - a)) + 4.0 * np.eye(e - a) * rng.choice([-1.0, 1.0])
        if symmetric:
            blk = blk + blk.T
        diag[a:e, : e - a] = blk
    if singular:  # the first pivot block (its Schur complement is itself) exactly zero
        diag[starts[0]:starts[1], :] = 0.0
    u, v = 0.3 * rng.standard_normal((n, r)), 0.3 * rng.standard_normal((n, r))
    p, q = 0.3 * rng.standard_normal((n, s)), 0.3 * rng.standard_normal((n, s))
    if symmetric:
        s_ = min(r, s)
        u, v = u[:, :s_].copy(), v[:, :s_].copy()
        p, q = v.copy(), u.copy()
    return starts, diag, u, v, p, q


def _cases():
    seed = 0
    for sizes in SIZES:
        for r, s in GENS:
            seed += 1
            yield seed, sizes, r, s


def _py(f):
    return getattr(f, "py_func", f)


def _kernels_compiled():
    numba = pytest.importorskip("numba")
    fns = ca._kernels()
    assert fns is not None
    g = {"np": np, "math": math, "RHO_FACTOR": RHO_FACTOR}
    exec(compile(_REFS, __file__, "exec"), g)
    small = numba.njit(g["_ref_inertia_small"])
    g["_ref_inertia_small"] = small
    return fns, {name: numba.njit(g[name]) for name in ("_ref_factor_loops", "_ref_solve_loops", "_ref_matvec_loops")}


@pytest.mark.parametrize("compiled", [False, True])
def test_factor_solve_matvec_same_bits(compiled):
    if compiled:
        (factor, solve, matvec), ref = _kernels_compiled()
        rfactor, rsolve, rmatvec = ref["_ref_factor_loops"], ref["_ref_solve_loops"], ref["_ref_matvec_loops"]
    else:
        factor, solve, matvec = _py(ca._factor_loops), _py(ca._solve_loops), _py(ca._matvec_loops)
        rfactor, rsolve, rmatvec = _ref_factor_loops, _ref_solve_loops, _ref_matvec_loops
    checked = 0
    for seed, sizes, r, s in _cases():
        for symmetric, lean, singular in ((False, False, False), (True, True, False), (True, False, False),
                                          (False, True, True), (True, True, True)):
            args = _problem(seed, sizes, r, s, symmetric, singular)
            got, want = factor(*args, symmetric, lean), rfactor(*args, symmetric, lean)
            assert _bits(got, want), (sizes, r, s, symmetric, lean, singular)
            if singular:
                assert got[3][4] == 1.0
                continue
            rng = np.random.default_rng(seed + 1000)
            pinv, x, y = got[:3]
            for nc in (1, 2, 4):
                rhs = rng.standard_normal((args[0][-1], nc))
                assert _bits(solve(args[0], pinv, args[2], x, y, args[5], rhs),
                             rsolve(args[0], pinv, args[2], x, y, args[5], rhs)), (sizes, r, s, nc)
                assert _bits(matvec(*args, rhs), rmatvec(*args, rhs)), (sizes, r, s, nc)
            checked += 1
    assert checked == len(SIZES) * len(GENS) * 3


def test_inertia_small_same_counts():
    rng = np.random.default_rng(7)
    for nk in range(1, 7):
        for _ in range(20):
            a = rng.standard_normal((nk, nk))
            a = a + a.T
            if nk > 2 and rng.random() < 0.3:
                a[0, :] = a[:, 0] = 0.0  # a zero pivot
            if nk > 1 and rng.random() < 0.3:
                a[np.diag_indices(nk)] *= 1e-3  # 2×2 pivots
            tiny = 1e-14 * nk * np.abs(a).sum(axis=1).max()
            want = _ref_inertia_small(a.copy(), nk, tiny)
            assert _py(ca._inertia_small)(a.copy(), nk, tiny) == want
            rows = np.zeros(nk + 2, np.int64)
            assert _py(ca._inertia_pivots)(a.copy(), nk, tiny, rows) == want


@pytest.mark.parametrize("compiled", [False, True])
def test_inertia_factor_and_bordered_same_bits(compiled):
    if compiled:
        pytest.importorskip("numba")
        assert ck._load() is not None
        inertia, bordered = ck._inertia_factor, ck._bordered
    else:
        inertia, bordered = _py(ck._inertia_factor), _py(ck._bordered)
    for seed, sizes, r, s in _cases():
        for singular in (False, True):
            args = _problem(seed, sizes, r, s, True, singular)
            assert _bits(inertia(*args), _ref_inertia_factor(*args)), (sizes, r, s, singular)
        rng = np.random.default_rng(seed + 2000)
        starts, diag = args[0], args[1]
        n, b = diag.shape
        blk = np.searchsorted(starts, np.arange(n), side="right") - 1
        dpos = (np.arange(n) - starts[blk]).astype(np.int64)
        kp = rng.standard_normal((n, b))
        gens = [np.ascontiguousarray(rng.standard_normal((n, 3))) for _ in range(4)]
        for k in range(0, min(4, n) + 1):
            cb = rng.standard_normal((k, n))
            got = bordered(diag, *gens, starts, dpos, kp, cb)
            assert _bits(got, _ref_bordered(diag, *gens, starts, dpos, kp, cb)), (sizes, k)


# --------------------------------------------------------------------------- the loops as they were
_REFS = """
def _ref_factor_loops(starts, diag, u, v, p, q, symmetric, lean=False):
    n, r = u.shape
    s = q.shape[1]
    bmax = diag.shape[1]
    pinv = np.zeros_like(diag)
    x = np.zeros((n, r))
    y = np.zeros((n, s))
    g = np.zeros((r, s))
    ug = np.zeros((bmax, s))
    pi = np.zeros((bmax, bmax))
    work = np.zeros((bmax, 2 * bmax))
    vt = np.zeros((bmax, r))
    sm = np.zeros((bmax, bmax))
    info = np.zeros(5)
    counts = np.zeros(3, np.int64)
    rc_min, logdet, sign, worst = np.inf, 0.0, 1.0, -1
    for k in range(len(starts) - 1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for i in range(nk):
            for c in range(s):
                t = 0.0
                for l in range(r):
                    t += u[a + i, l] * g[l, c]
                ug[i, c] = t
        ref_d, ref_c, ref_p = 0.0, 0.0, 0.0
        for i in range(nk):
            rd, rcr = 0.0, 0.0
            for j in range(nk):
                t = 0.0
                for c in range(s):
                    t += ug[i, c] * q[a + j, c]
                pi[i, j] = diag[a + i, j] - t
                rd += abs(diag[a + i, j])
                rcr += abs(t)
            ref_d = max(ref_d, rd)
            ref_c = max(ref_c, rcr)
        if symmetric:
            for i in range(nk):
                for j in range(i + 1, nk):
                    t = 0.5 * (pi[i, j] + pi[j, i])
                    pi[i, j] = t
                    pi[j, i] = t
        for i in range(nk):
            rp = 0.0
            for j in range(nk):
                rp += abs(pi[i, j])
            ref_p = max(ref_p, rp)
        ref = max(ref_d, max(ref_c, ref_p))
        # Gauss-Jordan inverse with partial pivoting: work = [pi | I]
        for i in range(nk):
            for j in range(nk):
                work[i, j] = pi[i, j]
                work[i, nk + j] = 1.0 if i == j else 0.0
        ok = True
        for col in range(nk):
            best, piv = -1.0, col
            for i in range(col, nk):
                if abs(work[i, col]) > best:
                    best, piv = abs(work[i, col]), i
            if not (best > 0.0) or not np.isfinite(best):
                ok = False
                break
            if piv != col:
                for j in range(2 * nk):
                    t = work[col, j]
                    work[col, j] = work[piv, j]
                    work[piv, j] = t
                if not lean:
                    sign = -sign
            dv = work[col, col]
            if not lean:
                if dv < 0.0:
                    sign = -sign
                logdet += np.log(abs(dv))
            for j in range(2 * nk):
                work[col, j] /= dv
            for i in range(nk):
                if i != col:
                    f = work[i, col]
                    if f != 0.0:
                        for j in range(2 * nk):
                            work[i, j] -= f * work[col, j]
        inv_norm = 0.0
        for i in range(nk):
            ri = 0.0
            for j in range(nk):
                t = work[i, nk + j]
                pinv[a + i, j] = t
                ri += abs(t)
            inv_norm = max(inv_norm, ri)
        if not ok or not np.isfinite(inv_norm):
            info[0], info[1], info[2], info[3], info[4] = 0.0, -np.inf, 0.0, k, 1.0
            return pinv, x, y, info, counts
        rc = 1.0 / (inv_norm * ref) if ref > 0.0 else 0.0
        if rc < rc_min:
            rc_min, worst = rc, k
        if symmetric and lean:
            for i in range(nk):
                for j in range(nk):
                    sm[i, j] = pi[i, j]
            cp, cn, cz = _ref_inertia_small(sm, nk, 1e-14 * nk * ref)
            counts[0] += cp
            counts[1] += cn
            counts[2] += cz
        elif symmetric:
            if nk == 1:
                ev = np.array([pi[0, 0]])
            else:
                ev = np.linalg.eigvalsh(pi[:nk, :nk].copy())
            tiny = 1e-14 * nk * ref
            for i in range(nk):
                if ev[i] > tiny:
                    counts[0] += 1
                elif ev[i] < -tiny:
                    counts[1] += 1
                else:
                    counts[2] += 1
        for i in range(nk):
            for l in range(r):
                t = 0.0
                for c in range(s):
                    t += q[a + i, c] * g[l, c]
                vt[i, l] = v[a + i, l] - t
        # x_k = pinvᵀ vt ; y_k = pinv (p_k − ug) ; g += vtᵀ y_k
        for i in range(nk):
            for l in range(r):
                t = 0.0
                for j in range(nk):
                    t += pinv[a + j, i] * vt[j, l]
                x[a + i, l] = t
            for c in range(s):
                t = 0.0
                for j in range(nk):
                    t += pinv[a + i, j] * (p[a + j, c] - ug[j, c])
                y[a + i, c] = t
        for l in range(r):
            for c in range(s):
                t = 0.0
                for i in range(nk):
                    t += vt[i, l] * y[a + i, c]
                g[l, c] += t
    info[0], info[1], info[2], info[3], info[4] = rc_min, logdet, sign, worst, 0.0
    return pinv, x, y, info, counts


def _ref_solve_loops(starts, pinv, u, x, y, q, b):
    n, nc = b.shape
    r, s = u.shape[1], q.shape[1]
    bmax = pinv.shape[1]
    z = np.empty((n, nc))
    zk = np.empty((bmax, nc))
    acc = np.zeros((r, nc))
    nb = len(starts) - 1
    for k in range(nb):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for i in range(nk):
            for c in range(nc):
                t = b[a + i, c]
                for l in range(r):
                    t -= u[a + i, l] * acc[l, c]
                zk[i, c] = t
        for l in range(r):
            for c in range(nc):
                t = 0.0
                for i in range(nk):
                    t += x[a + i, l] * zk[i, c]
                acc[l, c] += t
        for i in range(nk):
            for c in range(nc):
                t = 0.0
                for j in range(nk):
                    t += pinv[a + i, j] * zk[j, c]
                z[a + i, c] = t
    out = np.empty((n, nc))
    acc2 = np.zeros((s, nc))
    for k in range(nb - 1, -1, -1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for i in range(nk):
            for c in range(nc):
                t = z[a + i, c]
                for l in range(s):
                    t -= y[a + i, l] * acc2[l, c]
                out[a + i, c] = t
        for l in range(s):
            for c in range(nc):
                t = 0.0
                for i in range(nk):
                    t += q[a + i, l] * out[a + i, c]
                acc2[l, c] += t
    return out


def _ref_matvec_loops(starts, diag, u, v, p, q, x):
    n, nc = x.shape
    r, s = u.shape[1], q.shape[1]
    y = np.zeros((n, nc))
    acc = np.zeros((r, nc))
    nb = len(starts) - 1
    for k in range(nb):
        a, e = starts[k], starts[k + 1]
        for i in range(a, e):
            for c in range(nc):
                t = 0.0
                for j in range(a, e):
                    t += diag[i, j - a] * x[j, c]
                for l in range(r):
                    t += u[i, l] * acc[l, c]
                y[i, c] = t
        for l in range(r):
            for c in range(nc):
                t = 0.0
                for i in range(a, e):
                    t += v[i, l] * x[i, c]
                acc[l, c] += t
    acc2 = np.zeros((s, nc))
    for k in range(nb - 1, -1, -1):
        a, e = starts[k], starts[k + 1]
        for i in range(a, e):
            for c in range(nc):
                t = 0.0
                for l in range(s):
                    t += p[i, l] * acc2[l, c]
                y[i, c] += t
        for l in range(s):
            for c in range(nc):
                t = 0.0
                for i in range(a, e):
                    t += q[i, l] * x[i, c]
                acc2[l, c] += t
    return y


def _ref_inertia_small(a, nk, tiny):
    alpha = (1.0 + math.sqrt(17.0)) / 8.0
    alive = np.ones(nk, np.bool_)
    npos, nneg, nzero = 0, 0, 0
    left = nk
    while left > 0:
        gd, idd = -1.0, -1
        go, io, jo = 0.0, -1, -1
        for i in range(nk):
            if not alive[i]:
                continue
            if abs(a[i, i]) > gd:
                gd, idd = abs(a[i, i]), i
            for j in range(i + 1, nk):
                if alive[j] and abs(a[i, j]) > go:
                    go, io, jo = abs(a[i, j]), i, j
        if gd >= alpha * go or left == 1:
            piv = a[idd, idd]
            if piv > tiny:
                npos += 1
            elif piv < -tiny:
                nneg += 1
            else:
                nzero += 1
            alive[idd] = False
            left -= 1
            if piv != 0.0:
                for i in range(nk):
                    if alive[i]:
                        f = a[i, idd] / piv
                        for j in range(nk):
                            if alive[j]:
                                a[i, j] -= f * a[idd, j]
        else:
            p11, p12, p22 = a[io, io], a[io, jo], a[jo, jo]
            det = p11 * p22 - p12 * p12
            if det < 0.0:
                npos += 1
                nneg += 1
            elif det > 0.0:
                if p11 + p22 > 0.0:
                    npos += 2
                else:
                    nneg += 2
            else:
                nzero += 1
                if p11 + p22 > 0.0:
                    npos += 1
                else:
                    nneg += 1
            alive[io] = False
            alive[jo] = False
            left -= 2
            if det != 0.0:
                i11, i12, i22 = p22 / det, -p12 / det, p11 / det
                for i in range(nk):
                    if alive[i]:
                        c1 = a[i, io] * i11 + a[i, jo] * i12
                        c2 = a[i, io] * i12 + a[i, jo] * i22
                        for j in range(nk):
                            if alive[j]:
                                a[i, j] -= c1 * a[io, j] + c2 * a[jo, j]
    return npos, nneg, nzero


def _ref_inertia_factor(starts, diag, u, v, p, q):
    n, r = u.shape
    s = q.shape[1]
    bmax = diag.shape[1]
    g = np.zeros((r, s))
    ug = np.zeros((bmax, s))
    pi = np.zeros((bmax, bmax))
    work = np.zeros((bmax, 2 * bmax))
    vt = np.zeros((bmax, r))
    sm = np.zeros((bmax, bmax))
    pk = np.zeros((bmax, bmax))
    yk = np.zeros((bmax, s))
    rc_min = np.inf
    npos, nneg, nzero = 0, 0, 0
    for k in range(len(starts) - 1):
        a, e = starts[k], starts[k + 1]
        nk = e - a
        for i in range(nk):
            for c in range(s):
                t = 0.0
                for l in range(r):
                    t += u[a + i, l] * g[l, c]
                ug[i, c] = t
        ref_d, ref_c, ref_p = 0.0, 0.0, 0.0
        for i in range(nk):
            rd, rcr = 0.0, 0.0
            for j in range(nk):
                t = 0.0
                for c in range(s):
                    t += ug[i, c] * q[a + j, c]
                pi[i, j] = diag[a + i, j] - t
                rd += abs(diag[a + i, j])
                rcr += abs(t)
            ref_d = max(ref_d, rd)
            ref_c = max(ref_c, rcr)
        for i in range(nk):
            for j in range(i + 1, nk):
                t = 0.5 * (pi[i, j] + pi[j, i])
                pi[i, j] = t
                pi[j, i] = t
        for i in range(nk):
            rp = 0.0
            for j in range(nk):
                rp += abs(pi[i, j])
            ref_p = max(ref_p, rp)
        ref = max(ref_d, max(ref_c, ref_p))
        # Gauss-Jordan inverse with partial pivoting: work = [pi | I]
        for i in range(nk):
            for j in range(nk):
                work[i, j] = pi[i, j]
                work[i, nk + j] = 1.0 if i == j else 0.0
        ok = True
        for col in range(nk):
            best, piv = -1.0, col
            for i in range(col, nk):
                if abs(work[i, col]) > best:
                    best, piv = abs(work[i, col]), i
            if not (best > 0.0) or not np.isfinite(best):
                ok = False
                break
            if piv != col:
                for j in range(2 * nk):
                    t = work[col, j]
                    work[col, j] = work[piv, j]
                    work[piv, j] = t
            dv = work[col, col]
            for j in range(2 * nk):
                work[col, j] /= dv
            for i in range(nk):
                if i != col:
                    f = work[i, col]
                    if f != 0.0:
                        for j in range(2 * nk):
                            work[i, j] -= f * work[col, j]
        inv_norm = 0.0
        for i in range(nk):
            ri = 0.0
            for j in range(nk):
                t = work[i, nk + j]
                pk[i, j] = t
                ri += abs(t)
            inv_norm = max(inv_norm, ri)
        if not ok or not np.isfinite(inv_norm):
            return 0.0, True, npos, nneg, nzero
        rc = 1.0 / (inv_norm * ref) if ref > 0.0 else 0.0
        if rc < rc_min:
            rc_min = rc
        for i in range(nk):
            for j in range(nk):
                sm[i, j] = pi[i, j]
        cp, cn, cz = _ref_inertia_small(sm, nk, 1e-14 * nk * ref)
        npos += cp
        nneg += cn
        nzero += cz
        for i in range(nk):
            for l in range(r):
                t = 0.0
                for c in range(s):
                    t += q[a + i, c] * g[l, c]
                vt[i, l] = v[a + i, l] - t
        for i in range(nk):
            for c in range(s):
                t = 0.0
                for j in range(nk):
                    t += pk[i, j] * (p[a + j, c] - ug[j, c])
                yk[i, c] = t
        for l in range(r):
            for c in range(s):
                t = 0.0
                for i in range(nk):
                    t += vt[i, l] * yk[i, c]
                g[l, c] += t
    return rc_min, False, npos, nneg, nzero


def _ref_bordered(wd, wu, wv, wp, wq, starts, dpos, kp, cb):
    n, b = wd.shape
    k = cb.shape[0]
    r0 = wu.shape[1]
    s0_ = wq.shape[1]
    nb = starts.shape[0] - 1
    jn = np.zeros(n)
    for c in range(k):
        for i in range(n):
            jn[i] += cb[c, i] * cb[c, i]
    kref_sum = 0.0
    npos = 0
    for i in range(n):
        t = abs(wd[i, dpos[i]])
        if t != 0.0:
            kref_sum += t
            npos += 1
    kref = kref_sum / npos if npos else 1.0
    comp = 0.0
    for kb in range(nb):
        a0, a1 = starts[kb], starts[kb + 1]
        for c in range(k):
            for i in range(a0, a1):
                t = 0.0
                for j in range(a0, a1):
                    t += kp[i, j - a0] * cb[c, j]
                comp += cb[c, i] * t
    if k == 0:
        rho = 0.0
    elif comp > 0.0 and math.isfinite(comp):
        rho = RHO_FACTOR * k / comp
    else:
        mj = 0.0
        for i in range(n):
            mj += jn[i]
        rho = RHO_FACTOR * kref / max(mj / max(n, 1), 1e-300)
    s = np.empty(n)
    for i in range(n):
        dw = abs(wd[i, dpos[i]]) + rho * jn[i]
        s[i] = 1.0 / math.sqrt(dw) if dw > 0.0 else 1.0 / math.sqrt(kref)
    bsz = max(b, k)
    bd = np.zeros((n + k, bsz))
    for kb in range(nb):
        a0, a1 = starts[kb], starts[kb + 1]
        for i in range(a0, a1):
            for j in range(a0, a1):
                t = 0.0
                for c in range(k):
                    t += cb[c, i] * cb[c, j]
                bd[i, j - a0] = (wd[i, j - a0] + rho * t) * s[i] * s[j]
    bu = np.zeros((n + k, r0 + k))
    bv = np.zeros((n + k, r0 + k))
    bp = np.zeros((n + k, s0_ + k))
    bq = np.zeros((n + k, s0_ + k))
    for i in range(n):
        si = s[i]
        for c in range(r0):
            bu[i, c] = wu[i, c] * si
            bv[i, c] = wv[i, c] * si
        for c in range(s0_):
            bp[i, c] = wp[i, c] * si
            bq[i, c] = wq[i, c] * si
        for c in range(k):
            js = si * cb[c, i]
            bu[i, r0 + c] = rho * js
            bv[i, r0 + c] = js
            bp[i, s0_ + c] = js
            bq[i, s0_ + c] = rho * js
    for c in range(k):
        bu[n + c, r0 + c] = 1.0
        bq[n + c, s0_ + c] = 1.0
    if k > 0:
        bst = np.empty(nb + 2, np.int64)
        bst[: nb + 1] = starts
        bst[nb + 1] = n + k
    else:
        bst = starts.copy()
    return bst, bd, bu, bv, bp, bq, s, rho
"""

exec(compile(_REFS, __file__, "exec"))
