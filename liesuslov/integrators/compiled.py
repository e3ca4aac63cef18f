"""A compiled (numba) RKMK step: the method of :class:`~liesuslov.integrators.rkmk.RKMKStepper`, one call per step.

:class:`CompiledStepper` is a drop-in for ``RKMKStepper``: same constructor arguments, same protocol
(``step(h, xi, G, gamma, want_error) -> (xi1, G1, Theta1, errs)``, ``accept()``, ``reset()``,
``gamma_of(G, gamma)``, ``nfev``, ``theta_out``), so the Python time loop of :func:`~liesuslov.integrate`
(controller, ``t_eval``, failure detection) drives either unchanged. A step is one jitted call that runs
every stage, the group update and the embedded error estimates — and the controller's error norm — for
each trajectory of the batch in turn, where the numpy stepper spends ~25 numpy calls (~1 µs each) per
stage. :func:`make_stepper` picks the stepper for ``integrate(..., backend=...)``.

What is compiled, and why it is the same method
-----------------------------------------------
Nothing about the mechanics is re-derived. The reduced field of every built-in scene (zero, linear and
quadratic potentials, the gyroscopic term; any form) is a polynomial of degree <= 2 in
``z = (xi, Gamma)`` jointly; :func:`compile_plan` reads its coefficients off the numpy model by
probing ``model.xi_dot`` (at 0, at ``±e_i`` and at ``e_i + e_j``: ``f(z) = c + L z + z^T Q z`` by
polarisation), drops the coefficients that are zero to rounding, keeps the rest as sparse (COO) lists so
that a field evaluation costs one multiply-add per nonzero (Klebsh–Tisserand in SO(n): n - 1 terms), and
then *verifies* the polynomial against ``model.xi_dot`` at random points (relative 1e-12). ``Omega(xi)``
is linear: its basis tensor is read off ``model.omega_matrix`` the same way. A scene whose potential is
not a built-in polynomial one (a user :class:`~liesuslov.Potential`, a
:class:`~liesuslov.FamilyPotential`) or whose field fails the check runs on numpy.

The group part (the attitude ``g1 = g0 phi(Theta)``, the vertical ``Gamma1 = phi(-Theta) Gamma0``, or
none) is compiled on so(n) (skew matrices; other algebras run a group part on numpy, and a scene without
one on any algebra is compiled), with the charts of :mod:`liesuslov.integrators.charts`:

* exp, n = 3: Rodrigues and the exact so(3) ``dexp^{-1}_{-Theta}(a) = (1 - c θ²) a + ½ θ × a + c (θ·a) θ``,
  ``c = (1 - (θ/2) cot(θ/2)) / θ²`` (series below θ = 0.1), by components;
* exp, n != 3: the truncated series ``Σ_{k < p-1} (B_k/k!) ad^k_Theta`` with the sign of the right side
  (:func:`liesuslov.groups.dexpinv_terms` terms; brackets of skew matrices, exactly skew); ``exp`` by
  scaling and squaring with the diagonal Padé approximants and bounds of
  :func:`liesuslov.groups.expm_skew` (Higham 2005; one degree per matrix), and ``exp(-Theta) Gamma`` in
  the stages by the Taylor series of the action on the vector (while ``|Theta|_2 <= 1``, ~10x cheaper);
* Cayley: ``cay(X) = (I - X/2)^{-1} (I + X/2)`` (closed form for n = 3, an LU solve with partial
  pivoting otherwise) and the exact ``dcay^{-1}_{-Theta}(A) = (I + Theta/2) A (I - Theta/2)``.

Stage 0 is reused between steps as the numpy stepper reuses it (FSAL, kept across rejected steps), so
``nfev`` and the accepted and rejected steps are the same; states agree with the numpy stepper to
rounding (~1e-15 relative per step, tested to 1e-13 for every tableau, both charts, both group modes,
n = 3, 4, 5), and the structure is as exact (``g^T g = I``, ``|Gamma| = 1`` to rounding).

The error estimates come back as :class:`ErrorEstimates`, a sequence in the numpy stepper's format
(``(err_xi, err_Theta)`` per estimator, ``err_Theta`` as (B, m, m) matrices) with one addition: when the
stepper is built with the run's ``rtol`` and ``atol``, ``errs.norm(rtol, atol)`` returns the
controller's scaled norm computed inside the kernel, so a controller that asks for it makes no numpy
call per step.

Cost and compilation
--------------------
Importing this module imports numba (``import liesuslov`` does not). The kernels are compiled with
``cache=True``: the first use on a machine compiles them (~10–30 s, once per installed version; the
cache lives in the package's ``__pycache__`` or in ``NUMBA_CACHE_DIR``), later processes load them
(~0.3 s, plus ~0.3 s to import numba). A step of one trajectory then costs ~3 µs (no group part) to
~10 µs (DOP853 with the attitude in SO(4)) including the Python call; the batch is looped over inside
the kernel.
"""

from __future__ import annotations

import math
import warnings
import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import groups

__all__ = ["CompiledStepper", "CompilePlan", "ErrorEstimates", "NotCompilable", "compile_plan", "numba_available",
           "make_stepper", "AUTO_MAX_N", "AUTO_MAX_BATCH"]

MODES = {"none": 0, "gamma": 1, "g": 2}
#: ``backend="auto"`` compiles a group part up to this n: the kernel's dense O(n^3) stage work (one
#: trajectory at a time) loses to the numpy stepper's batched and low-rank kernels beyond it (measured:
#: DOP853 weights, n = 24 at 0.6x the numpy time per step, n = 32 at 1.2x).
AUTO_MAX_N = 24
# Above this many trajectories the numpy stepper, vectorised along the batch, beats the kernel's
# serial loop (measured, RKMK4 with reconstruction: crossover near 200 for n = 3 and n = 4).
AUTO_MAX_BATCH = 200
CHART_CODES = {"exp": 0, "cayley": 1}

