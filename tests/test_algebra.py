"""Tests of the algebra layer: so(n), general Lie algebras, subspaces (distributions), inertia.

Property-based (hypothesis) where a law holds for every input; geomstats 2.8.0 serves as an
independent oracle for so(n) (its basis differs from ours for n = 2, 3: the conversion is written
out explicitly in :func:`geomstats_to_ours`).
"""

from __future__ import annotations

import logging
import os
import sys
from itertools import combinations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import liesuslov as ls
from liesuslov.algebra import LieAlgebra, Subspace

SETTINGS = settings(max_examples=30, deadline=None)
FLOATS = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False, width=64)
BATCH = hnp.array_shapes(min_dims=0, max_dims=2, min_side=1, max_side=3)


# ---------------------------------------------------------------------------- algebras under test
def _sl2() -> LieAlgebra:
    """sl(2) from structure constants only: basis (h, e, f), [h,e] = 2e, [h,f] = -2f, [e,f] = h."""
    C = np.zeros((3, 3, 3))
    C[0, 1, 1], C[1, 0, 1] = 2.0, -2.0
    C[0, 2, 2], C[2, 0, 2] = -2.0, 2.0
    C[1, 2, 0], C[2, 1, 0] = 1.0, -1.0
    return LieAlgebra(C, name="sl(2)")


def _heisenberg() -> LieAlgebra:
    """The Heisenberg algebra: [e_1, e_2] = e_3, all else zero (nilpotent)."""
    C = np.zeros((3, 3, 3))
    C[0, 1, 2], C[1, 0, 2] = 1.0, -1.0
    return LieAlgebra(C, name="heis")


