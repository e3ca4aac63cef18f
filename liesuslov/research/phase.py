r"""Reconstruction phase: the period of a periodic reduced motion and the monodromy of the attitude.

When the reduced state ``s = (Omega, Gamma)`` is periodic with period ``T``, ``t -> g(t + T)`` and
``t -> g(t) R`` both solve ``g' = g Omega(t)`` and agree at ``t0``, so ``g(t + T) = g(t) R`` with the constant
``R = g(t0)^{-1} g(t0 + T)`` in SO(n); left multiplication ``g -> h g`` (a symmetry) leaves R unchanged, so R
does not depend on ``g0``. Since ``Gamma = g^T gamma`` returns, ``R Gamma0 = Gamma0``; for the free body the
spatial momentum ``m = g M`` is constant and ``M`` returns, so ``R M0 = M0``.

For the free rigid body (n = 3, D the whole algebra, V = 0) Montgomery's formula splits the rotation
angle about ``M0`` into a dynamic and a geometric part (derived in ``docs/reconstruction.md``):

.. math::

    \Delta\theta \equiv \frac{2ET}{|M_0|} - \Lambda \pmod{2\pi},\qquad
    \Lambda = \oint \frac{p\cdot(u\times\dot u)}{1 + p\cdot u}\,dt,\qquad u = \frac{M}{|M|},

``Lambda`` the solid angle on the left of the closed curve ``u(t)`` (outward normal), in ``[0, 4 pi)`` (the
integral is that area modulo ``4 pi``), ``p`` any point with ``-p`` off the curve (we take the direction of
its mean).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..algebra import vee3
from . import _runner as R

__all__ = ["ReconstructionPhase", "reconstruction_phase", "rotation_angles", "axis_angle", "solid_angle"]

#: Status codes of :class:`ReconstructionPhase` (per trajectory).
STATUS = {0: "returned", 1: "no return within t_max", -1: "integration failed"}


@dataclass
class ReconstructionPhase:
    r"""Period and monodromy of periodic reduced motions (a batch).

    Attributes
    ----------
    period : ndarray, shape (...)
        ``T`` (NaN where no return was found).
    monodromy : ndarray, shape (..., m, m)
        ``R = g(t0)^{-1} g(t0 + T)`` in SO(n).
    angles : ndarray, shape (..., floor(m/2))
        Rotation angles of the invariant planes of R (real Schur form), descending, in ``[0, pi]``.
    axis : ndarray, shape (..., 3)
        n = 3: ``M0/|M0|`` if R fixes ``M0``, else ``Gamma0`` if R fixes ``Gamma0``, else R's own axis;
        NaN for n != 3. "Fixes ``u``" is ``|R u - u| <= 1e-7 + 4 eps``, ``eps`` the error of R estimated by a
        re-integration at ``rtol=1e-12`` (see :func:`reconstruction_phase`).
    angle : ndarray, shape (...)
        n = 3: ``R = exp(angle hat(axis))``, in ``(-pi, pi]`` (``>= 0`` with R's own axis); NaN for n != 3.
    dynamic_phase, geometric_phase : ndarray, shape (...)
        The free rigid body (n = 3, no constraint, no potential): ``2 E T / |M0|`` and the solid angle
        ``Lambda`` on the left of the closed curve ``M/|M|`` (outward normal), in ``[0, 4 pi)``, with
        ``angle == dynamic_phase - geometric_phase (mod 2 pi)`` (Montgomery); NaN for other systems.
    status : ndarray of int, shape (...)
        0 returned (or period given), 1 no return within ``t_max``, -1 the integration failed.
    return_distance : ndarray, shape (...)
        ``|s(T) - s0| / |s0|`` of the reduced state at the accepted return, in the integration with the
        given options (the closest return seen when none was accepted; NaN for a given period).
    closure : ndarray, shape (...)
        The same distance at the same return located on the checking re-integration (``rtol=1e-12``): the
        number compared with ``return_tol`` (the smallest over the checked candidates when none was
        accepted; NaN for a given period or when no crossing came within the screening tolerance).
    period_error : ndarray, shape (...)
        ``|T - T'|``, ``T'`` the same return's time on the checking re-integration: the error of the reported
        period as integrated with the given options (0 when they are that tight, and for a given period;
        NaN without a return). Near a homoclinic orbit it can be far above ``closure`` (Kharlamova n = 3 by
        a saddle: 0.18 on a period of 68.84 at the defaults, with ``closure`` 2e-9).
    crossings : ndarray of int, shape (...)
        Section crossings examined (0 for a given period).
    axis_kind : ndarray of str, shape (...)
        ``"momentum"``, ``"gamma"``, ``"own"`` or ``""`` (n != 3 or no period).
    """

    period: np.ndarray
    monodromy: np.ndarray
    angles: np.ndarray
    axis: np.ndarray
    angle: np.ndarray
    dynamic_phase: np.ndarray
    geometric_phase: np.ndarray
    status: np.ndarray
    return_distance: np.ndarray
    closure: np.ndarray
    period_error: np.ndarray
    crossings: np.ndarray
    axis_kind: np.ndarray
    message: str = ""
    stats: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """True iff every trajectory returned (status 0)."""
        return bool(np.all(self.status == 0))

    def montgomery_defect(self) -> np.ndarray:
        """``angle - (dynamic_phase - geometric_phase)`` wrapped to ``(-pi, pi]`` (free body; NaN otherwise)."""
        return _wrap(self.angle - (self.dynamic_phase - self.geometric_phase))


def _wrap(a: np.ndarray) -> np.ndarray:
    """Angles to ``(-pi, pi]``."""
    a = np.asarray(a, dtype=float)
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


# ------------------------------------------------------------------------------------- linear algebra
def rotation_angles(Rm) -> np.ndarray:
    r"""Rotation angles of the invariant planes of rotations, from the real Schur form.

    Parameters
    ----------
    Rm : array_like, shape (..., m, m)
        Rotations (orthogonal, det +1).

    Returns
    -------
    ndarray, shape (..., floor(m/2))
        Descending, in ``[0, pi]``: a 2x2 block ``[[a, b], [c, d]]`` gives ``atan2(sqrt(-b c), (a + d)/2)``
        (accurate near 0 and pi); 1x1 blocks ``-1`` pair into ``pi``, ``+1`` into 0.
    """
    from scipy.linalg import schur

    Rm = np.asarray(Rm, dtype=float)
    m = Rm.shape[-1]
    flat = Rm.reshape(-1, m, m)
    out = np.full((flat.shape[0], m // 2), np.nan)
    for k, A in enumerate(flat):
        if not np.all(np.isfinite(A)):
            continue
        T, _ = schur(A, output="real")
        ang: list[float] = []
        minus = 0
        i = 0
        while i < m:
            if i + 1 < m and T[i + 1, i] != 0.0:
                a, b, c, d = T[i, i], T[i, i + 1], T[i + 1, i], T[i + 1, i + 1]
                ang.append(float(np.arctan2(np.sqrt(max(-b * c, 0.0)), 0.5 * (a + d))))
                i += 2
            else:
                minus += T[i, i] < 0.0
                i += 1
        ang += [np.pi] * (minus // 2)
        ang += [0.0] * (m // 2 - len(ang))
        out[k] = sorted(ang[: m // 2], reverse=True)
    return out.reshape(Rm.shape[:-2] + (m // 2,))


def axis_angle(Rm, axis=None) -> tuple[np.ndarray, np.ndarray]:
    r"""Angle of 3x3 rotations about given unit axes (signed), or their own axis and angle.

    Parameters
    ----------
    Rm : array_like, shape (..., 3, 3)
    axis : array_like, shape (..., 3), optional
        A unit axis fixed by R: returns ``atan2(axis . v, (tr R - 1)/2)`` with ``v = vee((R - R^T)/2)``,
        i.e. ``R = exp(angle hat(axis))``, angle in ``(-pi, pi]``. Without it, R's axis with angle in ``[0, pi]``.

    Returns
    -------
    axis : ndarray, shape (..., 3)
    angle : ndarray, shape (...)
    """
    Rm = np.asarray(Rm, dtype=float)
    v = vee3(0.5 * (Rm - np.swapaxes(Rm, -1, -2)))
    c = 0.5 * (np.trace(Rm, axis1=-2, axis2=-1) - 1.0)
    if axis is not None:
        axis = np.asarray(axis, dtype=float)
        return np.broadcast_to(axis, v.shape).copy(), np.arctan2(np.sum(axis * v, axis=-1), c)
    s = np.linalg.norm(v, axis=-1)
    angle = np.arctan2(s, c)
    ax = v / np.where(s > 0.0, s, 1.0)[..., None]
    # near pi, v ~ sin(angle) loses the axis: take the longest column of (R + I)/2 = a a^T (at angle pi)
    P = 0.5 * (Rm + np.eye(3))
    cols = np.linalg.norm(P, axis=-2)
    j = np.argmax(cols, axis=-1)
    col = np.take_along_axis(P, j[..., None, None], axis=-1)[..., 0]
    col = col / np.where(cols.max(axis=-1) > 0, cols.max(axis=-1), 1.0)[..., None]
    col = col * np.where(np.sum(col * v, axis=-1) < 0.0, -1.0, 1.0)[..., None]
    ax = np.where((s < 1e-6)[..., None] & (c < 0.0)[..., None], col, ax)
    return ax, angle


def solid_angle(u, dt: float | np.ndarray, p=None) -> np.ndarray:
    r"""The solid angle on the left of a closed curve on the unit sphere sampled uniformly over one period.

    ``int p.(u x u')/(1 + p.u) dt`` by the trapezoidal rule (exponentially convergent for a smooth periodic
    curve), ``u'`` by the spectral derivative of the samples, reduced modulo ``4 pi``. For a simple closed
    curve avoiding ``-p`` the integral is ``+A`` (counter-clockwise about ``p`` seen from outside) or ``-A``
    (clockwise), ``A`` the area of the region not containing ``-p``; in both cases it is the area on the
    left modulo ``4 pi``, so the result is that area, in ``[0, 4 pi)``.

    Parameters
    ----------
    u : array_like, shape (N, ..., 3)
        ``u(t_j)``, ``t_j = j dt``, ``j = 0..N-1`` (the point ``t = T`` left out).
    dt : float or array_like, shape (...)
    p : array_like, shape (..., 3), optional
        A point such that ``-p`` is off the curve (default: the direction of the mean of ``u``).

    Returns
    -------
    ndarray, shape (...)
        In ``[0, 4 pi)``.
    """
    u = np.asarray(u, dtype=float)
    N = u.shape[0]
    if p is None:
        p = np.mean(u, axis=0)
        p = p / np.linalg.norm(p, axis=-1, keepdims=True)
    k = np.fft.fftfreq(N, d=1.0 / N)
    if N % 2 == 0:
        k[N // 2] = 0.0
    shape = (N,) + (1,) * (u.ndim - 1)
    uh = np.fft.fft(u, axis=0)
    du = np.real(np.fft.ifft(1j * k.reshape(shape) * uh, axis=0))  # d u / d(2 pi j / N)
    T = np.asarray(dt) * N
    du = du * (2.0 * np.pi / T)[..., None] if np.ndim(T) else du * (2.0 * np.pi / T)
    integrand = np.sum(p * np.cross(u, du), axis=-1) / (1.0 + np.sum(p * u, axis=-1))
    area = np.mod(np.sum(integrand, axis=0) * dt, 4.0 * np.pi)
    # np.mod rounds a tiny negative area (a small clockwise loop) up to 4 pi itself: that is 0
    return np.where(area >= 4.0 * np.pi, 0.0, area)


# ------------------------------------------------------------------------------------- the tool
#: Default closure of an accepted return, ``|s(T) - s0| <= RETURN_TOL |s0|`` on the checking re-integration.
RETURN_TOL = 1e-7
#: An accepted return also closes to this fraction of the orbit's size (its largest distance from s0, sampled
#: at :data:`ORBIT_SAMPLES` times of each window of the checking re-integration).
ORBIT_CLOSURE = 1e-5
ORBIT_SAMPLES = 65
#: ... unless it closes to this (relative to |s0|): the rounding level of the checking re-integration (rtol 1e-12),
#: where the orbit of a state near an equilibrium may be smaller than its closure / ORBIT_CLOSURE.
CLOSURE_FLOOR = 1e-13
#: ``R`` fixes a unit vector ``u`` when ``|R u - u| <= FIX_FLOOR + FIX_FACTOR * eps`` (``eps``: R's error).
FIX_FLOOR = 1e-7
FIX_FACTOR = 4.0


def reconstruction_phase(system, Omega0, *, Gamma0=None, g0=None, period=None, t_max: float = 1000.0,
                         return_tol: float | None = None, on_failure: str = "raise", samples: int = 256,
                         **options: Any) -> ReconstructionPhase:
    r"""Period and monodromy ``R = g(t0)^{-1} g(t0 + T)`` of periodic reduced motions (a batch).

    Parameters
    ----------
    system : SuslovSystem
    Omega0 : array_like, shape (..., n, n) or (..., d)
        Initial angular velocities in D.
    Gamma0 : array_like, shape (..., n), optional
        Required when the potential needs it; when given it is part of the reduced state.
    g0 : array_like, shape (..., m, m), optional
        Accepted for symmetry with ``integrate``; R does not depend on it (the attitude is integrated
        from the identity).
    period : float or array_like, shape (...), optional
        Use this period as is. None: the first return of the reduced state ``s = (xi, Gamma)`` to the
        plane through ``s0`` normal to the reduced velocity (crossed upwards), located on the continuous
        extension of the integration with ``options``. A crossing with ``|s - s0| <= screen |s0|``
        (``screen = max(return_tol, min(1e-2, 1e4 rtol))``, ``1e-2`` for a fixed-step method) is a
        candidate; it is the return only if the same crossing, located on a re-integration of the
        trajectory with ``method="rkmk853", rtol=1e-12, atol=1e-14``, closes to ``return_tol``:
        ``|s(T') - s0| <= return_tol |s0|``. Otherwise the search goes on to the next crossing.
    t_max : float
        Give up the search at this time.
    return_tol : float, optional
        The closure of an accepted return on the re-integration, relative to ``|s0|`` (default 1e-7). A
        quasi-periodic motion comes back no closer than ~1/(number of turns) of its torus within ``t_max``.
    on_failure : {"raise", "nan"}
        A trajectory without a return within ``t_max`` (or a failed integration): ValueError naming
        ``t_max`` (default), or NaN results with ``status`` 1 (-1).
    samples : int
        Points per period for the geometric phase of the free body.
    **options
        ``integrate``'s options; ``method="rkmk853", rtol=1e-10, atol=1e-12`` where not given. The reported
        period, monodromy and angles come from this integration (the re-integration only checks it).

    Returns
    -------
    ReconstructionPhase

    Raises
    ------
    ValueError
        No return within ``t_max`` (``on_failure="raise"``), or bad input.

    Notes
    -----
    Every trajectory is searched on its own (its own windows, its own checks): its numbers are the same
    alone or in any batch.

    n = 3: ``R`` is said to fix the unit vector ``u`` when ``|R u - u| <= 1e-7 + 4 eps``, ``eps = |R - R'|_2``
    the difference between ``R`` and the same monodromy from the re-integration (the error of ``R`` as
    integrated with ``options``; ``R'`` at the re-integration's own return for a found period).
    """
    if on_failure not in ("raise", "nan"):
        raise ValueError(f"on_failure must be 'raise' or 'nan', got {on_failure!r}")
    t_max = R.positive(t_max, "t_max")
    if isinstance(samples, (bool, np.bool_)) or not isinstance(samples, (int, np.integer)) or samples < 16:
        raise ValueError(f"samples must be an integer >= 16, got {samples!r}")
    opts = R.options_with_defaults(options)
    b = R.prepare(system, Omega0, Gamma0, g0)
    m = system.n
    if m is None:
        raise ValueError(f"reconstruction_phase needs a matrix representation of {system.algebra.name}")
    return_tol = RETURN_TOL if return_tol is None else R.positive(return_tol, "return_tol")
    tight = R.tight_options(opts)
    screen = max(return_tol, _screen(opts))
    B = b.size
    s0 = b.reduced(b.omega, b.Gamma)
    scale = np.maximum(np.linalg.norm(s0, axis=-1), np.finfo(float).tiny)
    T = np.full(B, np.nan)
    T_check = np.full(B, np.nan)       # the same return's time on the checking re-integration
    Rm = np.full((B, m, m), np.nan)
    Rt = np.full((B, m, m), np.nan)     # the monodromy of the checking re-integration
    status = np.zeros(B, dtype=int)
    dist = np.full(B, np.nan)
    closure = np.full(B, np.nan)
    count = np.zeros(B, dtype=int)
    want_axes = m == 3 and system.is_so
    why = np.full(B, "", dtype=object)  # why a trajectory failed (integrate's reason) or has no period
    if period is None:
        _search(system, b, s0, scale, return_tol, screen, t_max, opts, tight, T, T_check, Rm, Rt, status, dist,
                closure, count, why, on_failure == "raise")
    else:
        P = _period(period, b.shape)
        ident = np.broadcast_to(np.eye(m), (B, m, m)).copy()
        for val in np.unique(P):
            rows = np.nonzero(P == val)[0]
            G = None if b.Gamma is None else b.Gamma[rows]
            g_end, st, why_rows = R.run_plain(system, b.omega[rows], G, ident[rows], (0.0, float(val)), opts)
            T[rows] = T_check[rows] = val
            Rm[rows] = g_end
            status[rows] = np.where(st < 0, -1, 0)
            why[rows] = why_rows
            if want_axes:
                Rt[rows] = g_end if tight is None else R.run_plain(system, b.omega[rows], G, ident[rows],
                                                                   (0.0, float(val)), tight)[0]
    message = _message(status, dist, closure, t_max, return_tol, tight, why)
    if on_failure == "raise" and np.any(status != 0):
        raise ValueError(message)
    # ---- derived quantities
    ok = status == 0
    angles = rotation_angles(Rm)
    axis = np.full((B, 3), np.nan)
    angle = np.full(B, np.nan)
    kind = np.full(B, "", dtype=object)
    dyn = np.full(B, np.nan)
    geo = np.full(B, np.nan)
    if want_axes:
        _axes(system, b, Rm, Rt, ok, axis, angle, kind)
        if _is_free_body(system):
            _montgomery(system, b, T, ok, opts, samples, dyn, geo)
    shp = b.shape
    return ReconstructionPhase(
        period=T.reshape(shp), monodromy=Rm.reshape(shp + (m, m)), angles=angles.reshape(shp + (m // 2,)),
        axis=axis.reshape(shp + (3,)), angle=angle.reshape(shp), dynamic_phase=dyn.reshape(shp),
        geometric_phase=geo.reshape(shp), status=status.reshape(shp), return_distance=dist.reshape(shp),
        closure=closure.reshape(shp), period_error=np.abs(T - T_check).reshape(shp), crossings=count.reshape(shp),
        axis_kind=kind.astype(str).reshape(shp),
        message=message,
        stats={"return_tol": return_tol, "screen_tol": screen, "t_max": t_max,
               "check": dict(opts) if tight is None else tight, **opts})


def _screen(opts: dict) -> float:
    """The candidate tolerance of the search's own integration: ``min(1e-2, 1e4 rtol)``, 1e-2 for fixed step."""
    if not R.adaptive(opts.get("method")):
        return 1e-2
    return min(1e-2, 1e4 * float(opts.get("rtol", 1e-8)))


def _period(period, shape) -> np.ndarray:
    from .._validation import as_float_array

    P = as_float_array(period, "period")
    if np.any(P <= 0.0):
        raise ValueError(f"period must be positive, got {P.min():.3g}")
    try:
        P = np.broadcast_to(P, shape)
    except ValueError as exc:
        raise ValueError(f"period of shape {P.shape} does not broadcast to the batch {shape}") from exc
    return P.reshape(-1)


def _message(status, dist, closure, t_max, tol, tight, why) -> str:
    if np.all(status == 0):
        return "every trajectory returned"
    parts = []
    still = (status == 1) & (why != "")
    if np.any(still):
        parts.append(f"{int(np.sum(still))} trajectory(ies) start at an equilibrium of the reduced flow (the first: "
                     f"flat index {int(np.flatnonzero(still)[0])}): no period; pass period= to get R = exp(T Omega0)")
    wait = (status == 1) & (why == "")
    nr = int(np.sum(wait))
    if nr:
        d = dist[wait]
        c = closure[wait]
        if np.any(np.isfinite(d)):
            closest = f"; the closest return was at a relative distance {np.nanmin(d):.3g}"
            if np.any(np.isfinite(c)):
                how = "the integration itself" if tight is None else \
                    f"re-integration at rtol {tight['rtol']:g}"
                closest += f" (the closest candidate checked by {how} closes to {np.nanmin(c):.3g})"
        else:
            closest = "; the section through the initial state was never crossed again"
        parts.append(f"{nr} trajectory(ies) did not return to the initial reduced state within t_max = {t_max:g} "
                     f"(the first: flat index {int(np.flatnonzero(wait)[0])}; return_tol = {tol:.3g}){closest}: the "
                     "motion is not periodic (asymptotic or quasi-periodic), or raise t_max")
    nf = int(np.sum(status == -1))
    if nf:
        k = int(np.flatnonzero(status == -1)[0])
        parts.append(f"{nf} trajectory(ies) failed; the first (flat index {k}): {why[k] or 'integration failed'}")
    return "; ".join(parts)


class _Check:
    """The checking re-integration of one trajectory, advanced on demand from its last end (tight options).

    ``crossings`` holds ``(t, relative distance to s0, g)`` of every upward crossing of the trajectory's
    return plane seen so far (after ``t_min``).
    """

    def __init__(self, omega, Gamma, m: int):
        self.t = 0.0
        self.omega, self.Gamma = omega.copy(), None if Gamma is None else Gamma.copy()
        self.g = np.eye(m)[None]
        self.crossings: list[tuple[float, float, np.ndarray]] = []
        self.failed = False
        self.why = ""  # integrate's reason and time when it failed
        self.size = 0.0  # the orbit's size so far: the largest sampled |s(t) - s0| / |s0|

    def advance(self, system, b, plane, s0, scale, t_min, t_end, tight) -> None:
        if self.failed or t_end <= self.t:
            return
        win = R.run_window(system, self.omega, self.Gamma, self.g, (self.t, t_end), plane, 1, tight, True,
                           samples=ORBIT_SAMPLES)
        om, Ga = win.samples
        s = b.reduced(om[:, 0], None if Ga is None else Ga[:, 0])
        self.size = max(self.size, float(np.nanmax(np.linalg.norm(s - s0, axis=-1), initial=0.0)) / scale)
        cr = win.crossings
        for j in range(cr.t.size):
            if cr.t[j] <= t_min:
                continue
            s = b.reduced(cr.omega[j:j + 1], None if cr.Gamma is None else cr.Gamma[j:j + 1])[0]
            self.crossings.append((float(cr.t[j]), float(np.linalg.norm(s - s0) / scale), cr.g[j]))
        if win.status[0] < 0:
            self.failed = True
            self.why = str(win.why[0])
            return
        self.t, self.omega, self.g = t_end, win.omega, win.g
        self.Gamma = win.Gamma

    def near(self, t: float, width: float):
        """The crossing nearest ``t`` within ``width``, or None."""
        best = None
        for c in self.crossings:
            if abs(c[0] - t) <= width and (best is None or abs(c[0] - t) < abs(best[0] - t)):
                best = c
        return best


#: A candidate return at ``T`` is looked for on the re-integration within ``CHECK_WINDOW * T`` of ``T``.
CHECK_WINDOW = 1e-2


def _search(system, b, s0, scale, tol, screen, t_max, opts, tight, T, T_check, Rm, Rt, status, dist, closure,
            count, why, raise_still: bool) -> None:
    """Per trajectory, windows of doubling length until it has returned, failed or reached t_max.

    Everything is per trajectory (the plane, the first window's length, the checks); trajectories whose
    windows coincide share an ``integrate`` call, which keeps each trajectory's numbers its own.
    """
    B = b.size
    m = system.n
    xdot, Gdot = system.rhs(b.omega, b.Gamma)
    speed = np.sqrt(np.sum(xdot ** 2, axis=-1) + (0.0 if Gdot is None else np.sum(Gdot ** 2, axis=-1)))
    still = speed <= R.STILL * scale  # (relative: a slow motion of a small state is not an equilibrium)
    off = np.sum(xdot * b.omega, axis=-1) + (0.0 if Gdot is None else np.sum(Gdot * b.Gamma, axis=-1))
    # an equilibrium's plane has no normal (a zero velocity); it is never integrated: any normal stands in
    normal = np.where(still[:, None] & (np.arange(xdot.shape[-1]) == 0), 1.0, xdot)
    plane = R.make_plane(omega=normal, Gamma=Gdot, offset=off, direction=1)
    if raise_still and np.any(still):
        raise ValueError(f"Omega0: the initial state of trajectory {int(np.flatnonzero(still)[0])} (flat index) is an "
                         f"equilibrium of the reduced flow (speed <= {R.STILL:g} |s0|): it has no period to resolve; "
                         "pass period= to get R = exp(T Omega0)")
    # the first return cannot come before the state has moved away (R.start_time: a root at t0 itself)
    t_min = R.start_time(speed, scale)
    status[:] = 1
    why[still] = "an equilibrium of the reduced flow: no period"
    omega, Gamma = b.omega.copy(), None if b.Gamma is None else b.Gamma.copy()
    g = np.broadcast_to(np.eye(m), (B, m, m)).copy()
    # each trajectory's first window: ~32 / rate, rounded down to a power of two (so that trajectories of
    # similar rates share windows); then doubling
    width = np.minimum(2.0 ** np.floor(np.log2(32.0 / R.rates(b.omega, xdot))), t_max)
    t_a = np.zeros(B)
    checks: dict[int, _Check] = {}
    active = ~still
    while np.any(active):
        t_b = np.minimum(t_max, t_a + width)
        keys = sorted({(t_a[k], t_b[k]) for k in np.nonzero(active)[0]})
        for ta, tb in keys:
            rows = np.nonzero(active & (t_a == ta) & (t_b == tb))[0]
            win = R.run_window(system, omega[rows], None if Gamma is None else Gamma[rows], g[rows], (ta, tb),
                               R.slice_event(plane, rows, B), 1, opts, True)
            cr = win.crossings
            done = np.zeros(rows.size, dtype=bool)
            for j in range(cr.t.size):
                loc = int(cr.index[j])
                k = int(rows[loc])
                if done[loc] or cr.t[j] <= t_min[k]:
                    continue
                count[k] += 1
                s = b.reduced(cr.omega[j:j + 1], None if cr.Gamma is None else cr.Gamma[j:j + 1])[0]
                d = float(np.linalg.norm(s - s0[k]) / scale[k])
                dist[k] = d if not np.isfinite(dist[k]) else min(dist[k], d)
                if d > screen:
                    continue
                # a candidate: the same return on the checking re-integration
                if tight is None:
                    found = (float(cr.t[j]), d, cr.g[j])
                else:
                    chk = checks.get(k)
                    if chk is None:
                        chk = checks[k] = _Check(b.omega[k:k + 1], None if b.Gamma is None else b.Gamma[k:k + 1], m)
                    chk.advance(system, b, R.slice_event(plane, np.array([k]), B), s0[k], scale[k], t_min[k],
                                float(cr.t[j]) * (1.0 + CHECK_WINDOW), tight)
                    found = chk.near(float(cr.t[j]), CHECK_WINDOW * float(cr.t[j]))
                    if found is None and chk.failed:
                        status[k] = -1
                        why[k] = (f"the checking re-integration (rtol {tight['rtol']:g}) of the candidate return at "
                                  f"t = {float(cr.t[j]):.6g} failed: {chk.why}")
                        done[loc] = True
                        continue
                if found is None:
                    continue
                closure[k] = found[1] if not np.isfinite(closure[k]) else min(closure[k], found[1])
                # closed relative to |s0| and to the orbit's own size (sampled on the checking re-integration):
                # a small quasi-periodic orbit near an equilibrium comes back within tol |s0| without closing
                size = np.inf if tight is None else checks[k].size
                if found[1] <= tol and (found[1] <= ORBIT_CLOSURE * size or found[1] <= CLOSURE_FLOOR):
                    T[k], Rm[k], Rt[k], dist[k], closure[k], status[k] = cr.t[j], cr.g[j], found[2], d, found[1], 0
                    T_check[k] = found[0]
                    done[loc] = True
            failed = (win.status < 0) & ~done
            status[rows[failed]] = -1
            why[rows[failed]] = win.why[failed]
            omega[rows] = win.omega
            if Gamma is not None:
                Gamma[rows] = win.Gamma
            g[rows] = win.g
            active[rows[done | failed]] = False
        t_a = np.where(active, t_b, t_a)
        width = np.where(active, 2.0 * width, width)
        active &= t_a < t_max


def _is_free_body(system) -> bool:
    return (system.is_so and system.n == 3 and system.constraints.dim == system.algebra.dim
            and not system.has_potential and system.gyroscopic == 0.0)


def _vec3(x: np.ndarray) -> np.ndarray:
    """so(3) coordinates ``(Omega_12, Omega_13, Omega_23)`` to the vector ``(-Omega_23, Omega_13, -Omega_12)``."""
    return np.stack([-x[..., 2], x[..., 1], -x[..., 0]], axis=-1)


def _axes(system, b, Rm, Rt, ok, axis, angle, kind) -> None:
    """n = 3: the axis (M0 for the free body, else Gamma0, else R's own) and the signed angle about it.

    ``R`` fixes the unit vector ``u`` when ``|R u - u| <= FIX_FLOOR + FIX_FACTOR eps``, ``eps = |R - Rt|_2`` the
    error of ``R`` estimated by the checking re-integration ``Rt``: an exactly fixed vector is moved by at
    most ``eps`` (plus ``Rt``'s own, much smaller, error).
    """
    M0 = _vec3(system.inertia(b.omega))
    nM = np.linalg.norm(M0, axis=-1)
    # the momentum is an axis of R only where it is conserved (the free body): elsewhere R may fix M0 by
    # coincidence (Kharlamova with M0 ~ -3 Gamma0), and the axis would flip between nearby states
    free = _is_free_body(system)
    for k in np.nonzero(ok)[0]:
        Rk = Rm[k]
        eps = float(np.linalg.norm(Rk - Rt[k], 2)) if np.all(np.isfinite(Rt[k])) else 0.0
        fix_tol = FIX_FLOOR + FIX_FACTOR * eps
        cands = []
        if free and nM[k] > 0:
            cands.append(("momentum", M0[k] / nM[k]))
        if b.Gamma is not None:
            cands.append(("gamma", b.Gamma[k]))
        for name, a in cands:
            if np.linalg.norm(Rk @ a - a) <= fix_tol:
                axis[k], angle[k] = axis_angle(Rk, a)
                kind[k] = name
                break
        else:
            axis[k], angle[k] = axis_angle(Rk)
            kind[k] = "own"


def _montgomery(system, b, T, ok, opts, samples, dyn, geo) -> None:
    """Free body: ``2 E T / |M0|`` and the solid angle on the left of ``M/|M|`` over one period."""
    E = system.energy(b.omega)
    M0 = _vec3(system.inertia(b.omega))
    dyn[ok] = (2.0 * E * T / np.linalg.norm(M0, axis=-1))[ok]
    from ..integrators import integrate

    for k in np.nonzero(ok)[0]:
        tt = np.linspace(0.0, T[k], samples + 1)
        sol = integrate(system, b.omega[k], (0.0, T[k]), t_eval=tt, **opts)
        M = _vec3(system.inertia(sol.omega[:-1]))
        u = M / np.linalg.norm(M, axis=-1, keepdims=True)
        geo[k] = solid_angle(u, T[k] / samples)