# Relative agreement the probed polynomial must reach against model.xi_dot on random points.
_VERIFY_RTOL = 1e-12
# A probed coefficient below this many ulps of the values it was computed from is zero to rounding.
_ZERO_ULPS = 16.0


class NotCompilable(ValueError):
    """The scene cannot run on the compiled kernel; the message says why (it then runs on numpy)."""


def numba_available() -> bool:
    """Whether numba could be imported (the optional extra ``liesuslov[fast]``)."""
    return _njit is not None


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


def compile_plan(model, mode: str, chart: str | None) -> CompilePlan:
    """Check that ``model`` runs on the compiled kernel in ``mode`` / ``chart`` and extract its coefficients.

    Parameters
    ----------
    model : Model
        A model of :mod:`liesuslov.mechanics` (or an object with its protocol).
    mode : {"g", "gamma", "none"}
        As in :class:`~liesuslov.integrators.rkmk.RKMKStepper`.
    chart : {"exp", "cayley"} or None
        Ignored when ``mode == "none"``.

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
        if not name.startswith("so(") or not model.n or model.n < 2:
            raise NotCompilable(f"the compiled kernel moves the group part on SO(n) only; {name} runs on numpy")
    system = getattr(model, "system", None)
    pot = getattr(system, "potential", None)
    kind = getattr(pot, "kind", "zero")
    if kind not in ("zero", "linear", "quadratic"):
        raise NotCompilable(f"the potential {pot!r} (kind {kind!r}) is not a built-in polynomial potential "
                            "(zero, linear, quadratic): its field is not compiled")
    cache = _model_cache(model)
    field_index, field_value = _cached(cache, "field", _probe_field, model)
    n = 0
    omega_index, omega_value = np.zeros((0, 3), np.int64), np.zeros(0)
    if mode != "none":
        omega_index, omega_value = _cached(cache, "omega", _probe_omega, model)
        n = int(model.n)
    return CompilePlan(int(model.k), n, bool(model.has_gamma), field_index, field_value, omega_index,
                       omega_value)


def _model_cache(model) -> dict:
    """The dict of what was derived from ``model`` (probed coefficients, packed constants)."""
    try:
        return _PLANS.setdefault(model, {})
    except TypeError:  # not weak-referenceable or not hashable: no cache
        return {}


def _constants(plan: CompilePlan, mode: int, chart: int, tableau):
    """``(s, s_eval, fsal, nerr, iprm, fprm, nws)``: the tableau and the plan packed for the kernel."""
    s = tableau.A.shape[0]
    ew = [np.asarray(e, dtype=float) for e in tableau.error_weights]
    s_eval = max([s] + [len(e) for e in ew])
    # FSAL exactly as RKMKStepper decides it
    fsal = bool(s > 1 and np.allclose(tableau.A[-1], tableau.b) and tableau.c[-1] == 1.0)
    tab = np.zeros((s + 1 + len(ew), s_eval))
    tab[:s, :s] = tableau.A
    tab[s, :s] = tableau.b
    for i, e in enumerate(ew):
        tab[s + 1 + i, :len(e)] = e
    terms = groups.bernoulli_coefficients(groups.dexpinv_terms(tableau.order))[1:]
    bern = np.array(terms, dtype=float).reshape(-1, 2)
    iprm, fprm, nws = _pack(plan, mode, chart, s, s_eval, fsal, tab, bern)
    return s, s_eval, fsal, len(ew), iprm, fprm, nws


def _cached(cache: dict, key: str, probe, model):
    """``probe(model)``, or its NotCompilable, computed once per model."""
    if key not in cache:
        try:
            cache[key] = probe(model)
        except NotCompilable as exc:
            cache[key] = exc
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


# ====================================================================================== the stepper
class ErrorEstimates(Sequence):
    """The embedded error estimates of one compiled step, in the format of ``RKMKStepper.step``.

    ``errs[e] == (err_xi (B, k), err_Theta (B, m, m) or None)`` for each error estimator of the tableau
    (views, built on access). Besides, :meth:`norm` gives the controller's scaled norm (see
    ``_Run._error_norm`` in :mod:`liesuslov.integrators.integrate`) without any numpy call when the
    stepper was built with the run's ``rtol`` and ``atol`` (it was computed inside the kernel).
    """

    __slots__ = ("_E", "_k", "_m", "_group", "_norm", "_tol", "_xi0", "_xi1")

    def __init__(self, E, k, m, group, norm, tol, xi0, xi1) -> None:
        self._E, self._k, self._m, self._group = E, k, m, group
        self._norm, self._tol, self._xi0, self._xi1 = norm, tol, xi0, xi1

    def __len__(self) -> int:
        return self._E.shape[0]

    def __iter__(self):
        for e in range(self._E.shape[0]):
            yield self[e]

    def __getitem__(self, e):
        if not isinstance(e, (int, np.integer)):
            raise TypeError("ErrorEstimates supports integer indices only")
        E = self._E[e]  # IndexError ends iteration
        ex = E[:, :self._k]
        eg = E[:, self._k:].reshape(E.shape[0], self._m, self._m) if self._group else None
        return ex, eg

    def norm(self, rtol: float, atol: float) -> float:
        """Scaled error norm of the step (worst trajectory), as the adaptive controller defines it.

        With ``sc = atol + rtol max(|xi0|, |xi1|)`` on ``xi`` and ``atol + rtol`` on the group
        coordinates, ``s_e = Σ (err_e / sc)²`` per trajectory over ``ncomp = k (+ m²)`` components:
        ``sqrt(max_b s / ncomp)`` for one estimator, ``max_b s5 / sqrt(ncomp (s5 + 0.01 s3))`` for DOP853;
        ``inf`` when an estimate is NaN (the step is rejected). Computed inside the step when the stepper
        knows the tolerances.
        """
        if self._tol == (rtol, atol):
            return self._norm
        ng = self._m * self._m if self._group else 0
        return float(_kernels().error_norm(self._xi0, self._xi1, self._E, float(rtol), float(atol), self._k, ng))


class CompiledStepper:
    """Advance ``(xi, G)`` by one RKMK step in one compiled call; a drop-in for ``RKMKStepper``.

    Parameters
    ----------
    model : mechanics Model
        Must qualify (:func:`compile_plan`): polynomial field of degree <= 2, so(n) group part.
    tableau : ButcherTableau
    chart : Chart, {"exp", "cayley"} or None
        None (or anything) when ``mode == "none"``.
    mode : {"g", "gamma", "none"}
        The attitude ``g`` (B, n, n) with ``Gamma = g^T gamma``; the vertical (B, n); no group part.
    batch : int
        Number of trajectories B.
    rtol, atol : float, optional
        The adaptive controller's tolerances: the kernel then also returns the scaled error norm
        (:meth:`ErrorEstimates.norm`), saving the controller's numpy reductions.

    Raises
    ------
    NotCompilable
        When the model does not qualify (the reason in the message).
    ImportError
        When numba is not installed.

    Attributes
    ----------
    nfev : int
        Field evaluations so far (counted as ``RKMKStepper`` counts them).
    theta_out : bool
        Whether :meth:`step` returns ``Theta1`` (default True; the time loop sets it False).

    Notes
    -----
    The first step of a process loads the compiled kernel (~0.3 s) or, the first time on a machine,
    compiles it (~10–30 s; cached on disk). Stage 0 is cached between steps exactly as in ``RKMKStepper``
    (FSAL reuse of the last stage's field value, kept across rejected steps), so ``nfev`` matches.
    """

    def __init__(self, model, tableau, chart, mode: str, batch: int, *, rtol: float | None = None,
                 atol: float | None = None) -> None:
        chart_name = chart if (chart is None or isinstance(chart, str)) else getattr(chart, "name", None)
        plan = compile_plan(model, mode, chart_name)
        self.kern = _kernels()
        self.model, self.tab, self.chart, self.mode, self.B = model, tableau, chart, mode, int(batch)
        self.plan = plan
        self.k = plan.k
        self.m = plan.n
        self.nfev = 0
        chart_code = CHART_CODES.get(chart_name, 0) if mode != "none" else 0
        key = ("pack", mode, chart_code, tableau)
        cache = _model_cache(model)
        if key not in cache:
            cache[key] = _constants(plan, MODES[mode], chart_code, tableau)
        s, s_eval, fsal, nerr, self._iprm, self._fprm, nws = cache[key]
        self.fsal = fsal
        self._s, self._s_eval = s, s_eval
        self._gives_new = fsal or s_eval > s
        self._nerr = nerr
        self._ws = np.zeros(nws)
        self._first = np.zeros((self.B, self.k))
        self._new = np.zeros((self.B, self.k))
        self._first_ok = False
        self._empty = np.zeros((self.B, 0))
        self._no_err = np.zeros((0, self.B, self.k + self.m * self.m))
        self._theta_scratch = np.zeros((self.B, self.m * self.m))
        self.theta_out = True
        self._tol = (float(rtol), float(atol)) if rtol is not None and atol is not None else None
        self._rtol = self._tol[0] if self._tol is not None else -1.0
        self._atol = self._tol[1] if self._tol is not None else -1.0

    def reset(self) -> None:
        """Forget cached stage data (call when the state is changed from outside)."""
        self._first_ok = False

    def accept(self) -> None:
        """The last step was accepted: what it computed at the new point becomes stage 0."""
        if self._gives_new:
            self._first, self._new = self._new, self._first
            self._first_ok = True
        else:
            self._first_ok = False

    def gamma_of(self, G: np.ndarray | None, gamma: np.ndarray | None) -> np.ndarray | None:
        """The vertical in the body frame at the current point (None when the model has none)."""
        if not self.model.has_gamma or G is None:
            return None
        if self.mode == "g":
            return np.einsum("bji,bj->bi", G, gamma)  # Gamma = g^T gamma
        return G

    def step(self, h: float, xi: np.ndarray, G: np.ndarray | None, gamma: np.ndarray | None,
             want_error: bool = False):
        """One step of size h (negative for backward integration); the state is not modified.

        Parameters
        ----------
        h : float
        xi : (B, k)
        G : (B, m, m) attitude, (B, n) vertical, or None (see ``mode``)
        gamma : (B, n) or None
            The vertical in space (mode "g" with a vertical only).
        want_error : bool
            Also return the embedded error estimates.

        Returns
        -------
        xi1 : (B, k)
        G1 : like G
        Theta1 : (B, m, m) or None
            The chart coordinates of the group increment (None in mode "none" or when
            :attr:`theta_out` is False).
        errs : ErrorEstimates or list
            A sequence of ``(err_xi (B, k), err_Theta (B, m, m) or None)``, one per error estimator
            (DOP853 has two), with a :meth:`ErrorEstimates.norm` shortcut; ``[]`` unless asked.
        """
        B, k, m = self.B, self.k, self.m
        xi = np.ascontiguousarray(xi, dtype=float)
        group = G is not None
        if group:
            G = np.ascontiguousarray(G, dtype=float)
            G1 = np.empty_like(G)
            if self.theta_out:
                Th1 = np.empty((B, m, m))
                Thf = Th1.reshape(B, m * m)
            else:
                Th1, Thf = None, self._theta_scratch
            gs = m * m if self.mode == "g" else m
            Gf, G1f = G.reshape(B, gs), G1.reshape(B, gs)
        else:
            G1 = Th1 = None
            Gf = G1f = Thf = self._empty
        gm = self._empty if gamma is None else np.ascontiguousarray(gamma, dtype=float)
        xi1 = np.empty_like(xi)
        E = np.empty((self._nerr, B, k + m * m)) if want_error else self._no_err
        first_ok = self._first_ok
        nrm = self.kern.step(float(h), xi, Gf, gm, self._first, self._new, first_ok,
                             self._rtol if want_error else -1.0, self._atol, self._ws, self._iprm, self._fprm,
                             xi1, G1f, Thf, E)
        self._first_ok = True
        self.nfev += self._s_eval - (1 if first_ok else 0)
        errs = ErrorEstimates(E, k, m, group, nrm, self._tol, xi, xi1) if want_error else []
        return xi1, G1, Th1, errs


def make_stepper(backend: str, model, tableau, chart, mode: str, batch: int, *, rtol: float | None = None,
                 atol: float | None = None):
    """The stepper for ``backend``: ``(stepper, name)`` with name "numba" or "numpy".

    Parameters
    ----------
    backend : {"auto", "numba"}
        "auto": the compiled stepper when numba imports, the model qualifies and the group matrices are
        at most :data:`AUTO_MAX_N` wide and the batch at most :data:`AUTO_MAX_BATCH`, else the numpy
        ``RKMKStepper``; "numba": the compiled one (any n, any batch) or a ValueError saying why not.
    model, tableau, chart, mode, batch
        As for ``RKMKStepper``.
    rtol, atol : float, optional
        The adaptive controller's tolerances (see :class:`CompiledStepper`).
    """
    from .rkmk import RKMKStepper

    try:
        if not numba_available():
            raise NotCompilable("numba is not installed (pip install 'liesuslov[fast]')")
        if backend == "auto" and mode != "none" and model.n is not None and model.n > AUTO_MAX_N:
            raise NotCompilable(f"n = {model.n} > {AUTO_MAX_N}: the numpy stepper is faster there")
        if backend == "auto" and batch > AUTO_MAX_BATCH:
            raise NotCompilable(f"batch = {batch} > {AUTO_MAX_BATCH}: the vectorised numpy stepper is faster there")
        stepper = CompiledStepper(model, tableau, chart, mode, batch, rtol=rtol, atol=atol)
        _ensure_compiled(strict=backend == "numba")
        return stepper, "numba"
    except NotCompilable as exc:
        if backend == "numba":
            raise ValueError(f"backend='numba' cannot run this scene: {exc}; use backend='auto' or 'numpy'") from None
        return RKMKStepper(model, tableau, chart, mode, batch), "numpy"


_COMPILED: bool | Exception | None = None  # None: not tried in this process; True; or why it failed


def _ensure_compiled(strict: bool) -> None:
    """Compile (or load from the cache) the step kernel once per process, on an empty batch.

    A failure (a numba that cannot compile here) raises it when ``strict``; otherwise it warns once and
    raises :class:`NotCompilable`, so that ``backend="auto"`` falls back to numpy.
    """
    global _COMPILED
    if _COMPILED is None:
        try:
            empty = np.zeros((0, 0))
            plan = CompilePlan(1, 0, False, np.zeros((0, 3), np.int64), np.zeros(0), np.zeros((0, 3), np.int64),
                               np.zeros(0))
            iprm, fprm, nws = _pack(plan, 0, 0, 1, 1, False, np.zeros((2, 1)), np.zeros((0, 2)))
            xi = np.zeros((0, 1))
            _rkmk_step(0.0, xi, empty, empty, xi, xi, False, -1.0, -1.0, np.zeros(nws), iprm, fprm, xi.copy(),
                       empty, empty, np.zeros((0, 0, 1)))
            _COMPILED = True
        except Exception as exc:  # pragma: no cover - depends on the platform's numba
            _COMPILED = exc
            if not strict:
                warnings.warn(f"the numba kernel of liesuslov failed to compile ({type(exc).__name__}: {exc}); "
                              "integrating on numpy", RuntimeWarning, stacklevel=3)
    if _COMPILED is not True:
        if strict:
            raise _COMPILED
        raise NotCompilable(f"the numba kernel failed to compile ({_COMPILED})")


# ====================================================================================== the kernels
# numba is optional: without it the functions below stay plain Python and are never called. The kernels
# use numpy's error model (x / 0 gives inf or nan, as in the numpy stepper, so the controller sees a
# non-finite error and rejects the step) and no fast-math (the rounding must follow the numpy path).
try:
    from numba import njit as _njit
except Exception:  # ImportError, or a numba broken by an incompatible numpy
    _njit = None


def _jit(fn):
    return _njit(cache=True, nogil=True, error_model="numpy")(fn) if _njit is not None else fn


def _kernels():
    """The jitted entry points ``(rkmk_step, error_norm)``; ImportError without numba."""
    if _njit is None:
        raise ImportError("the compiled stepper needs numba: pip install 'liesuslov[fast]'")
    return _ENTRY


def _pade_table() -> tuple[np.ndarray, np.ndarray]:
    """Bounds theta_m (Higham 2005, Table 2.3, m = 3, 5, 7, 9, 13) and the [m/m] Padé numerator coefficients."""
    thetas = np.array([1.495585217958292e-2, 2.539398330063230e-1, 9.504178996162932e-1,
                       2.097847961257068e0, 5.371920351148152e0])
    coef = np.zeros((5, 14))
    for r, m in enumerate((3, 5, 7, 9, 13)):
        for j in range(m + 1):
            coef[r, j] = (math.factorial(2 * m - j) * math.factorial(m)
                          / (math.factorial(2 * m) * math.factorial(j) * math.factorial(m - j)))
    return thetas, coef


_PADE_THETA, _PADE_COEF = _pade_table()


# ---------------------------------------------------------------------- small dense linear algebra
@_jit
def _mm(A, B, C):
    """C = A @ B for (n, n) matrices (C distinct from A and B)."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for p in range(n):
                acc += A[i, p] * B[p, j]
            C[i, j] = acc


@_jit
def _bracket_skew(A, B, C):
    """C = [A, B] = A B - B A for skew A, B: the upper triangle of P - P^T (P = A B), made exactly skew."""
    n = A.shape[0]
    for i in range(n):
        C[i, i] = 0.0
        for j in range(i + 1, n):
            acc = 0.0
            for p in range(n):
                acc += A[i, p] * B[p, j] - A[j, p] * B[p, i]
            C[i, j] = acc
            C[j, i] = -acc


@_jit
def _set_eye(out, d):
    """out = d I."""
    n = out.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.0
        out[i, i] = d


@_jit
def _axpy(out, a, A):
    """out += a A."""
    n = out.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] += a * A[i, j]


