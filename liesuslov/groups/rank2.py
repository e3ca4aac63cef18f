"""Rank-2 elements a ∧ b (plane rotations): exp and Cayley in closed form, their action; re-orthonormalisation."""

from __future__ import annotations

import numpy as np

from .common import _dot, _eye, _rodrigues


# ---------------------------------------------------------------------------- rank-2 (plane rotations)
def _rank2_factors(a: np.ndarray, b: np.ndarray, chart: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``p``, ``x``, ``y`` (broadcast shape (..., n)) with ``φ(a ∧ b) = I + a xᵀ + p yᵀ``.

    ``p = b − (a·b)/|a|² a`` is b made orthogonal to a; ``a ∧ p = a ∧ b`` and ``θ = |a||p|``. With
    ``a ⊥ p``, ``(a ∧ p)² = −|p|² a aᵀ − |a|² p pᵀ`` and ``φ(Ω) = I + α Ω + β Ω²`` (exp:
    ``α = sin θ/θ``, ``β = (1 − cos θ)/θ²``; Cayley: ``α = 4/(4 + θ²)``, ``β = 2/(4 + θ²)``), so
    ``x = α p − β|p|² a`` and ``y = −α a − β|a|² p``. Orthogonalising first keeps every term of
    size ``O(θ)``: the textbook ``θ² = |a|²|b|² − (a·b)²`` form loses ``ε (|a||b|)²`` when a and b
    are nearly parallel. In the Fedorov–Kozlov case ``a·b = 0`` and ``p = b`` exactly.
    """
    if a.ndim == 1 and b.ndim == 1:  # one pair: scalar dot products (a numpy call each saved)
        aa = float(a @ a)
        p = b - (float(a @ b) / aa) * a if aa > 0.0 else b
        pp = float(p @ p)
    else:
        aa = _dot(a, a)
        # a = 0 gives Ω = 0 whatever p is: divide by 1 there instead of 0
        p = b - (_dot(a, b) / np.where(aa > 0.0, aa, 1.0)) * a
        pp = _dot(p, p)
    t2 = aa * pp
    if chart == "exp":
        _, alpha, beta = _rodrigues(t2)
    else:
        beta = 2.0 / (4.0 + t2)
        alpha = 2.0 * beta
    return p, alpha * p - (beta * pp) * a, -alpha * a - (beta * aa) * p


def _rank2_matrix(a: np.ndarray, b: np.ndarray, chart: str) -> np.ndarray:
    p, x, y = _rank2_factors(a, b, chart)
    return _eye(x.shape[-1]) + a[..., :, None] * x[..., None, :] + p[..., :, None] * y[..., None, :]


def _rank2_apply(g: np.ndarray, a: np.ndarray, b: np.ndarray, chart: str) -> np.ndarray:
    # g φ(a ∧ b) = g + (g a) xᵀ + (g p) yᵀ: two matrix-vector products and two outer products
    p, x, y = _rank2_factors(a, b, chart)
    return g + (g @ a[..., :, None]) * x[..., None, :] + (g @ p[..., :, None]) * y[..., None, :]


def _rank2_apply_vec(a: np.ndarray, b: np.ndarray, v: np.ndarray, chart: str) -> np.ndarray:
    p, x, y = _rank2_factors(a, b, chart)
    return v + _dot(x, v) * a + _dot(y, v) * p


def exp_rank2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``exp(a ∧ b)``, the rotation by θ in the plane of a and b.

    ``exp(a ∧ b) = I + (sin θ/θ)(a ∧ b) + ((1 − cos θ)/θ²)(a ∧ b)²``, ``θ² = |a|²|b|² − (a·b)²``,
    assembled as the rank-2 update ``I + a xᵀ + p yᵀ`` with ``p = b − (a·b)/|a|² a``,
    ``θ = |a||p|``, ``x = α p − β|p|² a``, ``y = −α a − β|a|² p``, ``α = sin θ/θ``,
    ``β = (1 − cos θ)/θ²`` (see ``_rank2_factors``). No small-angle issue (see ``_rodrigues``).

    Parameters
    ----------
    a, b : ndarray, shape (..., n)
        Broadcast against each other (e.g. ``b = e_n`` of shape (n,) for the Fedorov–Kozlov ``D``).

    Returns
    -------
    ndarray, shape (..., n, n)
        In SO(n).
    """
    return _rank2_matrix(a, b, "exp")


def apply_exp_rank2(g: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``g exp(a ∧ b) = g + (g a) xᵀ + (g p) yᵀ`` in O(n²) per matrix (p, x, y as in :func:`exp_rank2`).

    Only the matrix-vector products ``g a``, ``g p`` and two outer products are formed — no
    n×n by n×n product.

    Parameters
    ----------
    g : ndarray, shape (..., n, n)
    a, b : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    return _rank2_apply(g, a, b, "exp")


def exp_rank2_apply_vec(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``exp(a ∧ b) v = v + (x·v) a + (y·v) p`` in O(n) (p, x, y as in :func:`exp_rank2`).

    Parameters
    ----------
    a, b, v : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n)
    """
    return _rank2_apply_vec(a, b, v, "exp")


def cayley_rank2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``cay(a ∧ b) = I + 4/(4 + θ²)(a ∧ b) + 2/(4 + θ²)(a ∧ b)²``, the plane rotation by ``2 arctan(θ/2)``.

    Parameters
    ----------
    a, b : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    return _rank2_matrix(a, b, "cayley")


def apply_cayley_rank2(g: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``g cay(a ∧ b)`` in O(n²) per matrix (rank-2 update, as :func:`apply_exp_rank2`).

    Parameters
    ----------
    g : ndarray, shape (..., n, n)
    a, b : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    return _rank2_apply(g, a, b, "cayley")


def cayley_rank2_apply_vec(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``cay(a ∧ b) v`` in O(n), shapes as :func:`exp_rank2_apply_vec`."""
    return _rank2_apply_vec(a, b, v, "cayley")


def orthonormalize(g: np.ndarray) -> np.ndarray:
    """One Newton–Schulz step toward the nearest orthogonal matrix: ``g (3I − gᵀg) / 2``.

    Each product ``g ← g φ(Θ)`` adds a rounding error of ~1e-16 to ``gᵀg − I``; when the steps are
    alike these errors add up linearly (≈5e-13 after 1e5 RKMK4 steps in a Klebsh–Tisserand scene,
    whichever Rodrigues variant is used). For ``g = Q(I + E)`` with ``E`` symmetric and ``|E| = δ``
    this step returns ``Q(I + O(δ²))``: the polar factor to rounding while ``δ < 1e-8``. Two matrix
    products; apply it every k steps (k = 100 keeps ``|gᵀg − I|`` ~1e-15).

    Parameters
    ----------
    g : ndarray, shape (..., n, n)
        Close to orthogonal.

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    return g @ (1.5 * _eye(g.shape[-1]) - 0.5 * (np.swapaxes(g, -1, -2) @ g))
