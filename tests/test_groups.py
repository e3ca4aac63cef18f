"""Group maps: exponential and Cayley charts, rank-2 closed forms, inverse derivatives.

Oracles, independent of the code under test:
- an extended-precision (80-bit ``longdouble``) Taylor scaling-and-squaring exponential — accurate
  to ~1e-18, where ``scipy.linalg.expm`` 1.17 errs by up to ~1e-12 on skew matrices;
- the exact derivative of exp from the block matrix ``exp([[Θ, V], [0, Θ]])`` (upper-right block)
  in the same precision, checked once against ``scipy.linalg.expm_frechet`` and against a
  Richardson-extrapolated central difference;
- the complex step (exact to rounding) for the rational Cayley map;
- a small RKMK stepper written here, whose observed orders pin the side convention of dexp⁻¹ and
  the number of series terms an order-p method needs.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from liesuslov import groups as G

SIZES = range(2, 9)
SPECIAL_ANGLES = (0.0, 1e-300, 1e-12, 1e-8, 1.99e-4, 2.01e-4, 1e-3, 0.5, np.pi - 1e-6, np.pi, np.pi + 1e-3,
                  2.0 * np.pi, 5.0, 20.0)
EPS = np.finfo(float).eps


# ----------------------------------------------------------------------------- helpers and oracles
def _skew(rng: np.random.Generator, shape: tuple[int, ...], n: int, scale: float = 1.0) -> np.ndarray:
    A = rng.standard_normal(shape + (n, n)) * scale
    return 0.5 * (A - np.swapaxes(A, -1, -2))


def _hat(w: np.ndarray) -> np.ndarray:
    w = np.asarray(w, dtype=float)
    X = np.zeros(w.shape[:-1] + (3, 3))
    X[..., 2, 1], X[..., 0, 2], X[..., 1, 0] = w[..., 0], w[..., 1], w[..., 2]
    return X - np.swapaxes(X, -1, -2)


def _wedge(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    P = a[..., :, None] * b[..., None, :]
    return P - np.swapaxes(P, -1, -2)


def _skew_with_angle(rng: np.random.Generator, n: int, theta: float) -> np.ndarray:
    """A skew matrix whose largest rotation angle (spectral norm) is ``theta``."""
    if n == 3:
        u = rng.standard_normal(3)
        return _hat(theta * u / np.linalg.norm(u))
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    B = np.zeros((n, n))
    for j, i in enumerate(range(0, n - 1, 2)):
        B[i + 1, i] = theta * 0.7**j
    X = Q @ (B - B.T) @ Q.T
    return 0.5 * (X - X.T)


def _expm_ld(X: np.ndarray) -> np.ndarray:
    """exp(X) in 80-bit extended precision: Taylor (30 terms) of X/2^s with |X/2^s|_1 <= 1/4, squared back."""
    X = np.asarray(X, dtype=np.longdouble)
    nrm = float(np.abs(X).sum(-2).max()) if X.size else 0.0
    s = max(0, int(np.ceil(np.log2(max(nrm, 1e-300) / 0.25))))
    Xs = X / np.longdouble(2.0) ** s
    R = np.broadcast_to(np.eye(X.shape[-1], dtype=np.longdouble), X.shape).copy()
    T = R.copy()
    for k in range(1, 30):
        T = np.einsum("...ij,...jk->...ik", T, Xs) / k
        R = R + T
    for _ in range(s):
        R = np.einsum("...ij,...jk->...ik", R, R)
    return R


def _frechet_ld(Theta: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``exp(Θ)`` and ``L = d/dt exp(Θ + tV)|_0`` from ``exp([[Θ, V], [0, Θ]])`` in extended precision."""
    n = Theta.shape[-1]
    Z = np.zeros(np.broadcast_shapes(Theta.shape, V.shape)[:-2] + (2 * n, 2 * n))
    Z[..., :n, :n] = Theta
    Z[..., n:, n:] = Theta
    Z[..., :n, n:] = V
    E = _expm_ld(Z)
    return E[..., :n, :n], E[..., :n, n:]


def _trivialised(Theta: np.ndarray, V: np.ndarray, side: str) -> np.ndarray:
    """The velocity a chart at Θ moving with Θ' = V produces: ``L e^{−Θ}`` (left) or ``e^{−Θ} L`` (right)."""
    L = _frechet_ld(Theta, V)[1]
    Einv = _expm_ld(-np.asarray(Theta))
    prod = np.einsum("...ij,...jk->...ik", *((L, Einv) if side == "left" else (Einv, L)))
    return np.asarray(prod, dtype=float)


def _orth_err(R: np.ndarray) -> float:
    return float(np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(R.shape[-1])).max())


def _rel(A, B) -> float:
    return float(np.abs(np.asarray(A, dtype=np.longdouble) - B).max() / max(1.0, float(np.abs(B).max())))


# ----------------------------------------------------------------------------- exponential
@pytest.mark.parametrize("n", SIZES)
def test_expm_skew_random_batches_match_extended_precision(n):
    rng = np.random.default_rng(n)
    for scale in (1e-8, 1e-3, 0.1, 1.0, 4.0):
        X = _skew(rng, (3, 4), n, scale)
        R = G.expm_skew(X)
        assert R.shape == X.shape
        theta = max(1.0, float(np.linalg.norm(X, 2, axis=(-2, -1)).max()))
        assert _rel(R, _expm_ld(X)) < 4 * EPS * theta, (n, scale)
        # scipy is a cross-check only: it is itself ~1e-13 off on these inputs
        assert np.allclose(R, scipy.linalg.expm(X), rtol=0, atol=1e-11 * theta)
        # a single matrix takes the same path as a batch
        assert np.abs(G.expm_skew(X[1, 2]) - R[1, 2]).max() < 4 * EPS * theta


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("theta", SPECIAL_ANGLES)
def test_expm_skew_special_angles(n, theta):
    X = _skew_with_angle(np.random.default_rng(7), n, theta)
    R = G.expm_skew(X)
    assert np.all(np.isfinite(R))
    assert _rel(R, _expm_ld(X)) < 4 * EPS * max(1.0, theta)
    assert _orth_err(R) < 2e-15 * max(1.0, theta)
    assert abs(np.linalg.det(R) - 1.0) < 2e-15 * max(1.0, theta)