@_jit
def _solve(A, X):
    """Solve A Y = X in place by LU with partial pivoting: A (n, n) is destroyed, X (n, r) becomes Y."""
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
    """R <- R (3 I - R^T R) / 2, one Newton–Schulz step toward the nearest orthogonal matrix (T, P scratch).

    For ``R = Q (I + E)``, ``|E| = δ``, it returns ``Q (I + O(δ²))``: applied where the maps below lose
    orthogonality like ``|X| eps`` (many squarings; the Cayley solve at large ``|X|``), it keeps
    ``R^T R = I`` to rounding whatever the step, as the closed forms of the numpy stepper do.
    """
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


# Beyond this |X|_2 bound the Cayley solve's orthogonality error (~ |X| eps / 2) gets a polar step; beyond
# _CAYLEY_MAX = 1/sqrt(eps) (a meaningless step: cay(X) = -I + O(1/|X|) on every plane) even that cannot
# restore it, and the map returns NaN, so that the run stops with status -1 and the time.
_CAYLEY_POLAR = 2.0
_CAYLEY_MAX = 6.7e7


# ---------------------------------------------------------------------- so(3) closed forms
@_jit
def _rodrigues(t2):
    """(cos θ, sin θ/θ, (1 - cos θ)/θ²) from θ², by the half angle (as ``groups._rodrigues``)."""
    x2 = 0.25 * t2
    x = np.sqrt(x2)
    if x < 1e-4:
        s = 1.0 - x2 * (1.0 / 6.0 - x2 / 120.0)
    else:
        s = np.sin(x) / x
    b = 0.5 * s * s
    return 1.0 - b * t2, s * np.cos(x), b


