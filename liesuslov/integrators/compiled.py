"""The field of a model as the compiled kernel reads it: :func:`compile_plan` (pure numpy, no numba import).

Nothing about the mechanics is re-derived. The reduced field of every built-in scene (zero, linear and
quadratic potentials, the gyroscopic term; any form) is a polynomial of degree <= 2 in ``z = (xi, Gamma)``
jointly; :func:`compile_plan` reads its coefficients off the numpy model by probing ``model.xi_dot`` (at 0,
at ``±e_i`` and at ``e_i + e_j``: ``f(z) = c + L z + z^T Q z`` by polarisation), drops the coefficients that
are zero to rounding, keeps the rest as sparse (COO) lists so that a field evaluation costs one
multiply-add per nonzero (Klebsh–Tisserand in SO(n): n - 1 terms), and then *verifies* the polynomial
against ``model.xi_dot`` at random points (relative 1e-12). ``Omega(xi)`` is linear: its basis tensor is
read off ``model.omega_matrix`` the same way (the upper triangle on so(n), every entry on a general matrix
algebra such as se(2), se(3)). A scene whose potential is not a built-in polynomial one (a user
:class:`~liesuslov.Potential`, a :class:`~liesuslov.FamilyPotential`) or whose field fails the check runs
on numpy (:class:`NotCompilable` says why).

The compiled solve itself — time loop, stepper, controller, dense output, events — is
:mod:`liesuslov.integrators.kernel` (which imports numba).
"""

from __future__ import annotations

import importlib.util
import warnings
import weakref
from dataclasses import dataclass

import numpy as np

__all__ = ["CompilePlan", "NotCompilable", "compile_plan", "numba_available"]

MODES = {"none": 0, "gamma": 1, "g": 2}
CHART_CODES = {"exp": 0, "cayley": 1}

# Relative agreement the probed polynomial must reach against model.xi_dot on random points.
_VERIFY_RTOL = 1e-12
# A probed coefficient below this many ulps of the values it was computed from is zero to rounding.
_ZERO_ULPS = 16.0


class NotCompilable(ValueError):
    """The scene cannot run on the compiled kernel; the message says why (it then runs on numpy)."""


def numba_available() -> bool:
    """Whether numba is installed (the optional extra ``liesuslov[fast]``); does not import it."""
    return importlib.util.find_spec("numba") is not None


# ====================================================================================== the plan
@dataclass(frozen=True)
class CompilePlan:
    """What the kernel needs to know about a model: its field and ``Omega`` as sparse coefficient lists.

    Attributes
    ----------
    k : int
        Dimension of ``xi``.
    n : int
        Size of the group matrices (0 when ``mode == "none"``).
    has_gamma : bool
        Whether the field reads ``Gamma`` (``z = (xi, Gamma)``, of length ``k + n``; else ``z = xi``).
    field_index : ndarray of int64, shape (p, 3)
        Rows ``(o, i, j)``: the term ``field_value[t] * z_i * z_j`` is added to output ``o``; ``i = j = -1``
        marks a constant, ``j = -1`` a linear term.
    field_value : ndarray, shape (p,)
    omega_index : ndarray of int64, shape (q, 3)
        Rows ``(a, r, c)`` with ``r < c``: ``Omega[r, c] += omega_value[t] * xi_a``; ``Omega[c, r] = -Omega[r, c]``.
    omega_value : ndarray, shape (q,)
    """

    k: int
    n: int
    has_gamma: bool
    field_index: np.ndarray
    field_value: np.ndarray
    omega_index: np.ndarray
    omega_value: np.ndarray

    def field(self, xi: np.ndarray, Gamma: np.ndarray | None) -> np.ndarray:
        """Evaluate the probed polynomial with numpy (for checks): (P, k), (P, n) -> (P, k)."""
        z = xi if not self.has_gamma else np.concatenate([xi, Gamma], axis=-1)
        return _eval_poly(self.field_index, self.field_value, z, self.k)[0]