@pytest.mark.parametrize("theta", (1e-300, 1e-12, 1e-8, 1e-5, 1.9999e-4, 2.0001e-4))
def test_expm_skew_tiny_angles_are_relatively_exact(theta):
    """n = 2, 3: the small off-diagonal entries keep full relative accuracy."""
    rng = np.random.default_rng(1)
    for n in (2, 3):
        X = _skew_with_angle(rng, n, theta)
        exact = np.asarray(_expm_ld(X), dtype=float)  # no scaling here: entrywise relative accuracy ~1e-19
        R = G.expm_skew(X)
        off = ~np.eye(n, dtype=bool)
        assert np.all(np.abs(R - exact)[off] <= 4 * EPS * np.abs(exact)[off] + 1e-320)
        assert np.abs(R - exact)[~off].max() <= EPS


def test_expm_skew_n3_at_pi_is_half_turn():
    u = np.array([1.0, -2.0, 0.5]) / np.sqrt(5.25)
    R = G.expm_skew(_hat(np.pi * u))
    assert np.abs(R - (2 * np.outer(u, u) - np.eye(3))).max() < 4 * EPS


def test_expm_skew_n1_and_mixed_scales_in_one_batch():
    assert G.expm_skew(np.zeros((4, 1, 1))).tolist() == [[[1.0]]] * 4
    rng = np.random.default_rng(3)
    X = np.stack([_skew_with_angle(rng, 5, t) for t in (1e-9, 0.3, 3.0, 40.0)])  # per-matrix scaling
    R = G.expm_skew(X)
    for Xi, Ri in zip(X, R, strict=True):
        theta = max(1.0, float(np.linalg.norm(Xi, 2)))
        assert _rel(Ri, _expm_ld(Xi)) < 4 * EPS * theta
        assert _orth_err(Ri) < 2e-15 * theta


@pytest.mark.parametrize("n", (2, 3, 4, 6))
@pytest.mark.parametrize("kind", ("se", "random"))
def test_expm_general_matrices(n, kind):
    rng = np.random.default_rng(10 * n)
    for scale in (1e-6, 0.3, 1.0, 3.0):
        A = rng.standard_normal((5, n, n)) * scale
        if kind == "se":  # homogeneous representation of se(n−1): [[Ω, v], [0, 0]]
            A[..., :-1, :-1] -= np.swapaxes(A[..., :-1, :-1], -1, -2)
            A[..., -1, :] = 0.0
        ref = _expm_ld(A)
        assert _rel(G.expm(A), ref) < 2e-15 * max(1.0, float(np.abs(ref).max()))
        assert _rel(G.expm(A[0]), ref[0]) < 2e-15 * max(1.0, float(np.abs(ref).max()))


def test_expm_so3_vector_forms():
    rng = np.random.default_rng(4)
    w = rng.standard_normal((6, 3)) * np.array([[1e-9], [1e-4], [0.5], [np.pi], [4.0], [0.0]])
    v = rng.standard_normal((6, 3))
    R = G.expm_skew(_hat(w))
    assert np.abs(G.expm_so3(w) - R).max() < 4 * EPS
    assert np.abs(G.expm_so3_apply(w, v) - (R @ v[..., None])[..., 0]).max() < 8 * EPS
    # broadcasting: one vector, many rotations
    assert np.abs(G.expm_so3_apply(w, v[0]) - (R @ v[0])).max() < 8 * EPS


def test_so3_single_element_paths_match_batched():
    """n = 3 functions run on Python floats for one element and on arrays for a batch: same results,
    and vectors broadcast against matrices either way."""
    rng = np.random.default_rng(15)
    w = rng.standard_normal((9, 3)) * np.array([0, 1e-9, 1e-4, 0.05, 0.2, 1, np.pi, 5, 30])[:, None]
    v = rng.standard_normal((9, 3))
    X, V = _hat(w), _hat(v)
    pairs = [(G.expm_skew, (X,)), (G.cayley_skew, (X,)), (G.expm_so3, (w,)), (G.cayley_so3, (w,)),
             (G.expm_skew_apply, (X, v)), (G.cayley_skew_apply, (X, v)), (G.expm_so3_apply, (w, v)),
             (G.cayley_so3_apply, (w, v)), (G.dexpinv_so3, (w, v)), (G.dcayinv_so3, (w, v)),
             (G.dexpinv_skew3, (X, V)), (G.dexpinv_so3, (w, v, "left")), (G.dexpinv_skew3, (X, V, "left")),
             (G.dcayinv_skew3, (X, V)), (G.dcayinv_skew3, (X, V, "left"))]
    for f, args in pairs:
        batch = f(*args)
        for i in range(9):
            single = f(*[x[i] if isinstance(x, np.ndarray) else x for x in args])
            assert single.shape == batch.shape[1:]
            tol = 4 * EPS * max(1.0, np.abs(batch[i]).max())
            assert np.abs(single - batch[i]).max() <= tol, (f.__name__, i)
        if len(args) > 1:  # one vector against a batch, and a batch of vectors against one element
            mixed = f(args[0], args[1][3], *args[2:])
            assert np.abs(mixed[3] - batch[3]).max() <= 4 * EPS * max(1.0, np.abs(batch[3]).max())
            mixed = f(args[0][3], args[1], *args[2:])
            assert np.abs(mixed[3] - batch[3]).max() <= 4 * EPS * max(1.0, np.abs(batch[3]).max())
    # a batch of one (any number of unit axes) takes the single-element path and keeps its shape
    for f, args in pairs:
        ref = f(*[x[4] if isinstance(x, np.ndarray) else x for x in args])
        one = f(*[x[4:5] if isinstance(x, np.ndarray) else x for x in args])
        assert one.shape == (1,) + ref.shape and np.array_equal(one[0], ref), f.__name__
        if len(args) > 1:
            full = f(*args)
            deep = f(args[0][4][None, None], *args[1:])  # (1, 1, …) against a batch of 9
            assert deep.shape == (1,) + full.shape, f.__name__
            assert np.abs(deep[0, 4] - ref).max() <= 4 * EPS * max(1.0, np.abs(ref).max()), f.__name__
    assert G.expm_skew(np.zeros((3, 3), dtype=int)).tolist() == np.eye(3).tolist()