@_jit
def _dexp3_coefficient(t2):
    """(1 - (θ/2) cot(θ/2)) / θ², series below θ = 0.1 (as ``groups._dexp3_coefficient``)."""
    if t2 < 0.01:
        return 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 * (1.0 / 1209600.0 + t2 / 47900160.0)))
    x = 0.5 * np.sqrt(t2)
    return (1.0 - x * np.cos(x) / np.sin(x)) / t2


@_jit
def _mat3(c, a, b, w0, w1, w2, out):
    """out = c I + a hat(w) + b w w^T."""
    bw0, bw1, bw2 = b * w0, b * w1, b * w2
    o01, o02, o12 = bw0 * w1, bw0 * w2, bw1 * w2
    out[0, 0] = c + bw0 * w0
    out[0, 1] = o01 - a * w2
    out[0, 2] = o02 + a * w1
    out[1, 0] = o01 + a * w2
    out[1, 1] = c + bw1 * w1
    out[1, 2] = o12 - a * w0
    out[2, 0] = o02 - a * w1
    out[2, 1] = o12 + a * w0
    out[2, 2] = c + bw2 * w2


@_jit
def _lin3(c, a, b, w0, w1, w2, v0, v1, v2):
    """c v + a w × v + b (w·v) w."""
    d = b * (w0 * v0 + w1 * v1 + w2 * v2)
    return (c * v0 + a * (w1 * v2 - w2 * v1) + d * w0,
            c * v1 + a * (w2 * v0 - w0 * v2) + d * w1,
            c * v2 + a * (w0 * v1 - w1 * v0) + d * w2)