def _change_basis(C: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Constants in the basis ``f_i = sum_a P[i, a] e_a`` (P invertible)."""
    return np.einsum("ia,jb,abc,ck->ijk", P, P, C, np.linalg.inv(P))


def _twisted(n: int, seed: int) -> LieAlgebra:
    """so(n) in a random non-orthonormal basis, given by structure constants only."""
    rng = np.random.default_rng(seed)
    d = ls.so(n).dim
    P = np.eye(d) + 0.3 * rng.standard_normal((d, d))
    return LieAlgebra(_change_basis(np.asarray(ls.so(n).structure_constants), P), name=f"so({n})~")


ALGEBRAS = {f"so({n})": (lambda n=n: ls.so(n)) for n in range(2, 9)}
ALGEBRAS.update({"se(2)": lambda: ls.se(2), "se(3)": lambda: ls.se(3), "sl(2)": _sl2,
                 "heis": _heisenberg, "so(3)~": lambda: _twisted(3, 1), "so(4)~": lambda: _twisted(4, 2)})
MATRIX_ALGEBRAS = [k for k in ALGEBRAS if k.startswith(("so(", "se(")) and not k.endswith("~")]


@st.composite
def algebra_and_elements(draw, names=tuple(ALGEBRAS), count=2):
    """An algebra from ``names`` and ``count`` elements with a common batch shape."""
    alg = ALGEBRAS[draw(st.sampled_from(names))]()
    shape = draw(BATCH) + (alg.dim,)
    return (alg, *[draw(hnp.arrays(np.float64, shape, elements=FLOATS)) for _ in range(count)])


def _close(a, b, scale=1.0, tol=1e-10):
    np.testing.assert_allclose(a, b, rtol=0, atol=tol * max(1.0, scale))


# ---------------------------------------------------------------------------- geomstats oracle
@pytest.fixture(scope="module")
def geomstats_mods():
    """geomstats' so(n) classes, imported with the numpy backend and without touching logging."""
    if "geomstats" in sys.modules:
        import geomstats._backend as gsb
        if gsb.BACKEND_NAME != "numpy":
            pytest.skip(f"geomstats already imported with backend {gsb.BACKEND_NAME!r}")
    root = logging.getLogger()
    level, handlers = root.level, root.handlers[:]
    _LOGGING_BEFORE.update(level=level, handlers=handlers)
    old_env = os.environ.get("GEOMSTATS_BACKEND")
    os.environ["GEOMSTATS_BACKEND"] = "numpy"
    try:
        pytest.importorskip("geomstats", reason="geomstats is the optional extra liesuslov[geomstats]")
        from geomstats.geometry.invariant_metric import InvariantMetric
        from geomstats.geometry.skew_symmetric_matrices import SkewSymmetricMatrices
        from geomstats.geometry.special_orthogonal import SpecialOrthogonal
    finally:
        root.setLevel(level)
        root.handlers[:] = handlers
        if old_env is None:
            os.environ.pop("GEOMSTATS_BACKEND")
        else:
            os.environ["GEOMSTATS_BACKEND"] = old_env
    return SkewSymmetricMatrices, SpecialOrthogonal, InvariantMetric


_LOGGING_BEFORE: dict = {}


def geomstats_to_ours(n: int) -> np.ndarray:
    """Signed permutation T with ``x_ours = c_geomstats @ T`` (rows: our coordinates of its basis).

    * n = 2: geomstats' single basis matrix is [[0, -1], [1, 0]] = -E_12, so x_12 = -c.
    * n = 3: its basis is hat(e_1), hat(e_2), hat(e_3) (the cross-product form): hat(e_1) = -E_23,
      hat(e_2) = +E_13, hat(e_3) = -E_12; so c = w = (-x_23, x_13, -x_12) (our ``to_vector3``) and
      x = (x_12, x_13, x_23) = (-c_3, c_2, -c_1).
    * n >= 4: E_ij for i < j in lexicographic order, exactly ours: T = identity.
    """
    if n == 2:
        return np.array([[-1.0]])
    if n == 3:
        return np.array([[0.0, 0.0, -1.0],   # c_1: hat(e_1) = -E_23
                         [0.0, 1.0, 0.0],    # c_2: hat(e_2) = +E_13
                         [-1.0, 0.0, 0.0]])  # c_3: hat(e_3) = -E_12
    return np.eye(n * (n - 1) // 2)


def test_geomstats_import_leaves_logging_alone(geomstats_mods):
    assert "geomstats" in sys.modules
    root = logging.getLogger()
    assert root.level == _LOGGING_BEFORE["level"]
    assert root.handlers == _LOGGING_BEFORE["handlers"]


@pytest.mark.parametrize("n", range(2, 9))
def test_geomstats_basis_conversion(geomstats_mods, n):
    SkewSymmetricMatrices, _, _ = geomstats_mods
    alg = ls.so(n)
    gs_basis = np.asarray(SkewSymmetricMatrices(n).basis)
    np.testing.assert_array_equal(alg.vee(gs_basis), geomstats_to_ours(n))
    np.testing.assert_array_equal(alg.hat(geomstats_to_ours(n)), gs_basis)
    if n == 3:  # the conversion is exactly the n = 3 vector form
        np.testing.assert_array_equal(alg.to_vector3(np.eye(3)), geomstats_to_ours(3).T)


@SETTINGS
@given(n=st.integers(2, 8), data=st.data())
def test_bracket_against_geomstats(geomstats_mods, n, data):
    SkewSymmetricMatrices, _, _ = geomstats_mods
    gsalg = SkewSymmetricMatrices(n)
    alg = ls.so(n)
    x, y = (data.draw(hnp.arrays(np.float64, (alg.dim,), elements=FLOATS)) for _ in range(2))
    T = geomstats_to_ours(n)
    # matrix form: both are skew matrices, the bracket is the commutator
    _close(alg.hat(alg.bracket(x, y)), gsalg.bracket(alg.hat(x), alg.hat(y)), 9.0 * n)
    # coordinate form, in geomstats' basis (unbatched: its n = 3 basis_representation transposes batches)
    cx, cy = x @ T.T, y @ T.T
    c_xy = gsalg.basis_representation(gsalg.bracket(gsalg.matrix_representation(cx),
                                                     gsalg.matrix_representation(cy)))
    _close(c_xy @ T, alg.bracket(x, y), 9.0 * n)
    # BCH to second order: X + Y + 1/2 [X, Y]
    bch = gsalg.baker_campbell_hausdorff(alg.hat(x), alg.hat(y), order=2)
    _close(alg.vee(bch), x + y + 0.5 * alg.bracket(x, y), 9.0 * n)


@pytest.mark.parametrize("n", range(2, 7))
def test_structure_constants_against_geomstats(geomstats_mods, n):
    _, SpecialOrthogonal, InvariantMetric = geomstats_mods
    group = SpecialOrthogonal(n, equip=False)
    group.equip_with_metric(InvariantMetric)
    metric = group.metric
    E = np.asarray(ls.so(n).representation)
    # geomstats' structure_constant(a, b, c) is <[a, b], c> for its metric, not our array C:
    # C[i, j, k] = <[E_i, E_j], E_k>_gs / <E_k, E_k>_gs, valid because our basis is orthogonal for it.
    gram = metric.inner_product_at_identity(E[:, None], E[None, :])
    np.testing.assert_allclose(gram, np.diag(np.diag(gram)), atol=1e-14)
    sc = metric.structure_constant(E[:, None, None], E[None, :, None], E[None, None, :])
    np.testing.assert_allclose(sc / np.diag(gram), ls.so(n).structure_constants, atol=1e-14)


# ---------------------------------------------------------------------------- so(n): hat / vee
@SETTINGS
@given(n=st.integers(2, 8), shape=BATCH, data=st.data())
def test_hat_vee_round_trip(n, shape, data):
    alg = ls.so(n)
    x = data.draw(hnp.arrays(np.float64, shape + (alg.dim,), elements=FLOATS))
    X = alg.hat(x)
    assert X.shape == shape + (n, n)
    np.testing.assert_array_equal(X, -np.swapaxes(X, -1, -2))
    np.testing.assert_array_equal(alg.vee(X), x)
    A = data.draw(hnp.arrays(np.float64, shape + (n, n), elements=FLOATS))
    S = A - np.swapaxes(A, -1, -2)
    np.testing.assert_array_equal(alg.hat(alg.vee(S)), S)
    for i, j in combinations(range(n), 2):  # coordinate of E_ij is X[i, j], lexicographic order
        np.testing.assert_array_equal(x[..., alg.index(i, j)], X[..., i, j])
    assert [alg.index(i, j) for i, j in combinations(range(n), 2)] == list(range(alg.dim))


@pytest.mark.parametrize("n", range(2, 9))
def test_basis_is_orthonormal_for_pairing(n):
    alg = ls.so(n)
    E = alg.representation
    G = ls.pairing(E[:, None], E[None, :])
    np.testing.assert_allclose(G, np.eye(alg.dim), atol=1e-15)
    assert alg.dim == n * (n - 1) // 2


@SETTINGS
@given(algebra_and_elements(names=tuple(f"so({n})" for n in range(2, 9))))
def test_pairing_is_coordinate_dot(args):
    alg, x, y = args
    _close(alg.pairing(x, y), ls.pairing(alg.hat(x), alg.hat(y)), 9.0 * alg.dim)


# ---------------------------------------------------------------------------- brackets
@SETTINGS
@given(algebra_and_elements(count=3))
def test_bracket_antisymmetry_and_jacobi(args):
    alg, x, y, z = args
    s = 1.0 + float(np.max(np.abs(alg.structure_constants)))
    _close(alg.bracket(x, y), -alg.bracket(y, x), 9 * s)
    jac = (alg.bracket(alg.bracket(x, y), z) + alg.bracket(alg.bracket(y, z), x)
           + alg.bracket(alg.bracket(z, x), y))
    _close(jac, 0.0, 27 * s * s * alg.dim)
    assert alg.bracket(x, y).shape == x.shape


@SETTINGS
@given(algebra_and_elements(names=tuple(MATRIX_ALGEBRAS)))
def test_bracket_is_matrix_commutator(args):
    alg, x, y = args
    X, Y = alg.hat(x), alg.hat(y)
    _close(alg.hat(alg.bracket(x, y)), X @ Y - Y @ X, 9.0 * alg.dim)
    _close(alg.vee(X), x, 3.0)


@SETTINGS
@given(algebra_and_elements())
def test_ad_is_a_homomorphism(args):
    alg, x, y = args
    s = 1.0 + float(np.max(np.abs(alg.structure_constants)))
    ax, ay = alg.ad(x), alg.ad(y)
    _close(ax @ ay - ay @ ax, alg.ad(alg.bracket(x, y)), 27 * s * s * alg.dim)
    _close(np.einsum("...kj,...j->...k", ax, y), alg.bracket(x, y), 9 * s * alg.dim)


@SETTINGS
@given(algebra_and_elements(count=3))
def test_coad_defined_by_pairing(args):
    alg, x, m, y = args
    s = 1.0 + float(np.max(np.abs(alg.structure_constants)))
    lhs = np.sum(alg.coad(x, m) * y, axis=-1)
    rhs = np.sum(m * alg.bracket(x, y), axis=-1)
    _close(lhs, rhs, 27 * s * alg.dim)


@SETTINGS
@given(algebra_and_elements(names=tuple(f"so({n})" for n in range(2, 9))))
def test_coad_on_so_is_commutator(args):
    alg, x, m = args
    X, M = alg.hat(x), alg.hat(m)
    _close(alg.hat(alg.coad(x, m)), M @ X - X @ M, 9.0 * alg.dim)
    # the generic structure-constant formula agrees with the commutator shortcut
    _close(LieAlgebra.coad(alg, x, m), alg.coad(x, m), 9.0 * alg.dim)


@pytest.mark.parametrize("n", range(2, 9))
def test_killing_form_of_so(n):
    alg = ls.so(n)
    rng = np.random.default_rng(n)
    x, y = rng.standard_normal((2, 5, alg.dim))
    B = np.einsum("...i,ij,...j->...", x, alg.killing_form, y)
    trXY = np.einsum("...ij,...ji->...", alg.hat(x), alg.hat(y))
    _close(B, (n - 2) * trXY, 100.0 * n)
    _close(alg.killing_form, -2.0 * (n - 2) * np.eye(alg.dim), 1.0)


@pytest.mark.parametrize("n", range(2, 9))
def test_structure_constants_match_representation(n):
    alg = ls.so(n)
    E = np.asarray(alg.representation)
    comm = np.einsum("iab,jbc->ijac", E, E) - np.einsum("jab,ibc->ijac", E, E)
    C_rep = -0.5 * np.einsum("ijab,kba->ijk", comm, E)  # <[E_i, E_j], E_k>, basis orthonormal
    np.testing.assert_allclose(alg.structure_constants, C_rep, atol=1e-15)
    generic = LieAlgebra(C_rep, representation=E)
    rng = np.random.default_rng(n)
    x, y = rng.standard_normal((2, 4, alg.dim))
    _close(generic.bracket(x, y), alg.bracket(x, y), 10.0)
    _close(generic.ad(x), alg.ad(x), 10.0)
    _close(generic.hat(x), alg.hat(x), 1.0)
    _close(generic.vee(alg.hat(x)), x, 10.0)


def test_so3_vector_form():
    alg = ls.so(3)
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((2, 4, 3))
    np.testing.assert_allclose(ls.hat3(a) @ b[..., :, None], np.cross(a, b)[..., :, None], atol=1e-14)
    _close(alg.hat(alg.from_vector3(a)), ls.hat3(a))
    _close(alg.to_vector3(alg.vee(ls.hat3(a))), a)
    _close(ls.vee3(ls.hat3(a)), a)
    _close(alg.from_vector3(alg.to_vector3(a)), a)
    _close(alg.to_vector3(alg.bracket(alg.from_vector3(a), alg.from_vector3(b))), np.cross(a, b), 10.0)
    # w = (-Omega_23, Omega_13, -Omega_12)
    x = rng.standard_normal(3)
    X = alg.hat(x)
    np.testing.assert_array_equal(alg.to_vector3(x), [-X[1, 2], X[0, 2], -X[0, 1]])
    _close(ls.wedge(a, b), ls.hat3(np.cross(b, a)), 10.0)
    assert ls.wedge(a, b).shape == (4, 3, 3)


def test_se_brackets_as_documented():
    se2 = ls.se(2)
    e = np.eye(3)
    _close(se2.bracket(e[0], e[1]), e[2])
    _close(se2.bracket(e[0], e[2]), -e[1])
    _close(se2.bracket(e[1], e[2]), 0.0)
    np.testing.assert_array_equal(se2.hat([0.7, 1.5, -2.0]), [[0, -0.7, 1.5], [0.7, 0, -2.0], [0, 0, 0]])
    se3 = ls.se(3)
    rng = np.random.default_rng(0)
    (w1, v1), (w2, v2) = rng.standard_normal((2, 2, 5, 3))
    got = se3.bracket(np.concatenate([w1, v1], -1), np.concatenate([w2, v2], -1))
    _close(got[..., :3], np.cross(w1, w2), 10.0)
    _close(got[..., 3:], np.cross(w1, v2) - np.cross(w2, v1), 10.0)
    X = se3.hat(np.concatenate([w1, v1], -1))
    _close(X[..., :3, :3], ls.hat3(w1))
    _close(X[..., :3, 3], v1)
    np.testing.assert_array_equal(X[..., 3, :], 0.0)


@pytest.mark.parametrize("name", ["so(3)~", "so(4)~"])
def test_twisted_basis_is_isomorphic(name):
    """Killing forms of so(n) in any basis are negative definite (compact semisimple)."""
    alg = ALGEBRAS[name]()
    assert np.linalg.eigvalsh(alg.killing_form)[-1] < 0
    assert not alg.is_abelian()
    assert ls.so(2).is_abelian() and not _heisenberg().killing_form.any()  # nilpotent


# ---------------------------------------------------------------------------- subspaces, projectors
def _random_subspace(alg, k, rng):
    return Subspace(alg, rng.standard_normal((k, alg.dim)))


def _random_spd(d, rng):
    A = rng.standard_normal((d, d))
    return A @ A.T + 0.5 * np.eye(d)


def _around_the_tolerance(inside: np.ndarray, normal: np.ndarray, tol: float):
    """Points of D (rows of ``inside``, the last one 0) moved off D by 0.5 and 2 times ``tol |x|`` (by 0.5 and
    2 times tol from 0), and whether the relative test ``|x - P x| <= tol |x|`` holds: yes, yes, no (but 0)."""
    scale = np.linalg.norm(inside, axis=1)[:, None]
    scale[scale == 0.0] = 1.0
    pts = np.concatenate([inside, inside + 0.5 * tol * scale * normal, inside + 2.0 * tol * scale * normal])
    return pts, np.array([True] * 7 + [False] * 5)


@pytest.mark.parametrize("n", [3, 5, 17])  # so(17): d = 136, beyond the residual projector (the basis path)
def test_contains_one_vector_agrees_with_the_batch_at_the_tolerance(n):
    """One vector (the residual projector I - B^T B, or the basis when d is large) and a batch (the basis)
    give the same answer, also for points just inside and just outside the tolerance."""
    alg = ls.so(n)
    rng = np.random.default_rng(n)
    S = _random_subspace(alg, alg.dim // 2, rng)
    inside = S.project(rng.standard_normal((4, alg.dim))) * np.array([[1.0], [1e-3], [1e3], [0.0]])
    normal = S.complement().basis[0]
    tol = 1e-6
    pts, want = _around_the_tolerance(inside, normal, tol)
    np.testing.assert_array_equal(S.contains(pts, tol), want)
    one = np.array([S.contains(p, tol) for p in pts])
    np.testing.assert_array_equal(one, want)
    # the absolute floor (for brackets that vanish to rounding): a step off 0 within atol is inside
    np.testing.assert_array_equal(S.contains(pts[[7, 11]], tol, atol=tol), [True, False])
    assert S.contains(pts[7], tol, atol=tol) and not S.contains(pts[11], tol, atol=tol)
    assert all(isinstance(S.contains(p, tol), np.bool_) for p in pts[:2])


@pytest.mark.parametrize("n", [3, 5, 8, 9])  # so(9): d = 36, beyond the Python-float path (the projector)
def test_contains_one_vector_of_a_coordinate_subspace_agrees_with_the_batch(n):
    """A coordinate subspace (signed axes, in any order): one vector (its entries off D's axes, on Python
    floats up to d = 32) and a batch (the basis) give the same answer at the tolerance; a rotated copy of
    the same subspace is not a coordinate one and takes the projector."""
    alg = ls.so(n)
    d = alg.dim
    rng = np.random.default_rng(100 + n)
    axes = rng.permutation(d)[: d // 2]
    rows = np.zeros((axes.size, d))
    rows[np.arange(axes.size), axes] = rng.choice([-1.0, 1.0], axes.size)
    S = Subspace(alg, rows)
    off = tuple(sorted(set(range(d)) - set(axes.tolist())))
    assert S._outside_axes() == off
    Q = np.linalg.qr(rng.standard_normal((d, d)))[0]
    assert Subspace(alg, rows @ Q)._outside_axes() is None
    inside = S.project(rng.standard_normal((4, d))) * np.array([[1.0], [1e-3], [1e3], [0.0]])
    normal = np.zeros(d)
    normal[off[0]] = 1.0
    tol = 1e-6
    pts, want = _around_the_tolerance(inside, normal, tol)
    np.testing.assert_array_equal(S.contains(pts, tol), want)
    np.testing.assert_array_equal(np.array([S.contains(p, tol) for p in pts]), want)
    assert S.contains(pts[7], tol, atol=tol) and not S.contains(pts[11], tol, atol=tol)
    assert not S.contains(np.full(d, np.nan)) and isinstance(S.contains(pts[0], tol), np.bool_)


@SETTINGS
@given(name=st.sampled_from(sorted(ALGEBRAS)), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_projectors_idempotent_and_self_adjoint(name, seed, data):
    alg = ALGEBRAS[name]()
    k = data.draw(st.integers(0, alg.dim))
    rng = np.random.default_rng(seed)
    S = _random_subspace(alg, k, rng)
    assert S.dim == k
    np.testing.assert_allclose(S.basis @ S.basis.T, np.eye(k), atol=1e-12)
    P = S.projector()
    _close(P @ P, P)
    _close(P, P.T)
    K = _random_spd(alg.dim, rng)
    PK = S.projector(K)
    s = np.linalg.cond(K)
    _close(PK @ PK, PK, s)
    _close(K @ PK, PK.T @ K, s * np.max(K))  # self-adjoint for <x, y>_K = x^T K y
    _close(PK @ S.basis.T, S.basis.T, s)  # identity on the subspace
    x = rng.standard_normal((3, alg.dim))
    assert np.all(S.contains(S.project(x))) and np.all(S.contains(S.project(x, K)))
    _close(S.project(x, ls.Inertia(alg, K)), S.project(x, K))
    # the K-orthogonal residual is K-orthogonal to the subspace
    _close((x - S.project(x, K)) @ K @ S.basis.T, 0.0, s * np.max(K) * 10)


@SETTINGS
@given(name=st.sampled_from(sorted(ALGEBRAS)), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_annihilator_is_orthogonal_complement(name, seed, data):
    alg = ALGEBRAS[name]()
    r = data.draw(st.integers(0, alg.dim))
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((r, alg.dim))
    D = Subspace.annihilator(alg, A)
    assert D.dim == alg.dim - r
    _close(A @ D.basis.T, 0.0, 10.0)
    span = Subspace(alg, A) if r else None
    P_span = span.projector() if r else np.zeros((alg.dim, alg.dim))
    _close(D.projector(), np.eye(alg.dim) - P_span)
    _close(D.complement().projector(), P_span)
    _close(Subspace(alg, D.covectors).projector(), P_span)
    # the canonical basis depends only on the subspace, not on the spanning set
    mix = rng.standard_normal((D.dim, D.dim)) + 3 * np.eye(D.dim)
    if D.dim:
        _close(Subspace(alg, mix @ D.basis).basis, D.basis, np.linalg.cond(mix))


@pytest.mark.parametrize("n", range(2, 9))
def test_suslov_canonical_basis(n):
    alg = ls.so(n)
    D = ls.suslov_distribution(n)
    e = np.eye(n)
    want = alg.vee(np.stack([np.outer(e[i], e[n - 1]) - np.outer(e[n - 1], e[i]) for i in range(n - 1)]))
    np.testing.assert_array_equal(D.basis, want)  # E_1n, ..., E_{n-1,n} in this order
    assert D.dim == n - 1
    # the same subspace from its constraints Omega_ij = 0 (i < j <= n - 1) has the same basis
    A = np.eye(alg.dim)[[alg.index(i, j) for i, j in combinations(range(n - 1), 2)]]
    np.testing.assert_array_equal(Subspace.annihilator(alg, A).basis, want)
    xi = np.arange(1.0, n)
    np.testing.assert_array_equal(alg.hat(D.from_coordinates(xi))[:, n - 1][: n - 1], xi)


# ---------------------------------------------------------------------------- symmetric pairs
@pytest.mark.parametrize("n", range(3, 9))
def test_fedorov_kozlov_symmetric_pair(n):
    D = ls.suslov_distribution(n)
    k = D.complement()
    assert k.dim == (n - 1) * (n - 2) // 2
    assert ls.is_symmetric_pair(k, D)
    assert D.is_symmetric()
    assert k.is_subalgebra()  # k = so(n - 1)
    assert not ls.is_symmetric_pair(D, k)


def _block_split(p: int, q: int) -> tuple[Subspace, Subspace]:
    n = p + q
    alg = ls.so(n)
    diag = [alg.index(i, j) for i, j in combinations(range(n), 2) if (i < p) == (j < p)]
    off = [alg.index(i, j) for i, j in combinations(range(n), 2) if (i < p) != (j < p)]
    E = np.eye(alg.dim)
    return (Subspace(alg, E[diag]) if diag else Subspace(alg, np.zeros((0, alg.dim)))), Subspace(alg, E[off])


@pytest.mark.parametrize(("p", "q"), [(1, 2), (2, 2), (1, 4), (2, 3), (3, 3), (2, 5), (4, 4)])
def test_block_diagonal_symmetric_pair(p, q):
    k, off = _block_split(p, q)
    assert k.dim + off.dim == ls.so(p + q).dim
    assert ls.is_symmetric_pair(k, off)
    assert off.is_symmetric()
    assert k.is_subalgebra() and not off.is_subalgebra()


@SETTINGS
@given(n=st.integers(4, 7), seed=st.integers(0, 2**32 - 1))
def test_random_split_is_not_symmetric(n, seed):
    alg = ls.so(n)
    p = _random_subspace(alg, n - 1, np.random.default_rng(seed))
    assert not ls.is_symmetric_pair(p.complement(), p)
    assert not p.is_symmetric()
    k, off = _block_split(1, n - 1)
    tilted = Subspace(alg, off.basis + 0.5 * k.basis[0])  # k + tilted is still direct, not symmetric
    assert not ls.is_symmetric_pair(k, tilted)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_every_plane_of_so3_is_symmetric(seed):
    """In so(3) = (R^3, x): [u, v] is orthogonal to u, and [v, v'] is parallel to u for v, v' in u-perp."""
    p = _random_subspace(ls.so(3), 2, np.random.default_rng(seed))
    assert ls.is_symmetric_pair(p.complement(), p)
    assert not p.is_subalgebra() and p.is_bracket_generating()


def test_symmetric_pair_needs_direct_sum():
    D = ls.suslov_distribution(4)
    assert not ls.is_symmetric_pair(D, D)
    assert not ls.is_symmetric_pair(D.complement(), Subspace(D.algebra, D.basis[:2]))


# ---------------------------------------------------------------------------- nonholonomy
@pytest.mark.parametrize("n", range(3, 9))
def test_suslov_is_nonholonomic_and_bracket_generating(n):
    D = ls.suslov_distribution(n)
    assert not D.is_subalgebra()
    assert D.growth_vector() == (n - 1, n * (n - 1) // 2)
    assert D.is_bracket_generating()


@pytest.mark.parametrize("n", range(3, 9))
def test_holonomic_examples(n):
    alg = ls.so(n)
    k = ls.suslov_distribution(n).complement()  # so(n - 1): a subalgebra
    assert k.is_subalgebra()
    assert k.growth_vector() == (k.dim,)
    assert not k.is_bracket_generating()
    line = Subspace(alg, np.random.default_rng(n).standard_normal(alg.dim))  # span of one element
    assert line.dim == 1 and line.is_subalgebra() and line.growth_vector() == (1,)
    heis = _heisenberg()
    assert Subspace(heis, np.eye(3)[[0, 2]]).is_subalgebra()
    assert not Subspace(heis, np.eye(3)[:2]).is_subalgebra()
    assert Subspace(heis, np.eye(3)[:2]).growth_vector() == (2, 3)


def test_suslov_n2_is_whole_algebra():
    D = ls.suslov_distribution(2)
    assert D.dim == 1 and D.is_subalgebra() and D.growth_vector() == (1,)


# ---------------------------------------------------------------------------- inertia
def _random_mass_tensor(n, rng):
    A = rng.standard_normal((n, n))
    return A @ A.T + 0.2 * np.eye(n)


@SETTINGS
@given(n=st.integers(2, 8), seed=st.integers(0, 2**32 - 1))
def test_mass_tensor_matrix(n, seed):
    rng = np.random.default_rng(seed)
    I = _random_mass_tensor(n, rng)
    J = ls.Inertia.from_mass_tensor(I)
    E = ls.so(n).representation
    want = ls.pairing(E[:, None], (I @ E + E @ I)[None, :])  # <E_a, I E_b + E_b I>
    _close(J.matrix, want, np.max(I) * 10)
    x = rng.standard_normal((2, 3, J.dim))
    X = ls.so(n).hat(x)
    _close(ls.so(n).hat(J(x)), I @ X + X @ I, np.max(I) * 100)
    _close(J.kinetic_energy(x), 0.5 * ls.pairing(I @ X + X @ I, X), np.max(I) * 1000)
    _close(J.inverse(J(x)), x, np.linalg.cond(J.matrix) * 10)


@pytest.mark.parametrize("n", range(2, 9))
def test_diagonal_mass_tensor(n):
    Id = np.arange(1.0, n + 1) ** 1.5
    J = ls.Inertia.from_mass_tensor(Id)
    want = np.diag([Id[i] + Id[j] for i, j in combinations(range(n), 2)])
    np.testing.assert_allclose(J.matrix, want, atol=1e-14)
    np.testing.assert_array_equal(J.matrix, ls.Inertia.from_mass_tensor(np.diag(Id)).matrix)
    if n >= 3:
        D = ls.suslov_distribution(n)
        assert J.is_invariant(D)
        _close(J.restrict(D), np.diag(Id[:-1] + Id[-1]))


@pytest.mark.parametrize("n", range(3, 9))
def test_generic_mass_tensor_does_not_preserve_D(n):
    rng = np.random.default_rng(100 + n)
    I = _random_mass_tensor(n, rng)
    J = ls.Inertia.from_mass_tensor(I)
    D = ls.suslov_distribution(n)
    assert not J.is_invariant(D)
    _close(J.restrict(D), D.basis @ J.matrix @ D.basis.T)
    S = _random_subspace(J.algebra, 2, rng)
    _close(J.restrict(S), S.basis @ J.matrix @ S.basis.T)
    # an eigenspace of J is invariant
    w, V = np.linalg.eigh(J.matrix)
    assert J.is_invariant(Subspace(J.algebra, V[:, :2].T))


def test_indefinite_mass_tensor_with_positive_inertia():
    J = ls.Inertia.from_mass_tensor([-1.0, 2.0, 3.0])  # lambda_i + lambda_j > 0 for all pairs
    assert np.linalg.eigvalsh(J.matrix)[0] > 0


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_principal_moments(seed):
    rng = np.random.default_rng(seed)
    Jd = rng.uniform(0.5, 3.0, 3)
    Jw = np.diag(Jd) if seed % 2 else _random_mass_tensor(3, rng)  # diagonal or a full SPD 3x3
    J = ls.Inertia.from_principal_moments(Jd if seed % 2 else Jw)
    alg = ls.so(3)
    w = rng.standard_normal((4, 3))
    # J(hat w) = hat(J w)
    _close(alg.hat(J(alg.vee(ls.hat3(w)))), ls.hat3(w @ Jw), 100.0)
    _close(J.principal_moments, Jw, 10.0)
    _close(J.mass_tensor, 0.5 * np.trace(Jw) * np.eye(3) - Jw, 10.0)
    _close(np.trace(J.mass_tensor) * np.eye(3) - J.mass_tensor, Jw, 10.0)


# ---------------------------------------------------------------------------- validation errors
def test_so_argument_errors():
    with pytest.raises(ValueError, match="n must be >= 2"):
        ls.so(1)
    with pytest.raises(TypeError, match="n must be an integer"):
        ls.so(2.5)
    with pytest.raises(TypeError, match="n must be an integer"):
        ls.so(True)
    assert ls.so(np.int64(4)) is ls.so(4)
    with pytest.raises(ValueError, match="se"):
        ls.se(4)
    with pytest.raises(ValueError, match="so\\(3\\) only"):
        ls.so(4).to_vector3(np.zeros(6))


def test_structure_constant_shape_errors():
    for bad in (np.zeros((3, 3)), np.zeros((2, 3, 3)), np.zeros((0, 0, 0))):
        with pytest.raises(ValueError, match="structure_constants must have shape"):
            LieAlgebra(bad)
    C = np.zeros((2, 2, 2))
    C[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="structure_constants contains NaN"):
        LieAlgebra(C)
    with pytest.raises(TypeError, match="structure_constants"):
        LieAlgebra("abc")


def test_non_antisymmetric_constants_name_worst_triple():
    C = np.array(_sl2().structure_constants)
    C[1, 2, 0] += 0.5  # the worst violation: C[1, 2, 0] + C[2, 1, 0] = 0.5
    C[0, 1, 1] += 0.1
    with pytest.raises(ValueError, match="not antisymmetric") as info:
        LieAlgebra(C)
    assert "(1, 2, 0)" in str(info.value) or "(2, 1, 0)" in str(info.value)


def test_jacobi_violation_names_identity():
    rng = np.random.default_rng(0)
    R = rng.standard_normal((4, 4, 4))
    C = R - R.transpose(1, 0, 2)  # antisymmetric, generically not Lie
    with pytest.raises(ValueError, match="Jacobi identity") as info:
        LieAlgebra(C)
    msg = str(info.value)
    assert "[[e_i, e_j], e_k] + [[e_j, e_k], e_i] + [[e_k, e_i], e_j] = 0" in msg
    assert "worst at (i, j, k)" in msg


def test_representation_errors():
    C = np.asarray(ls.so(3).structure_constants)
    E = np.asarray(ls.so(3).representation)
    with pytest.raises(ValueError, match="representation must have shape"):
        LieAlgebra(C, representation=E[:2])
    with pytest.raises(ValueError, match="does not represent"):
        LieAlgebra(C, representation=-E)  # R -> -R maps the bracket to its negative
    with pytest.raises(ValueError, match="not faithful"):
        LieAlgebra(np.zeros((2, 2, 2)), representation=np.stack([np.eye(2), 2 * np.eye(2)]))
    with pytest.raises(ValueError, match="no matrix representation"):
        _sl2().hat(np.ones(3))


def test_subspace_errors():
    alg = ls.so(4)
    with pytest.raises(TypeError, match="algebra must be a LieAlgebra"):
        Subspace("so4", np.eye(6))
    with pytest.raises(TypeError, match="algebra must be a LieAlgebra"):
        Subspace.annihilator(None, np.eye(6))
    with pytest.raises(ValueError, match="rows must have shape"):
        Subspace(alg, np.eye(5))
    with pytest.raises(ValueError, match="covectors must have shape"):
        Subspace.annihilator(alg, np.eye(3))
    A = np.eye(6)[:3]
    with pytest.raises(ValueError, match="covectors are linearly dependent"):
        Subspace.annihilator(alg, np.vstack([A, A[0] + 2 * A[1]]))
    with pytest.raises(ValueError, match="covectors contains NaN"):
        Subspace.annihilator(alg, np.full(6, np.nan))
    D = ls.suslov_distribution(4)
    with pytest.raises(ValueError, match="metric must have shape"):
        D.projector(np.eye(5))
    with pytest.raises(TypeError, match="k must be a Subspace"):
        ls.is_symmetric_pair(np.eye(3), D)
    with pytest.raises(ValueError, match="same algebra"):
        ls.is_symmetric_pair(ls.suslov_distribution(3), Subspace(ls.se(2), np.eye(3)))
    with pytest.raises(TypeError, match="Subspace"):
        ls.Inertia.from_mass_tensor(np.ones(4)).restrict(np.eye(3))
    with pytest.raises(ValueError, match="lives in"):
        ls.Inertia.from_mass_tensor(np.ones(4)).restrict(ls.suslov_distribution(3))


def test_inertia_mass_tensor_must_give_K():
    """Beyond d = 64 the so(n) action goes through the mass tensor and never reads K: an I that is not K's
    was used silently (an error of 54 on n = 16)."""
    n = 16
    I = np.arange(1.0, n + 1.0)
    body = ls.Inertia.from_mass_tensor(I)
    x = np.random.default_rng(0).normal(size=n * (n - 1) // 2)
    same = ls.Inertia(ls.so(n), body.matrix, mass_tensor=I)
    assert np.max(np.abs(same(x) - body(x))) < 1e-12 and same.diagonal is not None
    with pytest.raises(ValueError, match="mass_tensor: K is not the inertia"):
        ls.Inertia(ls.so(n), body.matrix, mass_tensor=np.ones(n))
    with pytest.raises(ValueError, match="mass_tensor is a body on so\\(3\\), but the algebra is se\\(3\\)"):
        ls.Inertia(ls.se(3), np.eye(6), mass_tensor=np.ones(3))


def test_inertia_errors():
    alg = ls.so(3)
    with pytest.raises(ValueError, match="K must have shape"):
        ls.Inertia(alg, np.eye(4))
    with pytest.raises(ValueError, match="K must be symmetric"):
        ls.Inertia(alg, np.eye(3) + np.triu(np.ones((3, 3)), 1))
    with pytest.raises(ValueError, match="K must be positive definite.*smallest eigenvalue is -1"):
        ls.Inertia(alg, np.diag([1.0, 2.0, -1.0]))
    with pytest.raises(ValueError, match="K must be positive definite"):
        ls.Inertia(alg, np.diag([1.0, 0.0, 1.0]))
    with pytest.raises(TypeError, match="algebra must be a LieAlgebra"):
        ls.Inertia(np.eye(3), np.eye(3))
    # positive but without a finite inverse (subnormal): the velocities would be inf (accepted before)
    with pytest.raises(ValueError, match="K: the inertia's smallest eigenvalue 1e-320 has no finite inverse"):
        ls.Inertia(alg, 1e-320 * np.eye(3))
    with pytest.raises(ValueError, match=r"I \(the mass tensor\): the inertia's smallest eigenvalue 2e-320"):
        ls.Inertia.from_mass_tensor([1e-320, 1e-320, 1e-320])
    assert ls.Inertia.from_mass_tensor([1e-300, 2e-300, 3e-300]).inverse_matrix.max() == 1.0 / 3e-300
    with pytest.raises(ValueError, match="I \\(the mass tensor\\) must be symmetric"):
        ls.Inertia.from_mass_tensor(np.eye(3) + np.triu(np.ones((3, 3)), 1))
    with pytest.raises(ValueError, match="lambda_i \\+ lambda_j > 0") as info:
        ls.Inertia.from_mass_tensor([-1.0, 0.5, 3.0])
    assert "not positive definite" in str(info.value) and "-0.5" in str(info.value)
    for bad in (np.ones(1), np.ones((2, 3)), np.ones((2, 2, 2))):
        with pytest.raises(ValueError, match="I \\(the mass tensor\\) must be"):
            ls.Inertia.from_mass_tensor(bad)
    with pytest.raises(ValueError, match="J must be the principal moments"):
        ls.Inertia.from_principal_moments(np.ones(4))
    with pytest.raises(ValueError, match="J must be positive definite"):
        ls.Inertia.from_principal_moments([1.0, -1.0, 2.0])
    with pytest.raises(ValueError, match="principal_moments exist for so\\(3\\) only"):
        ls.Inertia.from_mass_tensor(np.ones(4)).principal_moments  # noqa: B018


# ---------------------------------------------------------------------------- known bugs (fail until fixed)
def test_hat_vee_reject_wrong_trailing_shape():
    """so(n).hat / vee must refuse coordinates or matrices of the wrong size.

    Today ``so(4).hat(np.ones(1))`` silently broadcasts the single value into all six entries,
    and ``so(4).vee`` of a 5x5 matrix silently returns six of its ten upper entries.
    """
    alg = ls.so(4)
    with pytest.raises(ValueError, match="x"):
        alg.hat(np.ones(1))
    with pytest.raises(ValueError, match="x"):
        alg.hat(np.ones((2, 5)))
    with pytest.raises(ValueError, match="X"):
        alg.vee(np.ones((5, 5)))
    with pytest.raises(ValueError, match="X"):
        alg.vee(np.ones((2, 3, 3)))


def test_projector_rejects_non_spd_metric():
    """A metric that is not symmetric positive definite has no K-orthogonal projector.

    Today a non-symmetric K silently yields a projector that is not self-adjoint for any metric.
    """
    D = ls.suslov_distribution(3)
    with pytest.raises(ValueError, match="metric"):
        D.projector(np.eye(3) + np.triu(np.ones((3, 3)), 1))
    with pytest.raises(ValueError, match="metric"):
        D.projector(-np.eye(3))


def test_structure_tests_do_not_change_with_the_scale():
    """is_subalgebra, is_symmetric_pair and Inertia.is_invariant are relative to the algebra's and the
    inertia's own scale: rescaled constants (an isomorphic algebra) or a small body give the same answers
    (with an absolute floor of 1 they said True for anything below ~1e-9)."""
    C3 = np.asarray(ls.so(3).structure_constants)
    C4 = np.asarray(ls.so(4).structure_constants)
    K6 = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    for s in (1.0, 1e-10, 1e8):
        a3 = ls.LieAlgebra(s * C3)
        assert a3.bracket_scale == s
        assert not Subspace(a3, np.eye(3)[:2]).is_subalgebra() and Subspace(a3, np.eye(3)[:1]).is_subalgebra()
        a4 = ls.LieAlgebra(s * C4)
        so3_in_so4 = Subspace(a4, np.eye(6)[[0, 1, 3]])  # E01, E02, E12: a subalgebra, not a symmetric p
        assert so3_in_so4.is_subalgebra() and not so3_in_so4.is_symmetric()
        fk = Subspace(a4, np.eye(6)[[2, 4, 5]])  # E03, E13, E23: Fedorov–Kozlov, p of (so(4), so(3))
        assert fk.is_symmetric() and ls.is_symmetric_pair(fk.complement(), fk)
        J = ls.Inertia(a4, s * (K6 + 0.1 * (np.eye(6, k=1) + np.eye(6, k=-1))))
        assert not J.is_invariant(fk) and ls.Inertia(a4, s * K6).is_invariant(fk)
    I4 = np.array([[1, 0.1, 0, 0.2], [0.1, 2, 0.1, 0.3], [0, 0.1, 3, 0.1], [0.2, 0.3, 0.1, 4.0]])
    forms = {ls.SuslovSystem(ls.Inertia.from_mass_tensor(s * I4)).model().form for s in (1.0, 1e-12, 1e6)}
    assert forms == {"reduced"}


def test_omega_outside_d_is_rejected_at_any_scale():
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0, 4.0])))
    for s in (1.0, 1e-10):
        with pytest.raises(ValueError, match="Omega0 is not in the constraint subspace"):
            ls.integrate(system, s * np.array([1.0, 0, 1, 0, 0, 0]), (0.0, 1.0), h=0.1)
        bad = s * ls.so(4).hat([0.0, 0, 1, 0, 0, 0]) + s * 1e-3 * np.eye(4)  # not skew, relative to its size
        with pytest.raises(ValueError, match="skew"):
            ls.integrate(system, bad, (0.0, 1.0), h=0.1)


def test_se_rejects_what_is_not_2_or_3():
    for bad in (2.0, "3", None, True):
        with pytest.raises(TypeError, match="se\\(n\\)"):
            ls.se(bad)
    with pytest.raises(ValueError, match="n = 4"):
        ls.se(4)
    assert ls.se(np.int64(3)).name == "se(3)"


def test_jacobi_is_checked_at_any_scale_and_so_n_is_bounded():
    """Constants of 1e160 overflowed the Jacobi residual to NaN (and passed), of 1e-200 underflowed it to 0;
    so(10^6) ran into a MemoryError (n^2 tables)."""
    r = np.random.default_rng(0).normal(size=(3, 3, 3))
    x = r - r.transpose(1, 0, 2)
    for scale in (1.0, 1e160, 1e-200):
        with pytest.raises(ValueError, match="Jacobi"):
            ls.LieAlgebra(scale * x)
    assert ls.LieAlgebra(1e160 * ls.so(3).structure_constants).dim == 3
    with pytest.raises(ValueError, match="largest size"):
        ls.so(10**6)


def test_batch_methods_name_a_wrong_shape():
    """Subspace, Inertia, se(n) and so(3)'s vector form raised numpy's IndexError or broadcasting messages."""
    D = ls.Subspace(ls.so(3), np.eye(3)[:2])
    J = ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0]))
    for call, says in ((lambda: D.contains([1.0, 2.0]), "x must have shape"),
                       (lambda: D.project([1.0, 2.0]), "x must have shape"),
                       (lambda: D.from_coordinates([1.0, 2.0, 3.0]), "xi must have shape"),
                       (lambda: J([1.0, 2.0]), "x must have shape"), (lambda: J.inverse([1.0]), "m must have shape"),
                       (lambda: ls.se(3).hat(np.ones(5)), "x must have shape"),
                       (lambda: ls.se(3).vee(np.ones((3, 3))), "X must have shape"),
                       (lambda: ls.se(3).bracket(np.ones(6), np.ones(5)), "y must have shape"),
                       (lambda: ls.so(3).to_vector3([1.0, 2.0]), "x must have shape")):
        with pytest.raises(ValueError, match=says):
            call()
    with pytest.raises(TypeError, match="name must be a string"):
        ls.LieAlgebra(ls.so(3).structure_constants, name=5)


def test_a_3x3_omega_near_a_skew_matrix_is_refused_on_so3_not_read_as_three_vectors():
    """On so(3) d = m = 3: a (3, 3) array off skew by 1e-11 was read as three coordinate vectors (energy gave
    three values; integrate said 'not in D'); on so(4) the same defect is a clear error."""
    from liesuslov.algebra import omega_coordinates
    alg = ls.so(3)
    X = alg.hat(np.array([0.3, -0.2, 0.5]))
    np.testing.assert_array_equal(omega_coordinates(alg, X + 1e-14 * np.eye(3)), alg.vee(X + 1e-14 * np.eye(3)))
    near = X.copy()
    near[0, 1] += 1e-11
    with pytest.raises(ValueError, match=r"Omega of shape \(3, 3\).*ambiguous"):
        omega_coordinates(alg, near)
    vectors = np.arange(9.0).reshape(3, 3)
    np.testing.assert_array_equal(omega_coordinates(alg, vectors), vectors)
    free = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])), constraints="none")
    with pytest.raises(ValueError, match="Omega0 of shape"):
        ls.integrate(free, near, (0.0, 1.0), h=0.1)


