"""The reference scenes of the work-precision sweeps (:data:`SCENES`) and the scenes of the throughput,
n-scaling and floor measurements.

A :class:`BenchScene` carries the liesuslov system and its initial data, the same motion as an embedded
ODE for scipy's ``solve_ivp`` (a hand-written numpy right-hand side, as a user would write it) and the
reference it is checked against (closed form where there is one).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class BenchScene:
    """A reference scene: the system, its initial data, the scipy formulation and the reference.

    Attributes
    ----------
    key, title : str
    n : int
        SO(n).
    system : SuslovSystem
    omega0 : ndarray, shape (d,)
        Initial Omega in so(n) coordinates (in D).
    Gamma0 : ndarray, shape (n,), or None
    reconstruct : bool
        Integrate the attitude g (g0 = identity); then Gamma = g^T gamma with gamma = Gamma0.
    t1 : float
        Final time (the errors are taken there).
    integrals : dict of str to callable
        First integrals ``F(omega (..., d), Gamma (..., n) or None)``; "energy" among them.
    rhs : callable
        ``f(t, y)`` of the embedded ODE for ``scipy.integrate.solve_ivp``.
    y0 : ndarray
        Its initial state.
    unpack : callable
        ``y (N, dim) -> (omega (N, d), Gamma (N, n) or None, g (N, n, n) or None)``.
    n_base : int
        The step-count scale of the fixed-step sweeps: rkmk4 with ``n_base`` steps over ``[0, t1]`` errs
        by about 1e-7 … 1e-6 (a quarter of it by ~1e-4).
    analytic : callable or None
        ``() -> dict`` with some of ``"omega"``, ``"Gamma"`` at ``t1`` from the closed form.
    extra : callable or None
        ``(omega, Gamma, g) -> dict`` of derived quantities at ``t1`` compared with ``extra_ref``
        (the Lagrange scene: the spherical pendulum ``q, v``).
    extra_ref : callable or None
        ``() -> dict`` of the same quantities from the closed form.
    reference : str
        How the reference was obtained (for the report).
    """

    key: str
    title: str
    n: int
    system: Any
    omega0: np.ndarray
    Gamma0: np.ndarray | None
    reconstruct: bool
    t1: float
    integrals: dict
    rhs: Callable
    y0: np.ndarray
    unpack: Callable
    n_base: int
    analytic: Callable | None = None
    extra: Callable | None = None
    extra_ref: Callable | None = None
    reference: str = ""

    @property
    def has_group(self) -> bool:
        """Whether a group part (g or Gamma) is integrated, i.e. whether the chart matters."""
        return self.reconstruct or self.Gamma0 is not None


def fk_coords(n: int) -> tuple[int, np.ndarray]:
    """(d, positions of Omega_in, i < n, among the so(n) coordinates)."""
    import liesuslov as ls

    alg = ls.so(n)
    return alg.dim, np.array([alg.index(i, n - 1) for i in range(n - 1)])


def _fk_unpacker(n: int, with_g: bool, gamma: np.ndarray | None) -> Callable:
    """Unpack ``y = (xi, vec g)`` or ``(xi, Gamma)`` of a Fedorov–Kozlov scene."""
    d, idx = fk_coords(n)
    m = n - 1

    def unpack(y):
        omega = np.zeros((y.shape[0], d))
        omega[:, idx] = y[:, :m]
        if with_g:
            g = y[:, m:].reshape(-1, n, n)
            Gamma = None if gamma is None else np.einsum("tji,j->ti", g, gamma)
            return omega, Gamma, g
        return omega, y[:, m:], None
    return unpack


def _fk_g_rhs(n: int, xi_dot: Callable) -> Callable:
    """Embedded ODE ``xi' = f(xi, Gamma)``, ``g' = g Omega`` with ``Gamma = g^T gamma``, Omega in the FK D.

    Omega has only its last row and column: ``(g Omega)[:, j] = -g[:, n-1] xi_j`` (j < n-1) and
    ``(g Omega)[:, n-1] = g[:, :n-1] @ xi``.
    """
    m = n - 1

    def rhs(t, y, gamma):
        xi = y[:m]
        g = y[m:].reshape(n, n)
        Gam = gamma @ g  # g^T gamma
        out = np.empty_like(y)
        out[:m] = xi_dot(xi, Gam)
        dg = out[m:].reshape(n, n)
        dg[:, :m] = np.multiply.outer(-g[:, m], xi)
        dg[:, m] = g[:, :m] @ xi
        return out
    return rhs


def klebsh_tisserand_rhs(c: np.ndarray) -> Callable:
    """The Klebsh–Tisserand body in SO(4) as scipy integrates it: ``rhs(t, y, gamma)`` of the embedded ODE
    (xi, vec g), ``xi_i' = c_i Gamma_i Gamma_4`` with ``c_i = (B_i - B_4) / (I_i + I_4)``, ``Gamma = g^T gamma``."""
    return _fk_g_rhs(4, lambda xi, G: c * G[:-1] * G[-1])