_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def compile_plan(model, mode: str, chart: str | None, *, skew: bool | None = None, omega: bool = True) -> CompilePlan:
    """Check that ``model`` runs on the compiled kernel in ``mode`` / ``chart`` and extract its coefficients.

    Parameters
    ----------
    model : Model
        A model of :mod:`liesuslov.mechanics` (or an object with its protocol).
    mode : {"g", "gamma", "none"}
        As in :class:`~liesuslov.integrators.rkmk.RKMKStepper`.
    chart : {"exp", "cayley"} or None
        Ignored when ``mode == "none"``.
    skew : bool, optional
        The algebra is so(n) (Omega skew: the upper triangle is stored); False: a general matrix algebra
        (se(2), se(3): every entry is stored). Default: whether the algebra's name starts with "so(".
    omega : bool
        Probe ``Omega(xi)`` (False for the low-rank kind, which writes Omega = u e_n^T - e_n u^T itself and
        would not fit the (k, n, n) basis tensor in memory at large n).

    Returns
    -------
    CompilePlan
        Cached per model (the probing costs a few numpy calls).

    Raises
    ------
    NotCompilable
        With the reason: a group part on an algebra other than so(n), an unknown chart, a potential that
        is not a built-in polynomial one, a field that is not a verified polynomial of degree <= 2 in
        ``(xi, Gamma)``, an ``Omega(xi)`` that is not linear.

    Notes
    -----
    The potential's ``kind`` is checked when the model has a ``system`` (a user callable never
    qualifies, even where it happens to be polynomial); a bare protocol object is judged by the
    verification alone.
    """
    if mode not in MODES:
        raise NotCompilable(f"mode must be one of {sorted(MODES)}, got {mode!r}")
    if mode != "none":
        if chart not in CHART_CODES:
            raise NotCompilable(f"the compiled kernel knows the charts {sorted(CHART_CODES)}, got {chart!r}")
        name = getattr(getattr(model, "algebra", None), "name", "?")
        if skew is None:
            skew = name.startswith("so(")
        if not model.n or model.n < 2:
            raise NotCompilable(f"the compiled kernel needs a matrix representation; {name} runs on numpy")
    system = getattr(model, "system", None)
    pot = getattr(system, "potential", None)
    kind = getattr(pot, "kind", "zero")
    if kind not in ("zero", "linear", "quadratic"):
        raise NotCompilable(f"the potential {pot!r} (kind {kind!r}) is not a built-in polynomial potential "
                            "(zero, linear, quadratic): its field is not compiled")
    cache = _model_cache(model)
    key = ("plan", mode, chart if mode != "none" else None, skew, omega)
    if key not in cache:  # one CompilePlan per model and use: the kernel's packed constants are keyed by it
        cache[key] = _compile_plan(model, cache, mode, skew, omega)
    return cache[key]


def _compile_plan(model, cache: dict, mode: str, skew: bool | None, omega: bool) -> CompilePlan:
    """The CompilePlan of :func:`compile_plan` (whose checks passed), from the model's probed coefficients."""
    field_index, field_value = _cached(cache, "field", _probe_field, model)
    n = 0
    omega_index, omega_value = np.zeros((0, 3), np.int64), np.zeros(0)
    if mode != "none":
        if omega:
            probe = _probe_omega if skew else _probe_omega_general
            omega_index, omega_value = _cached(cache, "omega" if skew else "omega_general", probe, model)
        n = int(model.n)
    return CompilePlan(int(model.k), n, bool(model.has_gamma), field_index, field_value, omega_index,
                       omega_value)


def _model_cache(model) -> dict:
    """The dict of what was derived from ``model`` (probed coefficients, packed constants)."""
    try:
        return _PLANS[model]  # (WeakKeyDictionary.setdefault is Python code: ~0.7 µs more on every call)
    except KeyError:
        return _PLANS.setdefault(model, {})
    except TypeError:  # not weak-referenceable or not hashable: no cache
        return {}