def test_hat_and_vee_refuse_complex_input():
    """numpy dropped the imaginary part with a ComplexWarning (an audit); float32 and integers still convert."""
    for call in (lambda: ls.so(3).hat([1j, 2.0, 3.0]), lambda: ls.so(4).vee(1j * np.eye(4)),
                 lambda: ls.se(2).vee(1j * np.eye(3)), lambda: ls.se(2).hat([1j, 0.0, 0.0])):
        with pytest.raises(TypeError, match="must be real numbers"):
            call()
    assert ls.so(3).hat(np.float32([1.0, 2.0, 3.0])).dtype == np.float64
    assert np.array_equal(ls.so(3).vee(ls.so(3).hat([1, 2, 3])), [1.0, 2.0, 3.0])


@pytest.mark.parametrize("alg", [ls.so(4), ls.se(2)], ids=["so4", "se2"])
def test_binary_operations_name_batches_that_do_not_broadcast(alg):
    """bracket/coad/pairing of batches (2,) and (3,) gave numpy's "remapped shapes" message naming neither argument."""
    d = alg.dim
    with pytest.raises(ValueError, match=rf"x and y must have batch shapes that broadcast.*\(2, {d}\) and \(3, {d}\)"):
        alg.bracket(np.ones((2, d)), np.ones((3, d)))
    with pytest.raises(ValueError, match="x and m must have batch shapes"):
        alg.coad(np.ones((2, d)), np.ones((3, d)))
    # broadcasting batches still work, and agree with the element-wise result
    x, y = np.random.default_rng(0).standard_normal((2, 3, d))
    out = alg.bracket(x[:, None, :], y[None, :, :])
    assert out.shape == (3, 3, d)
    assert np.allclose(out[1, 2], alg.bracket(x[1], y[2]), rtol=0, atol=1e-15)


