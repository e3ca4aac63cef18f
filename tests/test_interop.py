"""Tests of liesuslov.interop against geomstats 2.8.0 itself (exp, brackets, rotation vectors, spheres)."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import liesuslov as ls
from liesuslov import interop

# geomstats is an optional extra (it pins numpy < 2.4): the tests that call it are skipped without it
try:
    import importlib.util

    HAS_GEOMSTATS = importlib.util.find_spec("geomstats") is not None
except ValueError:  # pragma: no cover - a broken install
    HAS_GEOMSTATS = False
needs_geomstats = pytest.mark.skipif(not HAS_GEOMSTATS, reason="geomstats not installed: pip install "
                                     "'liesuslov[geomstats]'")

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = settings(max_examples=25, deadline=None)
FLOATS = st.floats(-2.0, 2.0, allow_nan=False, allow_infinity=False, width=64)
BATCH = hnp.array_shapes(min_dims=0, max_dims=2, min_side=1, max_side=3)

# geomstats' so(n) basis in our coordinates (row k = our coordinates of its k-th basis matrix):
# n = 2: [[0, -1], [1, 0]] = -E_12; n = 3: hat(e_1) = -E_23, hat(e_2) = E_13, hat(e_3) = -E_12.
EXPLICIT_BASIS = {2: np.array([[-1.0]]),
                  3: np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])}


def _explicit_basis(n: int) -> np.ndarray:
    return EXPLICIT_BASIS.get(n, np.eye(n * (n - 1) // 2))


def _run(code: str, env_backend: str | None = None) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter with the repository on the path."""
    env = {k: v for k, v in os.environ.items() if k != "GEOMSTATS_BACKEND"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    if env_backend is not None:
        env["GEOMSTATS_BACKEND"] = env_backend
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=120)