def _klebsh_tisserand() -> BenchScene:
    """Klebsh–Tisserand in SO(4) with its attitude: Omega, Gamma against the closed form on the torus."""
    import liesuslov as ls

    n = 4
    I = np.array([1.0, 2.0, 3.0, 4.0])
    B = np.array([4.0, 3.0, 2.0, 1.0])
    case = ls.cases.klebsh_tisserand(I, B)
    u0 = np.array([0.3, -0.2, 0.15])
    G0 = np.array([0.3, 0.25, -0.2, 0.0])
    G0[-1] = math.sqrt(1.0 - float(G0 @ G0))
    d, idx = fk_coords(n)
    omega0 = np.zeros(d)
    omega0[idx] = u0
    t1 = 20.0
    c = (B[:-1] - B[-1]) / (I[:-1] + I[-1])
    base = klebsh_tisserand_rhs(c)

    def analytic():
        u, G = ls.analytic.KlebshTisserandMotion(u0, G0, I, B).state(t1)
        om = np.zeros(d)
        om[idx] = u
        return {"omega": om, "Gamma": G}

    return BenchScene("klebsh-tisserand", "Klebsh–Tisserand, n = 4, with reconstruction", n, case.system, omega0, G0,
                      True, t1, dict(case.integrals), lambda t, y: base(t, y, G0),
                      np.concatenate([u0, np.eye(n).ravel()]), _fk_unpacker(n, True, G0), 250, analytic,
                      reference="Omega, Gamma: KlebshTisserandMotion (closed form on the torus, t(tau) by quadrature); "
                                "g: mean of liesuslov rkmk853 and scipy DOP853 at rtol 1e-13")


def _kharlamova() -> BenchScene:
    """Kharlamova in SO(5) over one period: the state returns to itself."""
    import liesuslov as ls

    n = 5
    I = np.array([1.0, 1.5, 2.0, 2.5, 3.0])
    B = np.array([1.0, -0.6, 0.8, 0.5])
    case = ls.cases.kharlamova(I, B)
    u0 = np.array([0.2, -0.1, 0.15, 0.05])
    G0 = np.array([0.3, -0.2, 0.4, 0.1, 0.8])
    G0 = G0 / np.linalg.norm(G0)
    motion = ls.analytic.KharlamovaMotion(u0, G0, I, B)
    if str(motion.kind) != "periodic":  # pragma: no cover - fixed data
        raise RuntimeError("the Kharlamova scene's data must give a periodic motion")
    T = float(motion.period)
    d, idx = fk_coords(n)
    omega0 = np.zeros(d)
    omega0[idx] = u0
    m = n - 1
    c = B / (I[:-1] + I[-1])

    def rhs(t, y):  # (I_i + I_n) u_i' = B_i Gamma_n, Gamma' = -Omega Gamma
        xi, G = y[:m], y[m:]
        out = np.empty_like(y)
        out[:m] = c * G[m]
        out[m:-1] = -G[m] * xi
        out[-1] = G[:m] @ xi
        return out

    def analytic():  # one period: the state returns to itself
        return {"omega": omega0.copy(), "Gamma": G0.copy()}

    return BenchScene("kharlamova", f"Kharlamova, n = 5, over one period (T = {T:.6f})", n, case.system, omega0, G0,
                      False, T, dict(case.integrals), rhs, np.concatenate([u0, G0]), _fk_unpacker(n, False, None), 100,
                      analytic, reference="the initial state (period T from KharlamovaMotion, Carlson's R_F)")