def test_so_helpers_refuse_wrong_sizes():
    """Read silently before: pairing of 7-vectors on so(4) summed them (7.0); hat3 of a 4-vector dropped its last
    entry; vee3 of a 4x4 matrix read three of its entries."""
    from liesuslov.algebra import hat3, pairing, vee3, wedge

    cases = [(lambda: ls.so(4).pairing(np.ones(7), np.ones(7)), r"x must have shape \(\.\.\., 6\) for so\(4\)"),
             (lambda: ls.so(4).pairing(np.ones((2, 6)), np.ones((3, 6))), "x and y must have batch shapes"),
             (lambda: hat3(np.ones(4)), r"w must have shape \(\.\.\., 3\)"),
             (lambda: vee3(np.eye(4)), r"W must have shape \(\.\.\., 3, 3\)"),
             (lambda: wedge(np.ones(3), np.ones(4)), r"y must have shape \(\.\.\., 3\)"),
             (lambda: wedge(np.ones((2, 3)), np.ones((3, 3))), "x and y must have batch shapes"),
             (lambda: pairing(np.eye(3), np.eye(4)), r"B must have shape \(\.\.\., 3, 3\)"),
             (lambda: pairing(np.ones(3), np.ones(3)), r"A must have shape \(\.\.\., n, n\)")]
    for call, message in cases:
        with pytest.raises(ValueError, match=message):
            call()
    w = np.array([0.3, -1.2, 0.7])
    assert np.array_equal(vee3(hat3(w)), w)
    assert np.isclose(pairing(hat3(w), hat3(w)), w @ w, rtol=1e-15)