@_jit
def _hat3(r0, r1, r2, out):
    out[0, 0] = 0.0
    out[0, 1] = -r2
    out[0, 2] = r1
    out[1, 0] = r2
    out[1, 1] = 0.0
    out[1, 2] = -r0
    out[2, 0] = -r1
    out[2, 1] = r0
    out[2, 2] = 0.0


# ---------------------------------------------------------------------- exponential (n != 3)
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
        _mm(X6, T, X8)  # X8 as scratch
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
def _expm(X, out, W):
    """out = exp(X) for a skew X (n, n): scaling and squaring with Padé (as ``groups.expm_skew``); W[0..8]."""
    n = X.shape[0]
    acc = 0.0
    for i in range(n):
        for j in range(n):
            acc += X[i, j] * X[i, j]
    nrm = np.sqrt(0.5 * acc)  # bounds |X|_2 for skew X
    r = 4
    for q in range(4):
        if nrm <= _PADE_THETA[q]:
            r = q
            break
    s = 0
    Xs = W[7]
    if r == 4:
        e = math.frexp(nrm / _PADE_THETA[4])[1]
        s = e if e > 0 else 0
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
        # each squaring doubles the departure from orthogonality: a polar step after every 8 squarings
        # (<= 256 eps) and at the end keeps R^T R = I to rounding for any |X| (absurd steps included)
        if q % 8 == 7 or q == s - 1:
            _polar_step(out, W[0], W[1])


# ---------------------------------------------------------------------- the charts
@_jit
def _phi(chart, X, out, W):
    """out = phi(X): exp or Cayley of a skew (n, n) matrix; W[0..9] scratch."""
    n = X.shape[0]
    if n == 3:
        w0, w1, w2 = X[2, 1], X[0, 2], X[1, 0]
        t2 = w0 * w0 + w1 * w1 + w2 * w2
        if chart == 0:
            c, a, b = _rodrigues(t2)
        else:
            b = 2.0 / (4.0 + t2)
            c, a = 1.0 - b * t2, 2.0 * b
        _mat3(c, a, b, w0, w1, w2, out)
    elif chart == 0:
        _expm(X, out, W)
    else:
        M = W[9]
        acc = 0.0
        for i in range(n):
            for j in range(n):
                M[i, j] = -0.5 * X[i, j]
                out[i, j] = 0.5 * X[i, j]
                acc += X[i, j] * X[i, j]
            M[i, i] += 1.0
            out[i, i] += 1.0
        nrm = np.sqrt(0.5 * acc)
        if nrm > _CAYLEY_MAX:  # the solve is no longer accurate enough to be made orthogonal: fail loudly
            for i in range(n):
                for j in range(n):
                    out[i, j] = np.nan
            return
        _solve(M, out)
        if nrm > _CAYLEY_POLAR:
            _polar_step(out, W[0], W[1])