@pytest.mark.parametrize("n", SIZES)
def test_expm_skew_apply(n):
    rng = np.random.default_rng(n + 20)
    X = np.stack([_skew_with_angle(rng, n, t) for t in (0.0, 1e-8, 0.7, np.pi, 7.0)])
    v = rng.standard_normal((5, n))
    ref = (G.expm_skew(X) @ v[..., None])[..., 0]
    assert np.abs(G.expm_skew_apply(X, v) - ref).max() < 1e-14
    assert np.abs(G.expm_skew_apply(X, v[0]) - G.expm_skew(X) @ v[0]).max() < 1e-14
    assert G.expm_skew_apply(X[2], v[2]).shape == (n,)


# ----------------------------------------------------------------------------- Cayley
@pytest.mark.parametrize("n", SIZES)
def test_cayley_against_direct_formula(n):
    rng = np.random.default_rng(30 + n)
    X = np.concatenate([_skew(rng, (4,), n, 1.0),
                        np.stack([_skew_with_angle(rng, n, t) for t in SPECIAL_ANGLES])])
    eye = np.eye(n)
    direct = np.linalg.inv(eye - X / 2) @ (eye + X / 2)
    for f in (G.cayley, G.cayley_skew):
        C = f(X)
        assert np.abs(C - direct).max() < 1e-14
        assert _orth_err(C) < 1e-14
        assert np.abs(np.linalg.det(C) - 1.0).max() < 1e-14
        assert np.abs(f(X[5]) - C[5]).max() < 1e-15
        assert f(X[5:6]).shape == (1, n, n) and np.abs(f(X[5:6])[0] - C[5]).max() < 1e-15
    v = rng.standard_normal(X.shape[:-1])
    ref = (direct @ v[..., None])[..., 0]
    assert np.abs(G.cayley_apply(X, v) - ref).max() < 1e-14
    assert np.abs(G.cayley_skew_apply(X, v) - ref).max() < 1e-14
    assert np.abs(G.cayley_skew_apply(X[3], v[3]) - ref[3]).max() < 1e-14
    assert G.cayley_apply(X[3:4], v[3]).shape == (1, n)
    assert np.abs(G.cayley_apply(X[3:4], v[3])[0] - ref[3]).max() < 1e-14
    with pytest.raises(np.linalg.LinAlgError):
        G.cayley(2.0 * np.eye(n))
    with pytest.raises(np.linalg.LinAlgError):
        G.cayley(2.0 * np.eye(n)[None])


def test_cayley_closed_forms_n2_n3():
    rng = np.random.default_rng(5)
    w = rng.standard_normal((7, 3)) * np.array([[0.0], [1e-8], [0.1], [1.0], [np.pi], [10.0], [1e3]])
    X = _hat(w)
    t2 = (w * w).sum(-1)[:, None, None]
    literal = np.eye(3) + 4 / (4 + t2) * (X + X @ X / 2)  # the brief's form
    assert np.abs(G.cayley_skew(X) - literal).max() < 4 * EPS
    assert np.abs(G.cayley_so3(w) - literal).max() < 4 * EPS
    v = rng.standard_normal((7, 3))
    assert np.abs(G.cayley_so3_apply(w, v) - (literal @ v[..., None])[..., 0]).max() < 1e-14
    # n = 2: rotation by 2 arctan(t/2)
    t = np.array([0.0, 1e-9, 0.3, 2.0, 50.0])
    X2 = np.zeros((5, 2, 2))
    X2[:, 1, 0], X2[:, 0, 1] = t, -t
    C = G.cayley_skew(X2)
    phi = 2 * np.arctan(t / 2)
    assert np.abs(C[:, 1, 0] - np.sin(phi)).max() < 4 * EPS
    assert np.abs(C[:, 0, 0] - np.cos(phi)).max() < 4 * EPS


def test_cayley_general_matrices_are_not_treated_as_skew():
    """3×3 se(2) matrices are not skew: cayley() must not use the so(3) closed form."""
    rng = np.random.default_rng(6)
    A = rng.standard_normal((4, 3, 3))
    A[:, 2, :] = 0.0
    A[:, :2, :2] -= np.swapaxes(A[:, :2, :2], -1, -2)
    eye = np.eye(3)
    direct = np.linalg.inv(eye - A / 2) @ (eye + A / 2)
    assert np.abs(G.cayley(A) - direct).max() < 1e-14
    v = rng.standard_normal((4, 3))
    assert np.abs(G.cayley_apply(A, v) - (direct @ v[..., None])[..., 0]).max() < 1e-14


