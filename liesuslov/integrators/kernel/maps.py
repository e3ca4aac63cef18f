"""Small linear algebra and the chart maps on matrices (Padé exp, Cayley by LU, dexp⁻¹ series) and the so(3)
closed forms' scalar branches, compiled."""

from __future__ import annotations

import math

import numpy as np

from ... import groups
from .common import _cayley_coefficients, _dexp3_series, _jit


# ====================================================================================== small linear algebra
def _pade_table() -> tuple[np.ndarray, np.ndarray]:
    """Bounds theta_m (Higham 2005, Table 2.3, m = 3, 5, 7, 9, 13) and the [m/m] Padé numerator coefficients."""
    thetas = np.array([t for _, t in groups._PADE_THETA])
    coef = np.zeros((5, 14))
    for r, (m, _) in enumerate(groups._PADE_THETA):
        coef[r, :m + 1] = groups._pade_coefficients(m)
    return thetas, coef


_PADE_THETA, _PADE_COEF = _pade_table()
# Beyond this |X|_2 bound the Cayley solve gets a polar step; beyond the chart's domain it returns NaN
_CAYLEY_POLAR = 2.0
_CAYLEY_MAX = groups._CAYLEY_LIMIT


@_jit
def _mm(A, B, C):
    """C = A @ B (C distinct from A and B)."""
    n = A.shape[0]
    p_ = A.shape[1]
    w = B.shape[1]
    for i in range(n):
        for j in range(w):
            C[i, j] = 0.0
        for p in range(p_):
            a = A[i, p]
            if a != 0.0:
                for j in range(w):
                    C[i, j] += a * B[p, j]


@_jit
def _set_eye(out, d):
    n = out.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.0
        out[i, i] = d


@_jit
def _axpy(out, a, A):
    n = out.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] += a * A[i, j]


@_jit
def _solve(A, X):
    """Solve A Y = X in place by LU with partial pivoting: A (n, n) destroyed, X (n, r) becomes Y."""
    n = A.shape[0]
    r = X.shape[1]
    for c in range(n):
        p = c
        big = abs(A[c, c])
        for i in range(c + 1, n):
            v = abs(A[i, c])
            if v > big:
                big = v
                p = i
        if p != c:
            for j in range(n):
                t = A[c, j]
                A[c, j] = A[p, j]
                A[p, j] = t
            for j in range(r):
                t = X[c, j]
                X[c, j] = X[p, j]
                X[p, j] = t
        d = A[c, c]
        for i in range(c + 1, n):
            f = A[i, c] / d
            if f != 0.0:
                for j in range(c + 1, n):
                    A[i, j] -= f * A[c, j]
                for j in range(r):
                    X[i, j] -= f * X[c, j]
    for i in range(n - 1, -1, -1):
        for j in range(r):
            acc = X[i, j]
            for p in range(i + 1, n):
                acc -= A[i, p] * X[p, j]
            X[i, j] = acc / A[i, i]


@_jit
def _polar_step(R, T, P):
    """R <- R (3 I - R^T R) / 2: one Newton–Schulz step toward the nearest orthogonal matrix (T, P scratch)."""
    n = R.shape[0]
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for p in range(n):
                acc += R[p, i] * R[p, j]
            T[i, j] = -0.5 * acc
        T[i, i] += 1.5
    _mm(R, T, P)
    for i in range(n):
        for j in range(n):
            R[i, j] = P[i, j]


@_jit
def _bracket(skew, A, B, C):
    """C = [A, B] = A B - B A (skew A, B: upper triangle of A B - (A B)^T, exactly skew)."""
    n = A.shape[0]
    if skew:
        for i in range(n):
            C[i, i] = 0.0
            for j in range(i + 1, n):
                acc = 0.0
                for p in range(n):
                    acc += A[i, p] * B[p, j] - A[j, p] * B[p, i]
                C[i, j] = acc
                C[j, i] = -acc
        return
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for p in range(n):
                acc += A[i, p] * B[p, j] - B[i, p] * A[p, j]
            C[i, j] = acc


# ---------------------------------------------------------------------- so(3) closed forms (scalar branches)
@_jit
def _rodrigues(t2):
    """(cos θ, sin θ/θ, (1 - cos θ)/θ²) from θ², by the half angle: the scalar branch of ``groups._rodrigues``."""
    x2 = 0.25 * t2
    x = math.sqrt(x2)
    if x < groups._SINC_TAYLOR:
        s = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0)
    else:
        s = math.sin(x) / x
    b = 0.5 * s * s
    return 1.0 - b * t2, s * math.cos(x), b