@_jit
def _expv_taylor(X, sign, v, out, nu, S):
    """out = exp(sign X) v by its Taylor series, for a skew X with ``|X|_2 <= nu <= 1``.

    Terms are added while the a-priori bound ``nu^j / j!`` of the next one exceeds 2^-56 (|v| = |out|
    for skew X, so that is below half an ulp of the result): at most 19 terms, each one matrix-vector
    product — ~10x cheaper than forming exp(X) when only its action on one vector is needed. S (>= 2, n)
    scratch.
    """
    n = X.shape[0]
    t = S[0]
    u = S[1]
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


@_jit
def _phi_vec(chart, X, sign, v, out, W, vb):
    """out = phi(sign X) v for a skew X (n, n) and v (n,); W[0..10], vb (n, 1) scratch.

    Small ``|X|_2`` (the steps of an accurate run): the Taylor series of the action (exp) or one solve with
    a vector (Cayley); large: the orthogonal matrix of :func:`_phi` / :func:`_expm`, then the product.
    """
    n = X.shape[0]
    if n == 3:
        w0, w1, w2 = sign * X[2, 1], sign * X[0, 2], sign * X[1, 0]
        t2 = w0 * w0 + w1 * w1 + w2 * w2
        if chart == 0:
            c, a, b = _rodrigues(t2)
        else:
            b = 2.0 / (4.0 + t2)
            c, a = 1.0 - b * t2, 2.0 * b
        out[0], out[1], out[2] = _lin3(c, a, b, w0, w1, w2, v[0], v[1], v[2])
        return
    T = W[9]
    if chart == 0:
        acc = 0.0
        for i in range(n):
            for j in range(n):
                acc += X[i, j] * X[i, j]
        nu = np.sqrt(0.5 * acc)  # bounds |X|_2 for skew X
        if nu <= 1.0:
            _expv_taylor(X, sign, v, out, nu, T)
            return
        for i in range(n):  # large or non-finite Theta: exp(sign X) by Padé, then the product
            for j in range(n):
                T[i, j] = sign * X[i, j]
        R = W[10]
        _expm(T, R, W)
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += R[i, j] * v[j]
            out[i] = acc
    else:
        acc = 0.0
        for i in range(n):
            for j in range(n):
                acc += X[i, j] * X[i, j]
        if np.sqrt(0.5 * acc) <= _CAYLEY_POLAR:  # (I - sX/2) y = v + sX v / 2
            h = 0.5 * sign
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    T[i, j] = -h * X[i, j]
                    acc += X[i, j] * v[j]
                T[i, i] += 1.0
                vb[i, 0] = v[i] + h * acc
            _solve(T, vb)
            for i in range(n):
                out[i] = vb[i, 0]
            return
        S = W[8]  # large or non-finite Theta: the orthogonalised matrix, then the product (_phi uses W[0, 1, 9])
        for i in range(n):
            for j in range(n):
                S[i, j] = sign * X[i, j]
        R = W[10]
        _phi(chart, S, R, W)
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += R[i, j] * v[j]
            out[i] = acc


@_jit
def _dinv(chart, Th, A, out, W, bern):
    """out = dphi^{-1}_{-Th}(A), the right-trivialised inverse derivative (``charts.make_chart``); W[0..2]."""
    n = Th.shape[0]
    if n == 3:
        t0, t1, t2_ = Th[2, 1], Th[0, 2], Th[1, 0]
        a0, a1, a2 = A[2, 1], A[0, 2], A[1, 0]
        tt = t0 * t0 + t1 * t1 + t2_ * t2_
        if chart == 0:  # exact: (1 - c θ²) a + ½ θ × a + c (θ·a) θ
            c = _dexp3_coefficient(tt)
            r0, r1, r2 = _lin3(1.0 - c * tt, 0.5, c, t0, t1, t2_, a0, a1, a2)
        else:  # exact: a + ½ θ × a + ¼ (θ·a) θ
            r0, r1, r2 = _lin3(1.0, 0.5, 0.25, t0, t1, t2_, a0, a1, a2)
        _hat3(r0, r1, r2, out)
        return
    if chart == 0:  # Σ (B_k/k!) ad^k_Th A, the odd (k = 1) term with the sign of the right side
        ad, P = W[0], W[1]
        for i in range(n):
            for j in range(n):
                ad[i, j] = A[i, j]
                out[i, j] = A[i, j]
        k_ad = 0
        for t in range(bern.shape[0]):
            kk = int(bern[t, 0])
            c = bern[t, 1]
            while k_ad < kk:  # ad <- [Th, ad]
                _bracket_skew(Th, ad, P)
                for i in range(n):
                    for j in range(n):
                        ad[i, j] = P[i, j]
                k_ad += 1
            _axpy(out, -c if kk == 1 else c, ad)
    else:  # (I + Th/2) A (I - Th/2) = M - M Th / 2 with M = A + Th A / 2, made exactly skew
        M, P = W[0], W[1]
        _mm(Th, A, P)
        for i in range(n):
            for j in range(n):
                M[i, j] = A[i, j] + 0.5 * P[i, j]
        _mm(M, Th, P)
        for i in range(n):
            for j in range(n):
                P[i, j] = M[i, j] - 0.5 * P[i, j]
        for i in range(n):
            out[i, i] = 0.0
            for j in range(i + 1, n):
                v = 0.5 * (P[i, j] - P[j, i])
                out[i, j] = v
                out[j, i] = -v


# ---------------------------------------------------------------------- the model
@_jit
def _field(x, Gam, has_gamma, fidx, fval, z, out):
    """out = f(x, Gam), the probed polynomial (COO, see :class:`CompilePlan`); z scratch (k [+ n])."""
    k = x.shape[0]
    for c in range(k):
        z[c] = x[c]
    if has_gamma:
        for c in range(Gam.shape[0]):
            z[k + c] = Gam[c]
    for c in range(out.shape[0]):
        out[c] = 0.0
    for t in range(fval.shape[0]):
        v = fval[t]
        i = fidx[t, 1]
        j = fidx[t, 2]
        if i >= 0:
            v = v * z[i]
        if j >= 0:
            v = v * z[j]
        out[fidx[t, 0]] += v