# ----------------------------------------------------------------------------- rank-2 closed forms
@pytest.mark.parametrize("n", SIZES)
def test_rank2_maps_equal_dense(n):
    rng = np.random.default_rng(40 + n)
    a = rng.standard_normal((8, n))
    b = rng.standard_normal((8, n))
    # scale pairs to rotation angles 0, tiny, ~π, beyond π, large; one parallel pair (θ = 0)
    angles = np.array([0.0, 1e-9, 1e-4, 0.8, np.pi - 1e-6, np.pi, np.pi + 1e-3, 12.0])
    th = np.sqrt(np.maximum((a * a).sum(-1) * (b * b).sum(-1) - ((a * b).sum(-1)) ** 2, 0))
    a *= (angles / th)[:, None]
    b[0] = 3.0 * a[0] if angles[0] else 2.5 * b[0]
    a[0] = 0.4 * b[0]
    Om = _wedge(a, b)
    g = np.linalg.qr(rng.standard_normal((8, n, n)))[0]
    v = rng.standard_normal((8, n))
    E, C = G.expm_skew(Om), G.cayley_skew(Om)
    tol = 4e-15 * 12
    assert np.abs(G.exp_rank2(a, b) - E).max() < tol
    assert np.abs(G.apply_exp_rank2(g, a, b) - g @ E).max() < tol
    assert np.abs(G.exp_rank2_apply_vec(a, b, v) - (E @ v[..., None])[..., 0]).max() < tol
    assert np.abs(G.cayley_rank2(a, b) - C).max() < 1e-14
    assert np.abs(G.apply_cayley_rank2(g, a, b) - g @ C).max() < 1e-14
    assert np.abs(G.cayley_rank2_apply_vec(a, b, v) - (C @ v[..., None])[..., 0]).max() < 1e-14
    assert _orth_err(G.exp_rank2(a, b)) < 4e-15 and _orth_err(G.cayley_rank2(a, b)) < 4e-15
    for i in range(8):  # one pair at a time: the scalar path
        assert np.abs(G.exp_rank2(a[i], b[i]) - E[i]).max() < tol
        assert np.abs(G.apply_exp_rank2(g[i], a[i], b[i]) - g[i] @ E[i]).max() < tol
        assert np.abs(G.exp_rank2_apply_vec(a[i], b[i], v[i]) - E[i] @ v[i]).max() < tol
        assert np.abs(G.apply_cayley_rank2(g[i], a[i], b[i]) - g[i] @ C[i]).max() < 1e-14
        assert np.abs(G.cayley_rank2_apply_vec(a[i], b[i], v[i]) - C[i] @ v[i]).max() < 1e-14
    # Cayley of a rank-2 skew matrix is the plane rotation by 2 arctan(θ/2): trace n − 2 + 2 cos φ
    phi = 2 * np.arctan(angles[1:] / 2)
    trace = np.trace(G.cayley_rank2(a, b), axis1=-2, axis2=-1)
    assert np.abs(trace[1:] - (n - 2 + 2 * np.cos(phi))).max() < 1e-14


@pytest.mark.parametrize("n", (3, 5, 8))
def test_rank2_fedorov_kozlov_broadcast(n):
    """Ω = u ∧ e_n with one e_n for a batch of u (shape (n,) against (..., n))."""
    rng = np.random.default_rng(50 + n)
    u = np.zeros((2, 3, n))
    u[..., :-1] = rng.standard_normal((2, 3, n - 1))
    e = np.eye(n)[-1]
    Om = _wedge(u, np.broadcast_to(e, u.shape))
    g = np.linalg.qr(rng.standard_normal((n, n)))[0]
    assert np.abs(G.exp_rank2(u, e) - G.expm_skew(Om)).max() < 1e-14
    assert np.abs(G.apply_exp_rank2(g, u, e) - g @ G.expm_skew(Om)).max() < 1e-14
    assert np.abs(G.apply_cayley_rank2(g, u, e) - g @ G.cayley_skew(Om)).max() < 1e-14
    assert np.abs(G.exp_rank2_apply_vec(u, e, e) - G.expm_skew(Om)[..., :, -1]).max() < 1e-14


# ----------------------------------------------------------------------------- brackets
MATS = st.integers(2, 5).flatmap(
    lambda n: hnp.arrays(np.float64, (3, n, n), elements=st.floats(-3, 3, width=64)))


@settings(max_examples=60, deadline=None)
@given(MATS, st.floats(-2, 2, width=64))
def test_bracket_laws(M, s):
    X, Y, Z = M
    br = G.bracket
    tol = 1e-12 * (1 + np.abs(M).max()) ** 3
    assert np.array_equal(br(X, Y), -br(Y, X))
    assert np.abs(br(X, br(Y, Z)) + br(Y, br(Z, X)) + br(Z, br(X, Y))).max() < tol
    assert np.abs(br(X, s * Y + Z) - s * br(X, Y) - br(X, Z)).max() < tol
    Xs, Ys = X - X.T, Y - Y.T
    assert np.abs(G.bracket_skew(Xs, Ys) - br(Xs, Ys)).max() < tol
    assert np.abs(br(M[None], M[:, None]) - np.stack([[br(P, Q) for P in M] for Q in M])).max() < tol


def test_orthonormalize_is_quadratic():
    rng = np.random.default_rng(16)
    Q = G.expm_skew(_skew(rng, (5,), 4, 2.0))
    for delta in (1e-4, 1e-6, 1e-8):
        E = rng.standard_normal((5, 4, 4)) * delta
        E = 0.5 * (E + np.swapaxes(E, -1, -2))
        g = Q @ (np.eye(4) + E)
        h = G.orthonormalize(g)
        # h = Q(I − 3/2 E² + O(E³)), so hᵀh − I ≈ −3E²
        tol = 4 * np.linalg.norm(E, 2, axis=(-2, -1)).max() ** 2 + 1e-15
        assert _orth_err(g) > 0.5 * delta and _orth_err(h) < tol
        assert np.abs(h - Q).max() < tol


def test_cross3_matches_numpy():
    rng = np.random.default_rng(8)
    a, b = rng.standard_normal((2, 4, 5, 3))
    assert np.abs(G.cross3(a, b) - np.cross(a, b)).max() < 4 * EPS * 10
    assert np.abs(G.cross3(a, b[0, 0]) - np.cross(a, b[0, 0])).max() < 4 * EPS * 10
    assert np.abs(_hat(G.cross3(a, b)) - G.bracket(_hat(a), _hat(b))).max() < 1e-14