@_jit
def _dexp3_coefficient(t2):
    """(1 - (θ/2) cot(θ/2)) / θ²: the scalar branch of ``groups._dexp3_coefficient``."""
    if t2 < groups._DEXP3_TAYLOR ** 2:
        return _dexp3_series(t2)
    x = 0.5 * math.sqrt(t2)
    return (1.0 - x * math.cos(x) / math.sin(x)) / t2


@_jit
def _so3_coef(chart, t2):
    """(c, a, b) with phi(hat w) = c I + a hat(w) + b w w^T."""
    if chart == 0:
        return _rodrigues(t2)
    return _cayley_coefficients(t2)


# ---------------------------------------------------------------------- matrix charts (dense and low-rank)
@_jit
def _pade(X, r, W):
    """Odd and even parts U -> W[5], V -> W[6] of the Padé numerator of degree (3, 5, 7, 9, 13)[r]."""
    b = _PADE_COEF[r]
    X2, X4, X6, X8, T, U, V = W[0], W[1], W[2], W[3], W[4], W[5], W[6]
    _mm(X, X, X2)
    if r == 0:
        _set_eye(T, b[1])
        _axpy(T, b[3], X2)
        _set_eye(V, b[0])
        _axpy(V, b[2], X2)
    elif r < 4:
        _mm(X2, X2, X4)
        if r >= 2:
            _mm(X4, X2, X6)
        if r == 3:
            _mm(X6, X2, X8)
        _set_eye(T, b[1])
        _axpy(T, b[3], X2)
        _axpy(T, b[5], X4)
        _set_eye(V, b[0])
        _axpy(V, b[2], X2)
        _axpy(V, b[4], X4)
        if r >= 2:
            _axpy(T, b[7], X6)
            _axpy(V, b[6], X6)
        if r == 3:
            _axpy(T, b[9], X8)
            _axpy(V, b[8], X8)
    else:  # degree 13, Higham's form with 6 products
        _mm(X2, X2, X4)
        _mm(X4, X2, X6)
        _set_eye(T, 0.0)
        _axpy(T, b[13], X6)
        _axpy(T, b[11], X4)
        _axpy(T, b[9], X2)
        _mm(X6, T, X8)
        _set_eye(T, b[1])
        _axpy(T, 1.0, X8)
        _axpy(T, b[7], X6)
        _axpy(T, b[5], X4)
        _axpy(T, b[3], X2)
        _mm(X, T, U)
        _set_eye(T, 0.0)
        _axpy(T, b[12], X6)
        _axpy(T, b[10], X4)
        _axpy(T, b[8], X2)
        _mm(X6, T, V)
        _axpy(V, b[6], X6)
        _axpy(V, b[4], X4)
        _axpy(V, b[2], X2)
        for i in range(X.shape[0]):
            V[i, i] += b[0]
        return
    _mm(X, T, U)


@_jit
def _expm(skew, X, out, W):
    """out = exp(X): scaling and squaring with Padé (Higham 2005); skew X: the 2-norm bound |X|_F/√2 and a
    Newton–Schulz polish after the squarings (orthogonal to rounding); general X: the 1-norm. W[0..8]."""
    n = X.shape[0]
    if skew:
        acc = 0.0
        for i in range(n):
            for j in range(n):
                acc += X[i, j] * X[i, j]
        nrm = math.sqrt(0.5 * acc)
    else:
        nrm = 0.0
        for j in range(n):
            acc = 0.0
            for i in range(n):
                acc += abs(X[i, j])
            if acc > nrm or acc != acc:
                nrm = acc
    r = 4
    for q in range(4):
        if nrm <= _PADE_THETA[q]:
            r = q
            break
    s = 0
    if r == 4 and nrm == nrm and nrm < np.inf:
        e = math.frexp(nrm / _PADE_THETA[4])[1]
        s = e if e > 0 else 0
    Xs = W[7]
    sc = 2.0 ** (-s)
    for i in range(n):
        for j in range(n):
            Xs[i, j] = X[i, j] * sc
    _pade(Xs, r, W)
    A, U, V = W[4], W[5], W[6]
    for i in range(n):
        for j in range(n):
            A[i, j] = V[i, j] - U[i, j]
            out[i, j] = V[i, j] + U[i, j]
    _solve(A, out)
    T = W[8]
    for q in range(s):
        _mm(out, out, T)
        for i in range(n):
            for j in range(n):
                out[i, j] = T[i, j]
        if skew and (q % 8 == 7 or q == s - 1):
            _polar_step(out, W[0], W[1])