@_jit
def _omega(x, widx, wval, Om):
    """Om = Omega(x): the upper triangle from the COO list, the lower one by skew symmetry."""
    n = Om.shape[0]
    for i in range(n):
        for j in range(n):
            Om[i, j] = 0.0
    for t in range(wval.shape[0]):
        Om[widx[t, 1], widx[t, 2]] += wval[t] * x[widx[t, 0]]
    for i in range(n):
        for j in range(i + 1, n):
            Om[j, i] = -Om[i, j]


# ---------------------------------------------------------------------- the step
@_jit
def _error_norm(xi0, xi1, E, rtol, atol, k, ng):
    """The controller's scaled norm of the estimates E (ne, B, k + ng), as ``_Run._error_norm``.

    A NaN estimate gives inf (the step is rejected), also for DOP853's combination, where the numpy formula
    ``np.where(denom > 0, ..., 0)`` would turn it into 0 and accept the step.
    """
    ne = E.shape[0]
    B = E.shape[1]
    if ne == 0:
        return 0.0
    ncomp = k + ng
    scg = atol + rtol
    best = 0.0
    for b in range(B):
        s5 = 0.0
        s3 = 0.0
        for e in range(min(ne, 2)):
            acc = 0.0
            for c in range(k):
                a0 = abs(xi0[b, c])
                a1 = abs(xi1[b, c])
                v = E[e, b, c] / (atol + rtol * (a0 if a0 > a1 else a1))
                acc += v * v
            if ng > 0:
                g = 0.0
                for c in range(k, k + ng):
                    g += E[e, b, c] * E[e, b, c]
                acc = acc + g / (scg * scg)
            if e == 0:
                s5 = acc
            else:
                s3 = acc
        if np.isnan(s5) or np.isnan(s3):  # reject: the controller then shrinks the step toward the blow-up
            return np.inf
        if ne == 1:
            per = s5
        else:
            denom = s5 + 0.01 * s3
            per = s5 / np.sqrt(denom * ncomp) if denom > 0 else 0.0
            if np.isnan(per):  # inf / inf
                return np.inf
        if per > best:
            best = per
    if ne == 1:
        return np.sqrt(best / ncomp)
    return best


# Layout of the packed integer parameters (iprm[:_NHEAD]); the COO index lists follow the header.
_H_GAMMA, _H_MODE, _H_CHART, _H_N, _H_S, _H_SEVAL, _H_FSAL, _H_NERR = 0, 1, 2, 3, 4, 5, 6, 7
_H_BERN, _H_NF, _H_NW = 8, 9, 10
_NHEAD = 11