def _lagrange() -> BenchScene:
    """Lagrange in SO(3), mapped to the spherical pendulum and checked against its elliptic solution."""
    import liesuslov as ls

    n = 3
    I1, In, Bn = 1.0, 0.5, 1.0
    case = ls.cases.lagrange(n, I1, In, Bn)
    u0 = np.array([0.6, 0.3])
    G0 = np.array([0.4, 0.2, 0.9])
    G0 = G0 / np.linalg.norm(G0)
    d, idx = fk_coords(n)
    omega0 = np.zeros(d)
    omega0[idx] = u0
    t1 = 10.0
    k = -Bn / (I1 + In)
    base = _fk_g_rhs(n, lambda xi, G: k * G[:-1])
    q0, v0 = ls.to_spherical_pendulum(np.eye(n), omega0)
    # The closed-form motion was renamed SphericalPendulumMotion; the old name still works, with a warning.
    motion = getattr(ls.analytic, "SphericalPendulumMotion", None) or ls.analytic.SphericalPendulum
    pendulum = motion(q0, v0, G0, I1 + In, Bn)

    def extra(omega, Gamma, g):
        try:
            q, v = ls.to_spherical_pendulum(g, omega)
        except ValueError:  # g off SO(n) by more than 1e-8 (scipy at loose tolerances): the same map, unchecked
            q, v = g[:, -1], g @ ls.so(n).hat(omega)[:, -1]
        return {"q": q, "v": v}

    def extra_ref():
        q, v = pendulum.state(t1)
        return {"q": q, "v": v}

    return BenchScene("lagrange", "Lagrange, n = 3, mapped to the spherical pendulum", n, case.system, omega0, G0, True,
                      t1, dict(case.integrals), lambda t, y: base(t, y, G0), np.concatenate([u0, np.eye(n).ravel()]),
                      _fk_unpacker(n, True, G0), 150, None, extra, extra_ref,
                      reference="(q, v) = (g e_n, g Omega e_n): SphericalPendulum (Jacobi elliptic functions); "
                                "Omega, Gamma, g: mean of liesuslov rkmk853 and scipy DOP853 at rtol 1e-13")


def _euler_top() -> BenchScene:
    """The free rigid body with its attitude (no closed form for g: two independent tight runs)."""
    import liesuslov as ls

    n = 3
    Id = np.array([1.0, 2.0, 3.5])  # mass tensor; J = tr(I) - I acts on w
    alg = ls.so(3)
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag(Id)), constraints=ls.Subspace(alg, np.eye(3)))
    K = system.inertia.matrix
    J = Id.sum() - Id
    w0 = np.array([0.8, 0.6, 0.5])
    omega0 = np.array([-w0[2], w0[1], -w0[0]])  # (Omega_12, Omega_13, Omega_23) = (-w3, w2, -w1)
    t1 = 20.0
    a1, a2, a3 = (J[1] - J[2]) / J[0], (J[2] - J[0]) / J[1], (J[0] - J[1]) / J[2]

    def rhs(t, y):  # J w' = J w x w, g' = g hat(w)
        w1, w2, w3 = y[0], y[1], y[2]
        g = y[3:].reshape(3, 3)
        out = np.empty_like(y)
        out[0], out[1], out[2] = a1 * w2 * w3, a2 * w3 * w1, a3 * w1 * w2
        W = np.array([[0.0, -w3, w2], [w3, 0.0, -w1], [-w2, w1, 0.0]])
        out[3:] = (g @ W).ravel()
        return out

    def unpack(y):
        w = y[:, :3]
        return np.stack([-w[:, 2], w[:, 1], -w[:, 0]], axis=-1), None, y[:, 3:].reshape(-1, 3, 3)

    def energy(x, G):
        return 0.5 * np.sum((x @ K) * x, axis=-1)

    def casimir(x, G):
        M = x @ K
        return np.sum(M * M, axis=-1)

    return BenchScene("euler-top", "free rigid body (Euler top), n = 3, with attitude", n, system, omega0, None, True,
                      t1, {"energy": energy, "|M|^2": casimir}, rhs, np.concatenate([w0, np.eye(3).ravel()]), unpack,
                      120,
                      reference="mean of liesuslov rkmk853 and scipy DOP853 at rtol 1e-13 (independent formulations)")