def _rotations(n: int, shape: tuple[int, ...], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    alg = ls.so(n)
    return scipy.linalg.expm(alg.hat(rng.standard_normal(shape + (alg.dim,))).reshape((-1, n, n))).reshape(
        shape + (n, n))


# ---------------------------------------------------------------------------- import hygiene
def test_import_liesuslov_does_not_import_geomstats():
    res = _run("""
        import logging, sys
        level = logging.getLogger().level
        import liesuslov, liesuslov.interop
        assert 'geomstats' not in sys.modules, sorted(m for m in sys.modules if 'geomstats' in m)
        assert logging.getLogger().level == level
        assert logging.getLogger().handlers == []
        print('ok')
    """)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "ok"


@needs_geomstats
def test_geomstats_import_preserves_user_logging():
    res = _run("""
        import io, logging, os
        stream = io.StringIO()
        handler = logging.StreamHandler(stream)
        root = logging.getLogger()
        root.addHandler(handler)
        root.setLevel(logging.ERROR)
        from liesuslov import interop
        gs = interop.import_geomstats()
        interop.geomstats_special_orthogonal(3)
        interop.geomstats_hypersphere(4)
        interop.algebra_to_geomstats([1.0, 2.0, 3.0])
        assert root.level == logging.ERROR, root.level
        assert root.handlers == [handler], root.handlers
        logging.info('must not appear')
        logging.warning('must not appear either')
        assert stream.getvalue() == '', stream.getvalue()
        assert os.environ['GEOMSTATS_BACKEND'] == 'numpy'
        assert gs.__version__ == '2.8.0'
        print('ok')
    """)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "ok"
    assert "INFO" not in res.stderr and "must not appear" not in res.stderr


@needs_geomstats
def test_geomstats_import_without_user_logging_adds_no_handler():
    res = _run("""
        import logging
        from liesuslov import interop
        interop.import_geomstats()
        assert logging.getLogger().level == logging.WARNING
        assert logging.getLogger().handlers == []
        print('ok')
    """)
    assert res.returncode == 0, res.stderr


def test_non_numpy_backend_is_refused():
    res = _run("""
        import sys
        from liesuslov import interop
        try:
            interop.rotation_vector_from_matrix([[1.0, 0.0], [0.0, 1.0]])
        except RuntimeError as exc:
            print(exc)
        assert 'geomstats' not in sys.modules
    """, env_backend="pytorch")
    assert res.returncode == 0, res.stderr
    assert "'pytorch'" in res.stdout and "GEOMSTATS_BACKEND=numpy" in res.stdout


@needs_geomstats
def test_in_process_calls_leave_logging_alone():
    root = logging.getLogger()
    level, handlers = root.level, root.handlers[:]
    interop.import_geomstats()
    interop.geomstats_skew_symmetric_matrices(4)
    assert root.level == level
    assert root.handlers == handlers


# ---------------------------------------------------------------------------- so(n) coordinates
@needs_geomstats
@pytest.mark.parametrize("n", range(2, 9))
def test_basis_change_is_the_explicit_signed_permutation(n):
    T = interop.geomstats_basis(n)
    np.testing.assert_array_equal(T, _explicit_basis(n))
    gs_basis = np.asarray(interop.geomstats_skew_symmetric_matrices(n).basis)
    np.testing.assert_array_equal(ls.so(n).hat(T), gs_basis)
    with pytest.raises(ValueError):
        T[0, 0] = 2.0  # read-only


@needs_geomstats
def test_so3_geomstats_coordinates_are_the_vector_form():
    x = np.array([[1.0, 2.0, 3.0], [-0.5, 0.0, 4.0]])
    np.testing.assert_array_equal(interop.algebra_to_geomstats(x), ls.so(3).to_vector3(x))
    np.testing.assert_array_equal(interop.algebra_to_geomstats([0.7]), [-0.7])


@needs_geomstats
@SETTINGS
@given(n=st.integers(2, 7), shape=BATCH, data=st.data())
def test_algebra_round_trip_and_matrices(n, shape, data):
    alg = ls.so(n)
    gsalg = interop.geomstats_skew_symmetric_matrices(n)
    x = data.draw(hnp.arrays(np.float64, shape + (alg.dim,), elements=FLOATS))
    c = interop.algebra_to_geomstats(x)
    assert c.shape == x.shape
    np.testing.assert_array_equal(interop.algebra_from_geomstats(c), x)
    # same matrix on both sides (geomstats' matrix_representation handles any batch shape)
    np.testing.assert_allclose(gsalg.matrix_representation(c), alg.hat(x), atol=1e-15)
    flat = alg.hat(x).reshape((-1, n, n))  # its n = 3 basis_representation only takes one batch axis
    np.testing.assert_allclose(gsalg.basis_representation(flat).reshape(c.shape), c, atol=1e-15)


@needs_geomstats
@SETTINGS
@given(n=st.integers(2, 7), data=st.data())
def test_bracket_against_geomstats(n, data):
    alg = ls.so(n)
    gsalg = interop.geomstats_skew_symmetric_matrices(n)
    x, y = (data.draw(hnp.arrays(np.float64, (4, alg.dim), elements=FLOATS)) for _ in range(2))
    cx, cy = interop.algebra_to_geomstats(x), interop.algebra_to_geomstats(y)
    gs_br = gsalg.bracket(gsalg.matrix_representation(cx), gsalg.matrix_representation(cy))
    c_xy = interop.algebra_to_geomstats(alg.bracket(x, y))
    np.testing.assert_allclose(gs_br, alg.hat(alg.bracket(x, y)), atol=1e-12)
    np.testing.assert_allclose(gsalg.basis_representation(gs_br), c_xy, atol=1e-12)
    if n == 3:  # geomstats' SO(3) in vector form brackets rotation vectors by the cross product
        so3v = interop.geomstats_special_orthogonal(3, point_type="vector")
        np.testing.assert_allclose(so3v.lie_bracket(cx, cy), c_xy, atol=1e-12)


# ---------------------------------------------------------------------------- exp and SO(n)
@needs_geomstats
@SETTINGS
@given(n=st.integers(2, 7), shape=BATCH, seed=st.integers(0, 2**32 - 1))
def test_group_exp_against_scipy(n, shape, seed):
    alg = ls.so(n)
    group = interop.geomstats_special_orthogonal(n)
    x = 1.5 * np.random.default_rng(seed).standard_normal(shape + (alg.dim,))
    X = alg.hat(x)
    ours = scipy.linalg.expm(X.reshape((-1, n, n))).reshape(X.shape)
    theirs = np.asarray(group.exp(X.reshape((-1, n, n)))).reshape(X.shape)
    np.testing.assert_allclose(theirs, ours, atol=1e-11)
    g = interop.rotation_to_geomstats(ours)
    assert np.all(group.belongs(g.reshape((-1, n, n))))
    np.testing.assert_array_equal(interop.rotation_from_geomstats(theirs), theirs)


@needs_geomstats
@pytest.mark.parametrize("n", [2, 3])
@pytest.mark.parametrize("shape", [(), (5,), (2, 3)])
def test_rotation_vectors(n, shape):
    alg = ls.so(n)
    rng = np.random.default_rng(n)
    x = rng.standard_normal(shape + (alg.dim,))
    x *= 2.5 / np.maximum(1.0, np.linalg.norm(x, axis=-1, keepdims=True))  # angle < pi: log is unique
    g = scipy.linalg.expm(alg.hat(x).reshape((-1, n, n))).reshape(shape + (n, n))
    r = interop.rotation_vector_from_matrix(g)
    assert r.shape == shape + (alg.dim,)
    np.testing.assert_allclose(r, interop.algebra_to_geomstats(x), atol=1e-10)  # r = coordinates of log g
    np.testing.assert_allclose(interop.matrix_from_rotation_vector(r), g, atol=1e-12)
    if n == 3:
        w = ls.so(3).to_vector3(x)
        np.testing.assert_allclose(r, w, atol=1e-10)
        np.testing.assert_allclose(scipy.linalg.expm(ls.hat3(w).reshape(-1, 3, 3)).reshape(g.shape), g,
                                   atol=1e-12)
    else:
        theta = r[..., 0]
        want = np.stack([np.stack([np.cos(theta), -np.sin(theta)], -1),
                         np.stack([np.sin(theta), np.cos(theta)], -1)], -2)
        np.testing.assert_allclose(g, want, atol=1e-12)


@needs_geomstats
def test_rotation_vectors_empty_batch():
    assert interop.rotation_vector_from_matrix(np.zeros((0, 3, 3))).shape == (0, 3)
    assert interop.matrix_from_rotation_vector(np.zeros((0, 2, 1))).shape == (0, 2, 2, 2)


# ---------------------------------------------------------------------------- spheres
@needs_geomstats
@pytest.mark.parametrize("n", range(2, 8))
def test_sphere_points(n):
    sphere = interop.geomstats_hypersphere(n)
    assert sphere.dim == n - 1
    rng = np.random.default_rng(n)
    v = rng.standard_normal((2, 3, n))
    Gamma = v / np.linalg.norm(v, axis=-1, keepdims=True)
    pts = interop.sphere_to_geomstats(Gamma)
    np.testing.assert_array_equal(pts, Gamma)
    assert np.all(sphere.belongs(pts.reshape(-1, n)))
    theirs = np.asarray(sphere.random_uniform(4))
    np.testing.assert_array_equal(interop.sphere_from_geomstats(theirs), theirs)
    # Gamma = g^T gamma stays on the sphere for a rotation g
    g = _rotations(n, (2, 3), n)
    body = np.einsum("...ji,...j->...i", g, Gamma)
    assert np.all(sphere.belongs(interop.sphere_to_geomstats(body).reshape(-1, n)))


# ---------------------------------------------------------------------------- validation
def test_rotation_validation():
    g = _rotations(4, (3,), 0)
    with pytest.raises(ValueError, match=r"g is not in SO\(4\): max \|g\^T g - I\|"):
        interop.rotation_to_geomstats(g * 1.01)
    refl = g.copy()
    refl[..., 0] *= -1
    with pytest.raises(ValueError, match="g is not in SO.*determinant"):
        interop.rotation_to_geomstats(refl)
    with pytest.raises(ValueError, match="point is not in SO"):
        interop.rotation_from_geomstats(refl)
    with pytest.raises(ValueError, match=r"g must have shape \(\.\.\., n, n\)"):
        interop.rotation_to_geomstats(np.eye(3)[:2])
    with pytest.raises(ValueError, match="g contains NaN"):
        interop.rotation_to_geomstats(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match=r"SO\(2\) or SO\(3\)"):
        interop.rotation_vector_from_matrix(g)
    with pytest.raises(ValueError, match="g is not in SO"):
        interop.rotation_vector_from_matrix(2 * np.eye(3))
    # a tolerance can be given
    interop.rotation_to_geomstats(g * (1 + 1e-7), atol=1e-6)


def test_sphere_validation():
    with pytest.raises(ValueError, match="Gamma must be unit vectors"):
        interop.sphere_to_geomstats([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    with pytest.raises(ValueError, match="point must be unit vectors"):
        interop.sphere_from_geomstats([0.0, 0.0, 0.5])
    with pytest.raises(ValueError, match=r"Gamma must have shape \(\.\.\., n\) with n >= 2"):
        interop.sphere_to_geomstats([1.0])
    with pytest.raises(ValueError, match="Gamma must have at least 1"):
        interop.sphere_to_geomstats(1.0)


def test_algebra_and_vector_validation():
    with pytest.raises(ValueError, match=r"x must have shape \(\.\.\., n \(n - 1\) / 2\)"):
        interop.algebra_to_geomstats(np.zeros(4))
    with pytest.raises(ValueError, match="c must have shape"):
        interop.algebra_from_geomstats(np.zeros((2, 5)))
    with pytest.raises(ValueError, match=r"r must have shape \(\.\.\., 1\)"):
        interop.matrix_from_rotation_vector(np.zeros(2))
    with pytest.raises(ValueError, match="n must be >= 2"):
        interop.geomstats_hypersphere(1)
    with pytest.raises(TypeError, match="n must be an integer"):
        interop.geomstats_basis(2.5)


def test_hypersphere_takes_n_or_geomstats_dim_and_refuses_a_mismatch():
    with pytest.raises(ValueError, match=r"disagree: dim must be n - 1"):
        interop.geomstats_hypersphere(3, dim=3)
    with pytest.raises(TypeError, match="ambient dimension n"):
        interop.geomstats_hypersphere()
    with pytest.raises(ValueError, match="dim .* must be an integer >= 1"):
        interop.geomstats_hypersphere(dim=0)


@needs_geomstats
@pytest.mark.parametrize("n", [2, 3, 5])
def test_hypersphere_by_dim_is_the_same_sphere(n):
    for sphere in (interop.geomstats_hypersphere(dim=n - 1), interop.geomstats_hypersphere(n, dim=n - 1)):
        assert sphere.dim == n - 1
        assert np.all(sphere.belongs(np.eye(n)))


def test_missing_geomstats_names_the_extra():
    res = _run("""
        import sys
        sys.modules['geomstats'] = None  # as if it were not installed
        from liesuslov import interop
        try:
            interop.geomstats_hypersphere(3)
        except ImportError as exc:
            print(exc)
    """)
    assert res.returncode == 0, res.stderr
    assert "pip install 'liesuslov[geomstats]'" in res.stdout