# ----------------------------------------------------------------------------- dexp and dexp^{-1}
def test_bernoulli_coefficients():
    c = dict(G.bernoulli_coefficients(13))
    assert set(c) == {0, 1, 2, 4, 6, 8, 10, 12}
    assert c[1] == -0.5 and c[2] == 1 / 12 and c[4] == -1 / 720 and c[6] == 1 / 30240
    assert c[8] == -1 / 1209600 and c[10] == 1 / 47900160
    assert G.dexpinv_terms(4) == 3 and G.dexpinv_terms(2) == 1 and G.dexpinv_terms(1) == 1


def test_oracle_frechet_against_scipy_and_richardson():
    rng = np.random.default_rng(9)
    Theta, V = _skew(rng, (), 4, 1.0), _skew(rng, (), 4, 1.0)
    E, L = _frechet_ld(Theta, V)
    L = np.asarray(L, dtype=float)
    assert np.abs(L - scipy.linalg.expm_frechet(Theta, V, compute_expm=False)).max() < 1e-12

    def cd(h):
        return (G.expm_skew(Theta + h * V) - G.expm_skew(Theta - h * V)) / (2 * h)
    # two Richardson levels: O(h^6) truncation, ~1e-14 rounding amplification
    d1, d2, d3 = cd(4e-3), cd(2e-3), cd(1e-3)
    r1, r2 = (4 * d2 - d1) / 3, (4 * d3 - d2) / 3
    rich = (16 * r2 - r1) / 15
    assert np.abs(rich - L).max() < 1e-11


@pytest.mark.parametrize("side", ("left", "right"))
@pytest.mark.parametrize("n", (2, 3, 4, 6))
def test_dexp_series_matches_exact_derivative(side, n):
    rng = np.random.default_rng(60 + n)
    Theta, V = _skew(rng, (3,), n, 0.6), _skew(rng, (3,), n, 1.0)
    assert np.abs(G.dexp(Theta, V, side) - _trivialised(Theta, V, side)).max() < 1e-14
    # a general (non-skew) algebra too
    Theta, V = rng.standard_normal((2, 3, n, n)) * 0.4
    assert np.abs(G.dexp(Theta, V, side) - _trivialised(Theta, V, side)).max() < 1e-14


@pytest.mark.parametrize("side", ("left", "right"))
@pytest.mark.parametrize("n", (2, 3, 4, 5, 7))
def test_dexpinv_recovers_chart_velocity(side, n):
    """Θ(t) = Θ0 + tV: dexp⁻¹ (80 terms) applied to the exact trivialised velocity gives back V.

    ad_Θ has eigenvalues up to θ1 + θ2 = 3.4 at θ = 2 here: the series converges like (3.4/2π)^k."""
    rng = np.random.default_rng(70 + n)
    for theta in (1e-8, 0.1, 1.0, 2.0):
        Theta = np.stack([_skew_with_angle(rng, n, theta) for _ in range(3)])
        V = _skew(rng, (3,), n)
        A = _trivialised(Theta, V, side)
        for skew in (False, True):
            got = G.dexpinv(Theta, A, 80, side, skew=skew)
            assert np.abs(got - V).max() < 1e-13 * (1 + theta), (theta, skew)
    # general matrices (se(3)-type), small enough for the series
    Theta, V = rng.standard_normal((2, 4, n, n)) * 0.3
    assert np.abs(G.dexpinv(Theta, _trivialised(Theta, V, side), 40, side) - V).max() < 1e-13


def test_dexpinv_sides_and_first_terms():
    rng = np.random.default_rng(11)
    T, A = _skew(rng, (2,), 4), _skew(rng, (2,), 4)
    br = G.bracket
    right = A + br(T, A) / 2 + br(T, br(T, A)) / 12
    left = A - br(T, A) / 2 + br(T, br(T, A)) / 12
    assert np.abs(G.dexpinv(T, A, 3, "right") - right).max() < 1e-14
    assert np.abs(G.dexpinv(T, A, 4, "left") - left).max() < 1e-14
    assert np.abs(G.dexpinv(T, A, 6, "right") - G.dexpinv(-T, A, 6, "left")).max() < 1e-14
    out = G.dexpinv(T, A, 1, "right")
    assert np.array_equal(out, A) and out is not A
    with pytest.raises(ValueError, match="side"):
        G.dexpinv(T, A, 3, "body")


@pytest.mark.parametrize("side", ("left", "right"))
def test_dexpinv_truncation_error_scales(side):
    """The truncated series errs like s^K at Θ = sΘ̂, K the first even index >= order (order 1: K = 1)."""
    rng = np.random.default_rng(12)
    That, V = _skew(rng, (4,), 5), _skew(rng, (4,), 5)
    scales = np.array([0.4, 0.2, 0.1])
    for order, K in ((1, 1), (2, 2), (3, 4), (4, 4), (5, 6), (6, 6)):
        errs = []
        for s in scales:
            A = _trivialised(s * That, V, side)
            errs.append(np.abs(G.dexpinv(s * That, A, order, side) - V).max())
        slopes = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
        assert np.all(np.abs(slopes - K) < 0.35), (order, slopes)


@pytest.mark.parametrize("side", ("left", "right"))
@pytest.mark.parametrize("theta", (0.0, 1e-8, 1e-3, 0.0999999, 0.1000001, 1.0, np.pi - 1e-6, np.pi,
                                   np.pi + 1e-3, 5.0, 6.0))