def _suslov3() -> BenchScene:
    """Suslov's problem in SO(3), V = 0: the explicit tanh law."""
    import liesuslov as ls

    Jw = np.array([[2.0, 0.0, 0.3], [0.0, 3.0, 0.4], [0.3, 0.4, 4.0]])
    case = ls.cases.suslov3(Jw)
    w0 = np.array([1.0, 0.5, 0.0])
    omega0 = np.array([-w0[2], w0[1], -w0[0]])
    t1 = 25.0
    JD, b = Jw[:2, :2], Jw[:2, 2]
    RJ = np.array([[0.0, -1.0], [1.0, 0.0]]) @ JD / np.linalg.det(JD)

    def rhs(t, y):  # J_D w' = <b, w> R w  (w3 = 0)
        return (b @ y) * (RJ @ y)

    def unpack(y):
        z = np.zeros(y.shape[0])
        return np.stack([z, y[:, 1], -y[:, 0]], axis=-1), None, None

    def analytic():
        w = ls.analytic.Suslov3Free(w0, Jw).omega(t1)
        return {"omega": np.array([-w[2], w[1], -w[0]])}

    return BenchScene("suslov3", "Suslov, n = 3, V = 0: asymptotic motion", 3, case.system, omega0, None, False, t1,
                      dict(case.integrals), rhs, w0[:2].copy(), unpack, 40, analytic,
                      reference="Suslov3Free (explicit tanh law on the energy ellipse)")


#: BenchScene name -> constructor.
SCENES: dict[str, Callable[[], BenchScene]] = {
    "klebsh-tisserand": _klebsh_tisserand,
    "kharlamova": _kharlamova,
    "lagrange": _lagrange,
    "euler-top": _euler_top,
    "suslov3": _suslov3,
}


def build_scene(name: str) -> BenchScene:
    """The :class:`BenchScene` called ``name`` (a key of :data:`SCENES`; underscores accepted).

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones).
    """
    return SCENES[scene_key(name)]()


def scene_key(name: str) -> str:
    """The key of :data:`SCENES` that ``name`` means; ValueError listing the valid ones."""
    key = str(name).strip().lower().replace("_", "-")
    if key not in SCENES:
        raise ValueError(f"unknown scene {name!r}; valid scenes: {', '.join(SCENES)}")
    return key