def _cached(cache: dict, key: str, probe, model):
    """``probe(model)``, or its NotCompilable, computed once per model."""
    if key not in cache:
        try:
            cache[key] = probe(model)
        except NotCompilable as exc:
            # kept as a fresh exception: the raised one's traceback holds the caller's frames, and through
            # them the model, the weak key of the cache (a new model per call then leaked the caller's data)
            cache[key] = NotCompilable(str(exc))
    out = cache[key]
    if isinstance(out, NotCompilable):
        raise NotCompilable(str(out))
    return out


def _quiet_call(fn, *args):
    """Call a model map on probe points, turning warnings and errors into :class:`NotCompilable`."""
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            out = np.asarray(fn(*args), dtype=float)
    except Exception as exc:  # a user callable may fail anywhere off its domain
        raise NotCompilable(f"evaluating the model at probe points failed ({type(exc).__name__}: {exc})") from exc
    return out


def _eval_poly(index: np.ndarray, value: np.ndarray, z: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The COO polynomial and the same with absolute values (a rounding scale) at points z (P, N)."""
    P = z.shape[0]
    zz = np.concatenate([z, np.ones((P, 1))], axis=1)  # index -1 reads the trailing 1
    terms = value * zz[:, index[:, 1]] * zz[:, index[:, 2]]
    out = np.zeros((P, k))
    mag = np.zeros((P, k))
    for t, o in enumerate(index[:, 0]):
        out[:, o] += terms[:, t]
        mag[:, o] += np.abs(terms[:, t])
    return out, mag


def _probe_field(model) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of ``model.xi_dot`` as a polynomial of degree <= 2 in z = (xi, Gamma), verified."""
    k = int(model.k)
    has_gamma = bool(model.has_gamma)
    nz = k + (int(model.n) if has_gamma else 0)
    eye = np.eye(nz)
    iu, ju = np.triu_indices(nz, 1)
    pts = np.concatenate([np.zeros((1, nz)), eye, -eye, eye[iu] + eye[ju]])

    def f(z):
        z = np.ascontiguousarray(z)
        G = np.ascontiguousarray(z[:, k:]) if has_gamma else None
        out = _quiet_call(model.xi_dot, np.ascontiguousarray(z[:, :k]), G)
        if out.shape != (z.shape[0], k):
            raise NotCompilable(f"model.xi_dot returned shape {out.shape} for {z.shape[0]} points, "
                                f"expected {(z.shape[0], k)}")
        return out

    F = f(pts)
    if not np.all(np.isfinite(F)):
        raise NotCompilable("the field is not finite at the probe points (0, ±e_i, e_i + e_j): not a polynomial")
    eps = np.finfo(float).eps
    c0 = F[0]
    Fp, Fm, Fij = F[1:1 + nz], F[1 + nz:1 + 2 * nz], F[1 + 2 * nz:]
    lin = 0.5 * (Fp - Fm)  # (nz, k): lin[i] is the coefficient vector of z_i
    lin_mag = 0.5 * (np.abs(Fp) + np.abs(Fm))
    dia = 0.5 * (Fp + Fm) - c0  # z_i^2
    dia_mag = lin_mag + np.abs(c0)
    off = Fij - c0 - lin[iu] - lin[ju] - dia[iu] - dia[ju]  # z_i z_j, i < j
    off_mag = (np.abs(Fij) + np.abs(c0) + np.abs(lin[iu]) + np.abs(lin[ju]) + np.abs(dia[iu])
               + np.abs(dia[ju]))
    rows: list[tuple[int, int, int]] = []
    vals: list[float] = []

    def keep(coef, mag, i, j):
        for o in range(k):
            if abs(coef[o]) > _ZERO_ULPS * eps * mag[o]:
                rows.append((o, i, j))
                vals.append(float(coef[o]))

    keep(c0, np.zeros(k), -1, -1)  # constants are probed exactly
    for i in range(nz):
        keep(lin[i], lin_mag[i], i, -1)
    for i in range(nz):
        keep(dia[i], dia_mag[i], i, i)
    for t in range(iu.size):
        keep(off[t], off_mag[t], int(iu[t]), int(ju[t]))
    index = np.array(rows, dtype=np.int64).reshape(-1, 3)
    value = np.array(vals, dtype=float)
    # verify on random points: general ones, and unit Gamma (the phase space)
    rng = np.random.default_rng(20030101)
    Z = rng.standard_normal((12, nz))
    if has_gamma:
        Z[6:, k:] /= np.linalg.norm(Z[6:, k:], axis=1, keepdims=True)
    true = f(Z)
    poly, mag = _eval_poly(index, value, Z, k)
    bound = _VERIFY_RTOL * np.maximum(mag, np.abs(true)).max(axis=1, keepdims=True)
    bad = ~(np.abs(true - poly) <= bound)  # NaN counts as bad
    if np.any(bad):
        dev = float(np.nanmax(np.abs(true - poly) / np.where(bound > 0, bound / _VERIFY_RTOL, 1.0)))
        raise NotCompilable(f"the field xi_dot(xi, Gamma) is not a polynomial of degree <= 2 in (xi, Gamma) "
                            f"(relative deviation {dev:.2g} of the probed polynomial at random points)")
    return index, value


def _probe_omega(model) -> tuple[np.ndarray, np.ndarray]:
    """Basis tensor of the linear map ``Omega(xi)`` (upper triangle, COO), verified and skew."""
    k, n = int(model.k), int(model.n)
    W = _quiet_call(model.omega_matrix, np.eye(k))
    if W.shape != (k, n, n) or not np.all(np.isfinite(W)):
        raise NotCompilable(f"model.omega_matrix gave shape {W.shape} (or non-finite values) on the basis, "
                            f"expected {(k, n, n)}")
    if not np.array_equal(W, -np.swapaxes(W, 1, 2)):
        raise NotCompilable("model.omega_matrix is not skew-symmetric: the compiled kernel needs so(n)")
    rng = np.random.default_rng(7)
    x = rng.standard_normal((4, k))
    Om = _quiet_call(model.omega_matrix, x)
    ref = np.einsum("pa,arc->prc", x, W)
    scale = np.einsum("pa,arc->prc", np.abs(x), np.abs(W)).max() + 1e-300
    if Om.shape != ref.shape or not np.all(np.abs(Om - ref) <= 1e-13 * scale):
        raise NotCompilable("model.omega_matrix is not linear in xi")
    a, r, c = np.nonzero(W * np.triu(np.ones((n, n)), 1))
    index = np.stack([a, r, c], axis=1).astype(np.int64).reshape(-1, 3)
    return index, np.ascontiguousarray(W[a, r, c], dtype=float)


def _probe_omega_general(model) -> tuple[np.ndarray, np.ndarray]:
    """Basis tensor of the linear map ``Omega(xi)`` on a general matrix algebra (every entry, COO), verified."""
    k, n = int(model.k), int(model.n)
    W = _quiet_call(model.omega_matrix, np.eye(k))
    if W.shape != (k, n, n) or not np.all(np.isfinite(W)):
        raise NotCompilable(f"model.omega_matrix gave shape {W.shape} (or non-finite values) on the basis, "
                            f"expected {(k, n, n)}")
    rng = np.random.default_rng(7)
    x = rng.standard_normal((4, k))
    Om = _quiet_call(model.omega_matrix, x)
    ref = np.einsum("pa,arc->prc", x, W)
    scale = np.einsum("pa,arc->prc", np.abs(x), np.abs(W)).max() + 1e-300
    if Om.shape != ref.shape or not np.all(np.abs(Om - ref) <= 1e-13 * scale):
        raise NotCompilable("model.omega_matrix is not linear in xi")
    a, r, c = np.nonzero(W)
    index = np.stack([a, r, c], axis=1).astype(np.int64).reshape(-1, 3)
    return index, np.ascontiguousarray(W[a, r, c], dtype=float)