def test_dexpinv_so3_closed_form_exact(side, theta):
    rng = np.random.default_rng(13)
    Theta = np.stack([_skew_with_angle(rng, 3, theta) for _ in range(4)])
    V = _skew(rng, (4,), 3)
    A = _trivialised(Theta, V, side)
    # conditioning of dexp⁻¹ grows like 1/|sin(θ/2)|·θ near 2π
    cond = (1 + theta) / max(abs(np.sin(theta / 2)) / max(theta / 2, 1e-300), 1e-3) if theta else 1.0
    got = G.dexpinv_skew3(Theta, A, side)
    assert np.abs(got - V).max() < 2e-14 * cond
    w = lambda X: np.stack([X[..., 2, 1], X[..., 0, 2], X[..., 1, 0]], -1)  # noqa: E731
    assert np.abs(G.dexpinv_so3(w(Theta), w(A), side) - w(V)).max() < 2e-14 * cond
    if theta < 3.5:  # inside the radius of convergence of the series (θ < 2π), fast enough
        assert np.abs(G.dexpinv(Theta, A, 60, side) - got).max() < 1e-13 * cond


def test_dexpinv_so3_coefficient_continuous_at_branch():
    """c(θ) multiplies ad²_Θ, of size θ²: c θ² is what must be continuous to rounding at the branch
    (the closed form of c itself cancels like ε/θ², harmlessly)."""
    t2 = np.array([0.1 * (1 - 1e-9), 0.1 * (1 + 1e-9), 0.5, 2.0]) ** 2
    # c θ² = 1 − (θ/2) cot(θ/2) = Σ_k |B_2k| θ^2k / (2k)!, converging like (θ/2π)^2k
    B = dict(G.bernoulli_coefficients(60))
    ref = sum(abs(B[2 * k]) * t2**k for k in range(1, 30))
    got = G._dexp3_coefficient(t2)
    assert np.abs(got * t2 - ref).max() < 4 * EPS
    assert abs(got[0] / ref[0] * t2[0] - 1) < 4 * EPS  # the series branch is relatively exact


# ----------------------------------------------------------------------------- dcay^{-1}
def _cay_derivative(Theta: np.ndarray, V: np.ndarray) -> np.ndarray:
    """d/dt cay(Θ + tV) at 0 by the complex step (cay is rational: exact to rounding)."""
    h = 1e-30
    eye = np.eye(Theta.shape[-1])
    Z = Theta + 1j * h * V
    return np.linalg.solve(eye - Z / 2, eye + Z / 2).imag / h


@pytest.mark.parametrize("n", (2, 3, 4, 6))
@pytest.mark.parametrize("kind", ("skew", "general"))
def test_dcayinv_exact(n, kind):
    rng = np.random.default_rng(80 + n)
    if kind == "skew":
        angles = (0.0, 1e-8, 1.0, np.pi, np.pi + 1e-3, 5.0, 20.0)
        Theta = np.stack([_skew_with_angle(rng, n, t) for t in angles])
        V = _skew(rng, (7,), n)
    else:
        Theta, V = rng.standard_normal((2, 5, n, n))
    C = np.linalg.solve(np.eye(n) - Theta / 2, np.eye(n) + Theta / 2)
    D = _cay_derivative(Theta, V)
    Cinv = np.linalg.inv(C)
    left, right = D @ Cinv, Cinv @ D  # Y = cay(Θ) Y0: A = Y'Y⁻¹;  g = g0 cay(Θ): Ω = g⁻¹g'
    # rounding of the products (I ∓ Θ/2) A (I ± Θ/2) with the data's sizes
    scale = 4 * n * EPS * (1 + np.abs(Theta).max()) ** 2 * max(np.abs(left).max(), np.abs(right).max())
    assert np.abs(G.dcayinv(Theta, left, "left") - V).max() < scale
    assert np.abs(G.dcayinv(Theta, right, "right") - V).max() < scale
    eye = np.eye(n)  # the brief's formulas, literally
    assert np.abs((eye - Theta / 2) @ left @ (eye + Theta / 2) - V).max() < scale
    assert np.abs((eye + Theta / 2) @ right @ (eye - Theta / 2) - V).max() < scale
    if n > 2 or kind == "general":  # so(2) is abelian: there both sides agree
        assert np.abs(G.dcayinv(Theta, right, "left") - V).max() > 1e-3
    if n == 3 and kind == "skew":
        w = lambda X: np.stack([X[..., 2, 1], X[..., 0, 2], X[..., 1, 0]], -1)  # noqa: E731
        for side, A in (("left", left), ("right", right)):
            assert np.abs(G.dcayinv_so3(w(Theta), w(A), side) - w(V)).max() < scale
            assert np.abs(G.dcayinv_skew3(Theta, A, side) - V).max() < scale
            assert np.abs(G.dcayinv_skew3(Theta[3], A[3], side) - V[3]).max() < scale


# ----------------------------------------------------------------------------- RKMK orders: side, truncation
RK3 = (np.array([[0, 0, 0], [0.5, 0, 0], [-1, 2, 0]]), np.array([1, 4, 1]) / 6, np.array([0, 0.5, 1]))
RK4 = (np.array([[0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1, 0]]), np.array([1, 2, 2, 1]) / 6,
       np.array([0, 0.5, 0.5, 1]))
_R = np.random.default_rng(14)
_COEFS = {n: _skew(_R, (3,), n, 1.0) for n in (3, 4)}


def _Omega(t: float, n: int) -> np.ndarray:
    A0, A1, A2 = _COEFS[n]
    return A0 + np.sin(2 * t) * A1 + t * t * A2


def _rkmk(tableau, N: int, dinv, phi, reconstruct: str, n: int, T: float = 1.0) -> np.ndarray:
    """Integrate g' = g Ω(t) (right) or Y' = Ω(t) Y (left) from I over [0, T] with N RKMK steps."""
    a, b, c = tableau
    h = T / N
    g = np.eye(n)
    for i in range(N):
        K = []
        for s in range(len(b)):
            Th = h * sum(a[s, j] * K[j] for j in range(s)) if s else np.zeros((n, n))
            K.append(dinv(Th, _Omega(i * h + c[s] * h, n)))
        step = phi(h * sum(bs * Ks for bs, Ks in zip(b, K, strict=True)))
        g = g @ step if reconstruct == "right" else step @ g
    return g