def _kt_parameters(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(I, B) of the Klebsh–Tisserand body of the sweeps: B_i > B_n, so the motion winds on tori."""
    I = np.linspace(1.0, 2.0, n)
    B = np.linspace(3.0, 2.0, n)
    B[-1] = 1.0
    return I, B


def kt_system(n: int):
    """The Klebsh–Tisserand case in SO(n) used by the throughput sweep (n = 4)."""
    import liesuslov as ls

    return ls.cases.klebsh_tisserand(*_kt_parameters(n))


def scaling_scene(n: int):
    """(system, Omega0, Gamma0) of the n-scaling sweep: Klebsh–Tisserand in SO(n), Fedorov–Kozlov D.

    Built as a SuslovSystem, not a Case: the Case's energy integral holds the dense d x d inertia
    (d = n(n-1)/2; 8 GiB at n = 256), which the integration itself does not need.
    """
    import liesuslov as ls

    I, B = _kt_parameters(n)
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(I), potential=ls.QuadraticPotential(B))
    rng = np.random.default_rng(n)
    u = 0.3 * rng.standard_normal(n - 1)
    Omega0 = np.zeros((n, n))
    Omega0[:-1, -1], Omega0[-1, :-1] = u, -u
    Gamma0 = rng.standard_normal(n)
    return system, Omega0, Gamma0 / np.linalg.norm(Gamma0)


def throughput_case(n: int):
    """The case of the batch-throughput sweep: Lagrange for n = 3, Klebsh–Tisserand for n = 4."""
    import liesuslov as ls

    return ls.cases.lagrange(3, 1.0, 0.5, 1.0) if n == 3 else kt_system(4)


# ---------------------------------------------------------------------- the floor's scenes
#: Step of every floor comparison (issue 10's measurement).
FLOOR_H = 0.005


@dataclass(frozen=True)
class FloorScene:
    """A scene the plain compiled loop (:mod:`.floor`) integrates with exactly the library's field.

    Attributes
    ----------
    key, title, n, system
        As in :class:`BenchScene`.
    Omega0 : ndarray, shape (n, n)
    Gamma0 : ndarray, shape (n,), or None
    x0 : ndarray
        The floor's initial vector: the angular velocity w (n = 3) or xi = (Omega_i4) (n = 4).
    coeffs : ndarray, shape (3,)
        The floor's field coefficients (Euler's a_i, or c_i = (B_i - B_4) / (I_i + I_4)).
    vector : callable
        ``Omega (..., n, n) -> (..., 3)``: the floor's vector read off the library's Omega.
    """

    key: str
    title: str
    n: int
    system: Any
    Omega0: np.ndarray
    Gamma0: np.ndarray | None
    x0: np.ndarray
    coeffs: np.ndarray
    vector: Callable


def _vee3(Omega: np.ndarray) -> np.ndarray:
    """w with Omega = hat(w) (so(3))."""
    return np.stack([Omega[..., 2, 1], Omega[..., 0, 2], Omega[..., 1, 0]], axis=-1)


def hat3(w: np.ndarray) -> np.ndarray:
    """hat(w) for w (..., 3)."""
    z = np.zeros(w.shape[:-1])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1), np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], axis=-2)


def floor_free_body() -> FloorScene:
    """The free rigid body in SO(3) of the euler-top scene (mass tensor diag(1, 2, 3.5), no constraint)."""
    import liesuslov as ls

    Id = np.array([1.0, 2.0, 3.5])
    J = Id.sum() - Id  # principal moments: J w' = (J w) x w
    system = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag(Id)), constraints=ls.Subspace(ls.so(3), np.eye(3)))
    w0 = np.array([0.8, 0.6, 0.5])
    a = np.array([(J[1] - J[2]) / J[0], (J[2] - J[0]) / J[1], (J[0] - J[1]) / J[2]])
    return FloorScene("free-body-3", "free rigid body, n = 3", 3, system, hat3(w0), None, w0, a, _vee3)


def floor_klebsh_tisserand() -> FloorScene:
    """The Klebsh–Tisserand body in SO(4) of the default scene of ``liesuslov run``."""
    import liesuslov as ls

    I = np.array([1.0, 1.5, 2.0, 0.5])
    B = np.array([4.0, 3.0, 2.5, 1.0])
    system = ls.cases.klebsh_tisserand(I, B).system
    xi0 = np.array([0.3, -0.2, 0.25])
    Gamma0 = np.array([0.2, -0.4, 0.4, 0.8])
    Omega0 = np.zeros((4, 4))
    Omega0[:3, 3], Omega0[3, :3] = xi0, -xi0
    c = (B[:-1] - B[-1]) / (I[:-1] + I[-1])
    return FloorScene("klebsh-tisserand-4", "Klebsh–Tisserand, n = 4", 4, system, Omega0,
                      Gamma0 / np.linalg.norm(Gamma0), xi0, c, lambda Om: Om[..., :3, 3])


#: n -> the scene of the one-trajectory floor comparison.
FLOOR_SCENES: dict[int, Callable[[], FloorScene]] = {3: floor_free_body, 4: floor_klebsh_tisserand}