@_jit
def _mat_phi(chart, skew, X, out, W):
    """out = phi(X) for an (n, n) matrix: exp or Cayley ``(I - X/2)^{-1} (I + X/2)``; W[0..9] scratch."""
    n = X.shape[0]
    if chart == 0:
        _expm(skew, X, out, W)
        return
    Mt = W[9]
    acc = 0.0
    for i in range(n):
        for j in range(n):
            Mt[i, j] = -0.5 * X[i, j]
            out[i, j] = 0.5 * X[i, j]
            acc += X[i, j] * X[i, j]
        Mt[i, i] += 1.0
        out[i, i] += 1.0
    nrm = math.sqrt(0.5 * acc)
    if skew and nrm > _CAYLEY_MAX:
        for i in range(n):
            for j in range(n):
                out[i, j] = np.nan
        return
    _solve(Mt, out)
    if skew and nrm > _CAYLEY_POLAR:
        _polar_step(out, W[0], W[1])


@_jit
def _mat_act(chart, skew, X, sign, v, out, W, vb):
    """out = phi(sign X) v for an (n, n) matrix X and v (n,); W[0..11], vb (n, 1) scratch.

    Skew X with small ``|X|_2``: the Taylor series of the action (exp) or one solve with a vector (Cayley);
    otherwise the matrix phi(sign X), then the product.
    """
    n = X.shape[0]
    T = W[9]
    acc = 0.0
    for i in range(n):
        for j in range(n):
            acc += X[i, j] * X[i, j]
    nu = math.sqrt(0.5 * acc)  # bounds |X|_2 for skew X
    if skew and chart == 0 and nu <= 1.0:
        t = W[11][0]
        u = W[11][1]
        for i in range(n):
            out[i] = v[i]
            t[i] = v[i]
        bound = 1.0
        for j in range(1, 25):
            c = sign / j
            for i in range(n):
                acc = 0.0
                for p in range(n):
                    acc += X[i, p] * t[p]
                u[i] = c * acc
            for i in range(n):
                t[i] = u[i]
                out[i] += u[i]
            bound = bound * nu / j
            if not bound > 1.4e-17:
                break
        return
    if skew and chart == 1 and nu <= _CAYLEY_POLAR:  # (I - sX/2) y = v + sX v / 2
        hh = 0.5 * sign
        for i in range(n):
            acc = 0.0
            for j in range(n):
                T[i, j] = -hh * X[i, j]
                acc += X[i, j] * v[j]
            T[i, i] += 1.0
            vb[i, 0] = v[i] + hh * acc
        _solve(T, vb)
        for i in range(n):
            out[i] = vb[i, 0]
        return
    Sg = W[8]
    for i in range(n):
        for j in range(n):
            Sg[i, j] = sign * X[i, j]
    R = W[10]
    _mat_phi(chart, skew, Sg, R, W)
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += R[i, j] * v[j]
        out[i] = acc


@_jit
def _mat_dinv(chart, skew, Th, A, out, W, bern):
    """out = dphi^{-1}_{-Th}(A), right-trivialised: the truncated Bernoulli series (exp), or the exact
    ``(I + Th/2) A (I - Th/2)`` (Cayley); W[0..2] scratch."""
    n = Th.shape[0]
    if chart == 0:
        ad, P = W[0], W[1]
        for i in range(n):
            for j in range(n):
                ad[i, j] = A[i, j]
                out[i, j] = A[i, j]
        k_ad = 0
        for t in range(bern.shape[0]):
            kk = int(bern[t, 0])
            c = bern[t, 1]
            while k_ad < kk:
                _bracket(skew, Th, ad, P)
                for i in range(n):
                    for j in range(n):
                        ad[i, j] = P[i, j]
                k_ad += 1
            _axpy(out, -c if kk == 1 else c, ad)
        return
    M, P = W[0], W[1]
    if skew:
        # Th, A skew: with P = Th A, P^T = A Th and P Th = Th A Th is skew, so the result is
        # A + (P - P^T)/2 - (P Th)/4, skew by construction: its upper triangle only (n^2 (n - 1)/2 products
        # instead of a second n^3). Pt = A Th is formed, not P: _mm skips A's zero entries (Omega of a
        # Fedorov–Kozlov model has 2(n - 1) of n^2), and its products and their order are P's (bitwise).
        Pt = P
        _mm(A, Th, Pt)
        for i in range(n):
            out[i, i] = 0.0
            for j in range(i + 1, n):
                acc = 0.0
                for p in range(n):
                    acc += Pt[p, i] * Th[p, j]
                v = A[i, j] + 0.5 * (Pt[j, i] - Pt[i, j]) - 0.25 * acc
                out[i, j] = v
                out[j, i] = -v
        return
    _mm(Th, A, P)
    for i in range(n):
        for j in range(n):
            M[i, j] = A[i, j] + 0.5 * P[i, j]
    _mm(M, Th, P)
    for i in range(n):
        for j in range(n):
            out[i, j] = M[i, j] - 0.5 * P[i, j]