@cache
def _reference(reconstruct: str, n: int, T: float = 1.0, N: int = 2000) -> np.ndarray:
    """Classical RK4 on the matrix ODE in R^{n×n} with small steps (error ~1e-14)."""
    h = T / N
    f = (lambda t, g: g @ _Omega(t, n)) if reconstruct == "right" else (lambda t, g: _Omega(t, n) @ g)
    g = np.eye(n)
    for i in range(N):
        t = i * h
        k1 = f(t, g)
        k2 = f(t + h / 2, g + h / 2 * k1)
        k3 = f(t + h / 2, g + h / 2 * k2)
        k4 = f(t + h, g + h * k3)
        g = g + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return g


def _observed_order(tableau, dinv, phi, reconstruct, n=4) -> float:
    ref = _reference(reconstruct, n)
    Ns = (8, 16, 32)
    errs = [np.abs(_rkmk(tableau, N, dinv, phi, reconstruct, n) - ref).max() for N in Ns]
    return float(np.log2(errs[-2] / errs[-1]))


@pytest.mark.parametrize("reconstruct", ("right", "left"))
def test_rkmk_order_depends_on_side_and_terms(reconstruct):
    """RK4 needs dexp⁻¹ through ad² (dexpinv_terms(4) = 3 terms) on the right side; one term fewer
    gives order 3, the wrong side gives order 2. RK3 needs 2 terms; 1 term gives order 2."""
    other = "left" if reconstruct == "right" else "right"

    def ex(order, side):
        return lambda T, A: G.dexpinv(T, A, order, side, skew=True)
    cases = [
        (RK4, ex(G.dexpinv_terms(4), reconstruct), 4),
        (RK4, ex(G.dexpinv_terms(4) - 1, reconstruct), 3),
        (RK4, ex(G.dexpinv_terms(4), other), 2),
        (RK3, ex(G.dexpinv_terms(3), reconstruct), 3),
        (RK3, ex(G.dexpinv_terms(3) - 1, reconstruct), 2),
        (RK4, lambda T, A: G.dcayinv(T, A, reconstruct), 4),
        (RK4, lambda T, A: G.dcayinv(T, A, other), 2),
    ]
    for i, (tab, dinv, expected) in enumerate(cases):
        phi = G.cayley_skew if i >= 5 else G.expm_skew
        p = _observed_order(tab, dinv, phi, reconstruct)
        assert abs(p - expected) < 0.4, (i, p, expected)


@pytest.mark.parametrize("reconstruct", ("right", "left"))
def test_rkmk_order_so3_exact_charts(reconstruct):
    """The exact so(3) inverse derivatives (closed-form dexp⁻¹, component dcay⁻¹) give RK4 its order."""
    other = "left" if reconstruct == "right" else "right"
    cases = [(G.dexpinv_skew3, G.expm_skew, reconstruct, 4), (G.dexpinv_skew3, G.expm_skew, other, 2),
             (G.dcayinv_skew3, G.cayley_skew, reconstruct, 4), (G.dcayinv_skew3, G.cayley_skew, other, 2)]
    for dinv, phi, side, expected in cases:
        p = _observed_order(RK4, lambda T, A, f=dinv, s=side: f(T, A, s), phi, reconstruct, n=3)
        assert abs(p - expected) < 0.4, (dinv.__name__, side, p)


# ----------------------------------------------------------------------------- so(4) = so(3) ⊕ so(3)
def _so4_basis():
    def E(i, j):
        M = np.zeros((4, 4))
        M[i, j], M[j, i] = 1.0, -1.0
        return M
    S = np.stack([E(0, 1) + E(2, 3), E(0, 2) - E(1, 3), E(0, 3) + E(1, 2)])
    A = np.stack([E(0, 1) - E(2, 3), E(0, 2) + E(1, 3), E(0, 3) - E(1, 2)])
    return S, A


def test_so4_split_is_a_lie_algebra_isomorphism():
    """so(4) = span S ⊕ span A with [S_i, A_j] = 0, S_i S_j = −δ_ij − ε_ijk S_k, A_i A_j = −δ_ij + ε_ijk A_k."""
    S, A = _so4_basis()
    eps3 = np.zeros((3, 3, 3))
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        eps3[i, j, k], eps3[j, i, k] = 1.0, -1.0
    for i in range(3):
        for j in range(3):
            assert np.abs(S[i] @ A[j] - A[j] @ S[i]).max() == 0.0
            want_S = -np.eye(4) * (i == j) - np.einsum("k,kab->ab", eps3[i, j], S)
            want_A = -np.eye(4) * (i == j) + np.einsum("k,kab->ab", eps3[i, j], A)
            assert np.abs(S[i] @ S[j] - want_S).max() == 0.0
            assert np.abs(A[i] @ A[j] - want_A).max() == 0.0
    rng = np.random.default_rng(40)
    X, Y = _skew(rng, (5,), 4), _skew(rng, (5,), 4)
    p, q = G.so4_split(X)
    pp, qq = G.so4_split(Y)
    assert p.shape == q.shape == (5, 3)
    assert np.abs(G.so4_join(p, q) - X).max() < 4 * EPS
    assert np.abs(np.einsum("bk,kij->bij", p, S) + np.einsum("bk,kij->bij", q, A) - X).max() < 4 * EPS
    br = G.so4_join(-2 * np.cross(p, pp), 2 * np.cross(q, qq))
    assert np.abs(br - (X @ Y - Y @ X)).max() < 1e-14
    assert np.allclose((X * X).sum((-2, -1)), 4 * ((p * p).sum(-1) + (q * q).sum(-1)), rtol=1e-14, atol=0)
    # the rotation angles of exp X are |p| + |q| and ||p| − |q||: eigenvalues ±i(|p| ± |q|)
    ang = np.sort(np.abs(np.linalg.eigvals(X[0]).imag))
    a, b = np.linalg.norm(p[0]), np.linalg.norm(q[0])
    assert np.allclose(ang, np.sort([abs(a - b), abs(a - b), a + b, a + b]), rtol=0, atol=1e-14)