def _pack(plan: CompilePlan, mode: int, chart: int, s: int, s_eval: int, fsal: bool, tab: np.ndarray,
          bern: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The kernel's constant parameters as one int64 and one float64 array, and its workspace size.

    ``iprm = header + field_index.ravel() + omega_index.ravel()``;
    ``fprm = tab.ravel() + bern.ravel() + field_value + omega_value`` (see :func:`_rkmk_step`).
    """
    head = np.zeros(_NHEAD, dtype=np.int64)
    n, k = plan.n, plan.k
    nerr = tab.shape[0] - s - 1
    head[[_H_GAMMA, _H_MODE, _H_CHART, _H_N, _H_S, _H_SEVAL, _H_FSAL, _H_NERR]] = (
        int(plan.has_gamma), mode, chart, n, s, s_eval, int(fsal), nerr)
    head[[_H_BERN, _H_NF, _H_NW]] = (bern.shape[0], plan.field_value.size, plan.omega_value.size)
    iprm = np.concatenate([head, plan.field_index.ravel(), plan.omega_index.ravel()]).astype(np.int64)
    fprm = np.concatenate([tab.ravel(), bern.ravel(), plan.field_value, plan.omega_value]).astype(float)
    nn = n * n
    nws = s_eval * k + s_eval * nn + k + (k + n) + 3 * nn + 2 * n + 11 * nn + n
    return np.ascontiguousarray(iprm), np.ascontiguousarray(fprm), nws


@_jit
def _rkmk_step(h, xi, G, gam, first, new, first_ok, rtol, atol, ws, iprm, fprm, xi1, G1, Th1, E):
    """One RKMK step for each trajectory of the batch (the algorithm of ``RKMKStepper.step``).

    Parameters
    ----------
    h : float
    xi : (B, k)
    G : (B, n*n), (B, n) or (B, 0)
        The group part flattened (attitude, vertical or nothing).
    gam : (B, n) or (B, 0)
        The vertical in space (mode "g").
    first, new : (B, k)
        The field at the current point (read when ``first_ok``, else written) and at the new point
        (written when FSAL or when an estimator needs it).
    first_ok : bool
    rtol, atol : float
        The controller's tolerances; ``rtol < 0``: no norm.
    ws : (nws,) scratch; iprm, fprm : the packed constants of :func:`_pack`.
    xi1 : (B, k), G1 : like G, Th1 : (B, n*n), E : (ne, B, k + n*n)
        Outputs (allocated by the caller: numba's boxing of arrays it allocates costs ~0.5 µs each):
        the new point, ``Theta1`` and the ``ne`` error estimates (``ne = 0``: none asked for).

    Returns
    -------
    norm : float
        The controller's error norm (:func:`_error_norm`) when ``ne > 0`` and ``rtol >= 0``, else -1.
    """
    has_gamma = iprm[_H_GAMMA] != 0
    mode = iprm[_H_MODE]
    chart = iprm[_H_CHART]
    n = iprm[_H_N]
    s = iprm[_H_S]
    s_eval = iprm[_H_SEVAL]
    fsal = iprm[_H_FSAL] != 0
    nerr = iprm[_H_NERR]  # E holds 0 or nerr estimates
    nb = iprm[_H_BERN]
    nf = iprm[_H_NF]
    nw = iprm[_H_NW]
    fidx = iprm[_NHEAD:_NHEAD + 3 * nf].reshape((nf, 3))
    widx = iprm[_NHEAD + 3 * nf:_NHEAD + 3 * nf + 3 * nw].reshape((nw, 3))
    o = (s + 1 + nerr) * s_eval
    tab = fprm[:o].reshape((s + 1 + nerr, s_eval))
    bern = fprm[o:o + 2 * nb].reshape((nb, 2))
    o += 2 * nb
    fval = fprm[o:o + nf]
    wval = fprm[o + nf:o + nf + nw]

    B = xi.shape[0]
    k = xi.shape[1]
    nn = n * n
    group = mode != 0
    ne = E.shape[0]
    # scratch, carved from ws
    o = 0
    L = ws[o:o + s_eval * k].reshape((s_eval, k))
    o += s_eval * k
    K = ws[o:o + s_eval * nn].reshape((s_eval, n, n))
    o += s_eval * nn
    Xi = ws[o:o + k]
    o += k
    z = ws[o:o + k + n]
    o += k + n
    Th = ws[o:o + nn].reshape((n, n))
    o += nn
    T1 = ws[o:o + nn].reshape((n, n))
    o += nn
    Om = ws[o:o + nn].reshape((n, n))
    o += nn
    Gam0 = ws[o:o + n]
    o += n
    Gam = ws[o:o + n]
    o += n
    W = ws[o:o + 11 * nn].reshape((11, n, n))
    o += 11 * nn
    vb = ws[o:o + n].reshape((n, 1))
    for b in range(B):
        if has_gamma:  # the vertical in the body frame at the current point
            if mode == 2:
                for i in range(n):
                    acc = 0.0
                    for j in range(n):
                        acc += G[b, j * n + i] * gam[b, j]
                    Gam0[i] = acc
            else:
                for i in range(n):
                    Gam0[i] = G[b, i]
        # Stage i evaluates the field at (Xi, Th): stage 0 at the current point (Th = 0, K_0 = Omega), stages
        # 1 .. s-1, and, when an estimator needs it, stage s at the new point. One call site per helper
        # keeps the compiled code (and its compilation time) small.
        for i in range(s + 1):
            if i == 0:
                for c in range(k):
                    Xi[c] = xi[b, c]
            elif i < s:
                for c in range(k):
                    acc = 0.0
                    for j in range(i):
                        acc += tab[i, j] * L[j, c]
                    Xi[c] = xi[b, c] + h * acc
                if group:
                    for p in range(n):
                        for q in range(n):
                            acc = 0.0
                            for j in range(i):
                                acc += tab[i, j] * K[j, p, q]
                            Th[p, q] = h * acc
            else:  # i == s: the new point (xi1, Theta1)
                if fsal:  # the last stage sits there
                    for c in range(k):
                        xi1[b, c] = Xi[c]
                        new[b, c] = L[s - 1, c]
                    for p in range(n):
                        for q in range(n):
                            T1[p, q] = Th[p, q]
                else:
                    for c in range(k):
                        acc = 0.0
                        for j in range(s):
                            acc += tab[s, j] * L[j, c]
                        xi1[b, c] = xi[b, c] + h * acc
                    if group:
                        for p in range(n):
                            for q in range(n):
                                acc = 0.0
                                for j in range(s):
                                    acc += tab[s, j] * K[j, p, q]
                                T1[p, q] = h * acc
                if s_eval == s:
                    break
                for c in range(k):  # an estimator uses the field at the new point: one more stage there
                    Xi[c] = xi1[b, c]
                for p in range(n):
                    for q in range(n):
                        Th[p, q] = T1[p, q]
            if i == 0:
                for c in range(n if has_gamma else 0):
                    Gam[c] = Gam0[c]
            elif group and has_gamma:
                _phi_vec(chart, Th, -1.0, Gam0, Gam, W, vb)
            if i > 0 or not first_ok:
                _field(Xi, Gam, has_gamma, fidx, fval, z, L[i])
            elif i == 0:
                for c in range(k):
                    L[0, c] = first[b, c]
            if i == 0 and not first_ok:
                for c in range(k):
                    first[b, c] = L[0, c]
            if group:
                O = K[0] if i == 0 else Om
                _omega(Xi, widx, wval, O)
                if i > 0:
                    _dinv(chart, Th, Om, K[i], W, bern)
            if i == s:
                for c in range(k):
                    new[b, c] = L[s, c]
        for e in range(ne):
            row = s + 1 + e
            for c in range(k):
                acc = 0.0
                for j in range(s_eval):
                    acc += tab[row, j] * L[j, c]
                E[e, b, c] = h * acc
            if group:
                for p in range(n):
                    for q in range(n):
                        acc = 0.0
                        for j in range(s_eval):
                            acc += tab[row, j] * K[j, p, q]
                        E[e, b, k + p * n + q] = h * acc
        if group:
            for p in range(n):
                for q in range(n):
                    Th1[b, p * n + q] = T1[p, q]
            if mode == 2:  # g1 = g phi(Theta1)
                R = W[10]
                _phi(chart, T1, R, W)
                for i in range(n):
                    for j in range(n):
                        acc = 0.0
                        for p in range(n):
                            acc += G[b, i * n + p] * R[p, j]
                        G1[b, i * n + j] = acc
            else:  # Gamma1 = phi(-Theta1) Gamma
                _phi_vec(chart, T1, -1.0, G[b], G1[b], W, vb)
    nrm = -1.0
    if ne > 0 and rtol >= 0.0:
        nrm = _error_norm(xi, xi1, E, rtol, atol, k, nn if group else 0)
    return nrm


class _Entry:
    """The jitted entry points (attributes resolved once)."""

    step = staticmethod(_rkmk_step)
    error_norm = staticmethod(_error_norm)


_ENTRY = _Entry