def test_membership_of_huge_vectors_is_decided_without_overflow():
    """Above |x| ~ 1e154 the squares overflowed and inf <= inf accepted any vector: integrate took an Omega0 off
    D and dropped its off-D part (an audit). The test is relative: the scale does not change the answer."""
    D = ls.suslov_distribution(3)
    off, on = np.array([0.5, 1.0, 0.0]), np.array([0.0, 1.0, 0.3])
    for scale in (1.0, 1e150, 1e160, 1e300):
        assert not D.contains(off * scale) and D.contains(on * scale)
        assert np.array_equal(D.contains(np.stack([off, on]) * scale), [False, True])
        assert np.isclose(D.distance(off * scale), 0.5 * scale, rtol=1e-15)
    D6 = ls.suslov_distribution(6)  # a batch of rows through the basis (not the single-vector paths)
    x = np.zeros((3, D6.algebra.dim))
    x[:, D6.algebra.index(0, 5)] = 1e200
    x[1, D6.algebra.index(0, 1)] = 1e199
    assert np.array_equal(D6.contains(x), [True, False, True])
    assert not D.contains([np.inf, 1.0, 0.0]) and not D.contains([np.nan, 1.0, 0.0])
    D17 = ls.suslov_distribution(17)  # one vector longer than the projector path takes (d = 136)
    y = np.zeros(D17.algebra.dim)
    y[D17.algebra.index(0, 16)] = 1e160
    assert D17.contains(y)
    y[D17.algebra.index(0, 1)] = 1e160
    assert not D17.contains(y)
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])))
    with pytest.raises(ValueError, match=r"not in the constraint subspace D \(distance 5e\+159\)"):
        ls.integrate(system, off * 1e160, (0.0, 1e-160), h=1e-161)