@pytest.mark.parametrize("theta", (0.0, 1e-300, 1e-9, 1e-4, 0.3, 1.0, np.pi, 5.0, 20.0))
def test_so4_closed_forms_match_pade_and_solve(theta):
    """expm_skew / cayley_skew and their actions on n = 4 use the so(3) ⊕ so(3) closed forms: equal to the
    Padé exponential, the extended-precision oracle and the LU-solved Cayley transform to rounding."""
    rng = np.random.default_rng(41)
    X = np.stack([_skew_with_angle(rng, 4, theta), _skew(rng, (), 4, theta), _skew(rng, (), 4, 1.0)])
    v = rng.standard_normal((3, 4))
    scale = max(1.0, theta)
    nrm = np.sqrt(0.5 * (X * X).sum((-2, -1)))
    R = G.expm_skew(X)
    assert np.abs(R - G._expm_pade(X, nrm)).max() < 8 * EPS * scale
    assert _rel(R, _expm_ld(X)) < 8 * EPS * scale
    assert _orth_err(R) < 4 * EPS * scale
    assert np.abs(G.expm_skew_apply(X, v) - (R @ v[..., None])[..., 0]).max() < 8 * EPS * scale
    assert np.abs(G.expm_skew(X[1]) - R[1]).max() < 4 * EPS * scale  # single element = batch
    C = G.cayley_skew(X)
    assert np.abs(C - G.cayley(X)).max() < 8 * EPS * scale
    assert _orth_err(C) < 8 * EPS
    assert np.abs(G.cayley_skew_apply(X, v) - G.cayley_apply(X, v)).max() < 8 * EPS * scale
    assert np.abs(G.cayley_skew_apply(X[2], v[0]) - C[2] @ v[0]).max() < 8 * EPS * scale
    # large batches take the component forms too (small ones the Padé / LU path): the same maps
    Xb = np.concatenate([np.repeat(X, 100, axis=0), _skew(rng, (20,), 4, 0.01)])
    vb = rng.standard_normal(Xb.shape[:-1])
    assert Xb.shape[0] >= max(G._SO4_EXP_MIN_BATCH, G._SO4_CAYLEY_MIN_BATCH)
    Rb = G.expm_skew(Xb)
    assert np.abs(Rb - G._expm_pade(Xb, np.sqrt(0.5 * (Xb * Xb).sum((-2, -1))))).max() < 8 * EPS * scale
    vmax = np.abs(vb).max()
    assert np.abs(G.expm_skew_apply(Xb, vb) - (Rb @ vb[..., None])[..., 0]).max() < 8 * EPS * scale * vmax
    assert np.abs(G.cayley_skew(Xb) - G.cayley(Xb)).max() < 8 * EPS * scale
    assert np.abs(G.cayley_skew_apply(Xb, vb) - G.cayley_apply(Xb, vb)).max() < 8 * EPS * scale * vmax


@pytest.mark.parametrize("side", ("left", "right"))
def test_dexpinv_so3_truncated_is_the_series(side):
    """``dexpinv_so3(..., order=K)`` is the truncated series of :func:`dexpinv` in closed form, and on
    so(4) the series is that closed form on each factor (ad_P ↔ −2 p ×, ad_Q ↔ 2 q ×)."""
    rng = np.random.default_rng(42)
    th = rng.standard_normal((6, 3)) * np.array([[0.0], [1e-6], [0.05], [0.3], [1.0], [2.0]])
    a = rng.standard_normal((6, 3))
    X = _skew(rng, (6,), 4, 0.4)
    Y = _skew(rng, (6,), 4)
    p, q = G.so4_split(X)
    ap, aq = G.so4_split(Y)
    for order in range(1, 10):
        want = G.dexpinv(_hat(th), _hat(a), order, side)
        got = G.dexpinv_so3(th, a, side, order=order)
        assert np.abs(_hat(got) - want).max() < 1e-14 * (1 + np.abs(want).max()), order
        want4 = G.dexpinv(X, Y, order, side, skew=True)
        got4 = G.so4_join(G.dexpinv_so3(-2 * p, ap, side, order=order), G.dexpinv_so3(2 * q, aq, side, order=order))
        assert np.abs(got4 - want4).max() < 1e-14 * (1 + np.abs(want4).max()), order


def test_batch_coefficient_paths_match_the_references():
    """The fused and polynomial coefficient paths used by the RKMK kernels on batches."""
    rng = np.random.default_rng(43)
    special = [0.0, 1e-300, 1e-20, 1e-10, 4e-8, 1e-4, 0.0099, 0.01, 0.2, 0.25, 0.26, 3.0, 30.0]
    small = [np.concatenate([special[:7], rng.uniform(0, top, 600)]) for top in (1e-9, 1e-4, 0.0099)]
    large = [np.concatenate([special, rng.uniform(0, 0.3, 600)]), rng.uniform(0.0, 0.25, 600)]
    # small batches (trigonometric), large ones (Taylor polynomials of adaptive degree), mixed branches
    for sub in [np.array(special), np.array(special[:7]), np.array(special[7:10])] + small + large:
        ref = G._rodrigues(sub) + (G._dexp3_coefficient(sub),)
        for g, r in zip(G._rodrigues_dexp3(sub), ref, strict=True):
            assert np.max(np.abs(g - r) / np.abs(r)) < 4 * EPS
        for g, r in zip(G._rodrigues_fast(sub), ref[:3], strict=True):
            assert np.max(np.abs(g - r) / np.abs(r)) < 4 * EPS
    for t in (0.0, 1e-12, 0.0099, 0.011, 1.0, 30.0):  # Python floats: the same branches exactly
        assert G._rodrigues_dexp3(t) == G._rodrigues(t) + (G._dexp3_coefficient(t),)
