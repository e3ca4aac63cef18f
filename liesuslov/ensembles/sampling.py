"""Initial data drawn on the workers: samplers from spawned seeds, reproducible whatever the chunking."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import as_float_array
from .checks import _positive_int
from .constants import (
    _INIT_KEYS,
    SAMPLER_BLOCK,
)


# ====================================================================== sampling
@dataclass(frozen=True)
class Perturbation:
    """A sampler of initial data near a base point (module-level, so it pickles to any worker).

    ``Omega0 = Omega_base + scale * z @ basis`` with ``z`` standard normal (k,), so Omega0 stays in
    the constraint subspace D spanned by ``basis``; ``Gamma0 = (Gamma_base + gamma_scale * w) / |...|``
    with ``w`` standard normal (n,), a unit vector; ``g0`` is kept as given. Build it with
    :meth:`around`.

    Parameters
    ----------
    omega : ndarray, shape (d,)
        Base Omega in algebra coordinates.
    basis : ndarray, shape (k, d)
        Rows spanning D (``system.constraints.basis``).
    Gamma0 : ndarray, shape (n,), optional
    g0 : ndarray, shape (m, m), optional
    scale : float
        Standard deviation of the perturbation of Omega along each basis row.
    gamma_scale : float, optional
        Standard deviation of the perturbation of Gamma0 per component (default: ``scale``).
    """

    omega: np.ndarray
    basis: np.ndarray
    Gamma0: np.ndarray | None = None
    g0: np.ndarray | None = None
    scale: float = 1e-2
    gamma_scale: float | None = None

    @classmethod
    def around(cls, system, Omega0, *, Gamma0=None, g0=None, scale: float = 1e-2,
               gamma_scale: float | None = None) -> Perturbation:
        """The perturbation of one initial state of ``system`` (Omega0 a matrix (n, n) or coordinates (d,))."""
        alg = system.algebra
        O = np.asarray(Omega0, dtype=float)
        omega = alg.vee(O) if O.shape != (alg.dim,) and O.ndim == 2 else O
        if omega.shape != (alg.dim,):
            raise ValueError(f"Omega0 must be one state: shape ({alg.dim},) or a matrix, got {O.shape}")
        for name, v in (("scale", scale), ("gamma_scale", gamma_scale)):
            if v is not None and (isinstance(v, bool) or not np.isfinite(v) or v < 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        basis = np.asarray(system.constraints.basis, dtype=float)
        G = None if Gamma0 is None else np.asarray(Gamma0, dtype=float)
        g = None if g0 is None else np.asarray(g0, dtype=float)
        return cls(omega, basis, G, g, float(scale), None if gamma_scale is None else float(gamma_scale))

    def __call__(self, rng: np.random.Generator, size: int) -> dict[str, np.ndarray]:
        """Draw ``size`` initial states: ``Omega0`` (size, d), ``Gamma0`` (size, n), ``g0`` (size, m, m)."""
        z = rng.standard_normal((size, self.basis.shape[0]))
        out = {"Omega0": self.omega + self.scale * (z @ self.basis)}
        if self.Gamma0 is not None:
            s = self.scale if self.gamma_scale is None else self.gamma_scale
            G = self.Gamma0 + s * rng.standard_normal((size, self.Gamma0.shape[-1]))
            out["Gamma0"] = G / np.linalg.norm(G, axis=-1, keepdims=True)
        if self.g0 is not None:
            out["g0"] = np.broadcast_to(self.g0, (size,) + self.g0.shape).copy()
        return out


def _seed_parts(seed) -> tuple[Any, tuple[int, ...], int]:
    """(entropy, spawn_key, pool_size) of ``SeedSequence(seed)``: workers rebuild block ``j``'s child."""
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(_check_seed(seed))
    return ss.entropy, tuple(ss.spawn_key), ss.pool_size


def _check_seed(seed):
    """``seed`` as ``SeedSequence`` takes it (None, an integer >= 0 or a sequence of them), else a clear error.

    numpy's own messages ("SeedSequence expects int or sequence of ints for entropy not x", "expected
    non-negative integer") do not say which argument; a bool would be read as 0 or 1.
    """
    want = "seed must be None, an integer >= 0, a sequence of them or a numpy.random.SeedSequence"
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)):
        raise TypeError(f"{want}, got the boolean {seed!r}")
    if isinstance(seed, (int, np.integer)):
        if seed < 0:
            raise ValueError(f"{want}, got {seed}; pass a non-negative integer")
        return int(seed)
    if isinstance(seed, (str, bytes)):
        raise TypeError(f"{want}, got the string {seed!r}; pass an integer such as 12345")
    try:
        values = list(seed)
    except TypeError:
        raise TypeError(f"{want}, got {type(seed).__name__}") from None
    if not values or any(isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) for v in values):
        raise TypeError(f"{want}, got {seed!r}; a sequence must hold integers (at least one)")
    if any(v < 0 for v in values):
        raise ValueError(f"{want}, got {seed!r}; every integer of a sequence must be >= 0")
    return [int(v) for v in values]


def _draw_range(sampler, seed_parts, start: int, stop: int, block: int) -> dict[str, np.ndarray]:
    """Trajectories ``[start, stop)`` of a sampler run: whole blocks drawn, then sliced."""
    entropy, key, pool = seed_parts
    parts: dict[str, list[np.ndarray]] = {}
    for j in range(start // block, -(-stop // block)):
        # the j-th child of SeedSequence(seed).spawn(...), built directly (no need to spawn j others)
        rng = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=key + (j,), pool_size=pool))
        drawn = sampler(rng, block)
        if not isinstance(drawn, Mapping) or "Omega0" not in drawn:
            raise TypeError(f"sampler must return a dict with 'Omega0' (and optionally 'Gamma0', 'g0'), got "
                            f"{type(drawn).__name__}")
        extra = set(drawn) - set(_INIT_KEYS)
        if extra:
            raise ValueError(f"sampler returned unknown keys {sorted(extra)}; allowed: {list(_INIT_KEYS)}")
        lo, hi = max(start, j * block) - j * block, min(stop, (j + 1) * block) - j * block
        for k, v in drawn.items():
            # integrate's conversion: complex or boolean draws are a TypeError, not silently cast
            v = as_float_array(v, f"sampler's {k!r}", finite=False)
            if v.ndim == 0 or v.shape[0] != block:
                raise ValueError(f"sampler(rng, size) must return arrays with a leading axis of length size "
                                 f"({block}); {k!r} has shape {v.shape}")
            parts.setdefault(k, []).append(v[lo:hi])
    return {k: np.concatenate(v) for k, v in parts.items()}


def draw(sampler: Callable, n: int, seed=None, *, start: int = 0, stop: int | None = None,
         block: int = SAMPLER_BLOCK) -> dict[str, np.ndarray]:
    """The initial data an :func:`ensemble` run with ``sampler``, ``n`` and ``seed`` integrates.

    Parameters
    ----------
    sampler : callable
        ``sampler(rng, size) -> {"Omega0": (size, ...), "Gamma0": (size, n), "g0": (size, m, m)}``.
    n : int
        Number of trajectories.
    seed : int >= 0, sequence of them, SeedSequence or None
        As passed to :func:`ensemble` (None is not reproducible: pass the ``stats["seed"]`` of a run).
    start, stop : int
        Only trajectories ``[start, stop)`` (default all ``n``).
    block : int
        Trajectories drawn per generator (:data:`SAMPLER_BLOCK`, as :func:`ensemble` draws them; another
        value draws other numbers).

    Returns
    -------
    dict of ndarray
        Leading axis ``stop - start``.
    """
    n = _positive_int(n, "n")
    stop = n if stop is None else stop
    if not 0 <= start <= stop <= n:
        raise ValueError(f"need 0 <= start <= stop <= n, got start={start}, stop={stop}, n={n}")
    return _draw_range(sampler, _seed_parts(seed), start, stop, block)
