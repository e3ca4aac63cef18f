"""Brackets, dexp and its inverse (the truncated Bernoulli series, exact on so(3)), and the Cayley chart's
inverse derivative."""

from __future__ import annotations

import math
from fractions import Fraction
from functools import cache
from math import comb, factorial

import numpy as np

from .common import _DEXP3_TAYLOR, _Coef
from .so3 import _hat_c, _so3_lin, _so3_lin_c, _sq, _vec_c, _vee_c


# ---------------------------------------------------------------------------- brackets
def bracket(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Matrix commutator ``[X, Y] = X Y − Y X``, batched (..., n, n)."""
    return X @ Y - Y @ X


def bracket_skew(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """``[X, Y]`` for skew X, Y with one product: ``Y X = (X Y)ᵀ``, so ``[X, Y] = P − Pᵀ``, ``P = X Y``."""
    P = X @ Y
    return P - np.swapaxes(P, -1, -2)


# ---------------------------------------------------------------------------- dexp and its inverse
@cache
def bernoulli_coefficients(order: int) -> tuple[tuple[int, float], ...]:
    """Nonzero ``(k, B_k / k!)`` for ``k < order`` (``B_1 = −1/2``; ``B_k = 0`` for odd k > 1).

    Exact rational recurrence ``B_m = −1/(m+1) Σ_{j<m} C(m+1, j) B_j``, cached per order.
    """
    B: list[Fraction] = []
    for m in range(order):
        B.append(Fraction(1) if m == 0 else -sum(comb(m + 1, j) * B[j] for j in range(m)) / (m + 1))
    return tuple((k, float(B[k] / factorial(k))) for k in range(order) if B[k] != 0)


def dexpinv_terms(p: int) -> int:
    """Number of dexp⁻¹ series terms (the ``order`` of :func:`dexpinv`) an RKMK method of order p needs.

    Terms ``k = 0 … p − 2`` suffice (a dropped ``ad^k_Θ`` term costs ``O(h^{k+2})`` per step, since
    ``Θ = O(h)`` and its leading part commutes with the velocity), so this is ``max(p − 1, 1)``;
    with ``p − 2`` terms the method generically has order p − 1 (verified for RK3 and RK4 in
    ``tests/test_groups.py``). For odd p >= 5, ``B_{p−2} = 0`` and the last bracket formed is
    ``ad^{p−3}``.
    """
    return max(p - 1, 1)


def _side_sign(side: str) -> float:
    """+1 for ``side="left"``, −1 for ``"right"``: the right-side map is the left one at ``−Θ``, which
    flips exactly the odd powers of ``ad_Θ`` (B_1 = −½ is the only nonzero odd Bernoulli number)."""
    if side == "right":
        return -1.0
    if side == "left":
        return 1.0
    raise ValueError(f"side must be 'left' or 'right', got {side!r}")


def dexpinv(Theta: np.ndarray, A: np.ndarray, order: int, side: str = "right", *,
            skew: bool = False) -> np.ndarray:
    """Truncated inverse derivative of the exponential, ``Σ_{k<order} (B_k/k!) ad^k A``, batched.

    - ``side="left"`` (``Y' = A Y``, ``Y = exp(Θ) Y0``):
      ``Θ' = dexp⁻¹_Θ(A) = A − ½[Θ, A] + 1/12 [Θ, [Θ, A]] − 1/720 ad⁴_Θ A + …``
    - ``side="right"`` (``g⁻¹ ġ = Ω``, ``g = g0 exp(Θ)``):
      ``Θ' = dexp⁻¹_{−Θ}(Ω) = Ω + ½[Θ, Ω] + 1/12 [Θ, [Θ, Ω]] − 1/720 ad⁴_Θ Ω + …``

    The truncation error is ``O(|Θ|^K)``, K the first even index >= ``order`` (``order = 1``: K = 1).
    The series converges while the eigenvalues of ``ad_Θ`` stay below 2π in modulus: for skew Θ with
    rotation angles θ1 >= θ2 >= …, ``θ1 + θ2 < 2π`` (n = 3: ``θ < 2π``); ``|Θ|_2 < π`` always
    suffices. Brackets whose coefficient vanishes (odd k > 1) are not
    formed: ``order = 3`` or ``4`` costs two brackets, ``5`` or ``6`` four. For an RKMK method of order p
    use ``order = dexpinv_terms(p) = p − 1``.

    Parameters
    ----------
    Theta, A : ndarray, shape (..., n, n)
    order : int
        Number of series terms, ``k = 0 … order − 1`` (>= 1).
    side : {"right", "left"}
        See above; "right" is the body-frame reconstruction of liesuslov.
    skew : bool
        Both Θ and A skew-symmetric: each bracket then costs one matrix product (:func:`bracket_skew`).

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    sign = _side_sign(side)
    terms = bernoulli_coefficients(order)
    if len(terms) < 2:
        return np.array(A, dtype=float)  # a copy: callers may update the result in place
    br = bracket_skew if skew else bracket
    out, ad, k_ad = A, A, 0
    for k, c in terms[1:]:
        while k_ad < k:  # ad^k only where B_k != 0 or a later term needs it
            ad, k_ad = br(Theta, ad), k_ad + 1
        out = out + (c * sign if k == 1 else c) * ad
    return out


def dexp(Theta: np.ndarray, X: np.ndarray, side: str = "right", terms: int = 30) -> np.ndarray:
    """Derivative of the exponential by its series (for tests and diagnostics; entire in Θ).

    - ``side="left"``: ``(d/dt exp(Θ)) exp(−Θ) = dexp_Θ(Θ') = Σ_k ad^k_Θ(Θ') / (k+1)!``
    - ``side="right"``: ``exp(−Θ) d/dt exp(Θ) = dexp_{−Θ}(Θ') = Σ_k (−1)^k ad^k_Θ(Θ') / (k+1)!``

    Parameters
    ----------
    Theta, X : ndarray, shape (..., n, n)
        The point Θ and the tangent Θ'.
    side : {"right", "left"}
    terms : int
        Series terms ``k = 0 … terms − 1``; the error is about ``|Θ|^terms / (terms+1)!``.

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    sign = _side_sign(side)  # −1 on the right: (−ad_Θ)^k
    out = np.array(X, dtype=float)
    ad = X
    for k in range(1, terms):
        ad = bracket(Theta, ad)
        out = out + (sign**k / factorial(k + 1)) * ad
    return out


def _dexp3_coefficient(t2: _Coef) -> _Coef:
    """``(1 − (θ/2) cot(θ/2)) / θ² = 1/12 + θ²/720 + θ⁴/30240 + …`` (valid for θ < 2π)."""
    if not isinstance(t2, np.ndarray) or t2.size == 1:
        t2 = float(t2) if not isinstance(t2, np.ndarray) else t2.item()
        if t2 < _DEXP3_TAYLOR**2:
            return 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 * (1.0 / 1209600.0
                                                                                  + t2 / 47900160.0)))
        x = 0.5 * math.sqrt(t2)
        return (1.0 - x * math.cos(x) / math.sin(x)) / t2
    small = t2 < _DEXP3_TAYLOR**2
    x = 0.5 * np.sqrt(np.where(small, 1.0, t2))
    closed = (1.0 - x * np.cos(x) / np.sin(x)) / (4.0 * x * x)
    series = 1.0 / 12.0 + t2 * (1.0 / 720.0 + t2 * (1.0 / 30240.0 + t2 * (1.0 / 1209600.0 + t2 / 47900160.0)))
    return np.where(small, series, closed)


@cache
def _dexpinv_so3_series(order: int) -> tuple[float, tuple[float, ...]]:
    """``(h, (c_1, c_2, …))`` of the series truncated to ``k < order`` in the so(3) vector form.

    With ``ad_θ a = θ × a`` and ``ad^{2j} = (−θ²)^{j−1} ad²``, ``Σ_{k<order} (B_k/k!) ad^k a`` (left side)
    is ``a − h θ × a + C(θ²) θ × (θ × a)`` with ``h = ½`` if order >= 2 (else 0) and
    ``C(t) = Σ_j c_j t^{j−1}``, ``c_j = (B_{2j}/(2j)!) (−1)^{j−1}`` for ``2j < order``:
    ``1/12 + t/720 + t²/30240 + …``, the Taylor polynomial of the exact coefficient.
    """
    terms = bernoulli_coefficients(order)
    h = 0.5 if any(k == 1 for k, _ in terms) else 0.0
    return h, tuple(c * (-1.0) ** (k // 2 - 1) for k, c in terms if k >= 2)


def _dexpinv_so3_poly(t2: _Coef, poly: tuple[float, ...]) -> _Coef:
    """``C(t2)`` of :func:`_dexpinv_so3_series` by Horner's rule (0.0 for an empty polynomial)."""
    c = 0.0
    for a in reversed(poly):
        c = c * t2 + a
    return c


def dexpinv_so3(theta_vec: np.ndarray, a_vec: np.ndarray, side: str = "right", order: int | None = None) -> np.ndarray:
    """``dexp⁻¹`` on so(3) in the vector form: ``a ∓ ½ θ × a + c(θ) θ × (θ × a)``, exact or truncated.

    Exact (``order=None``): ``c(θ) = (1 − (θ/2) cot(θ/2)) / θ²`` (series below θ = 0.1);
    ``θ × (θ × a) = (θ·a) θ − θ² a``. Singular at ``|θ| = 2π`` (where exp is not a local diffeomorphism).
    Truncated (``order`` an int): the series ``Σ_{k<order} (B_k/k!) ad^k`` of :func:`dexpinv`, in closed
    form: ``c`` becomes its Taylor polynomial ``1/12 + θ²/720 + θ⁴/30240 + …`` through ``θ^{order−4}``
    (no ``θ × (θ × a)`` term for order <= 2, no ``θ × a`` term for order 1). On so(4) ≅ so(3) ⊕ so(3)
    the truncated series of :func:`dexpinv` is this on each factor (see :func:`so4_split`).
    The upper sign is ``side="left"`` (``dexp⁻¹_θ``), the lower ``side="right"`` (``dexp⁻¹_{−θ}``).

    Parameters
    ----------
    theta_vec, a_vec : ndarray, shape (..., 3)
    side : {"right", "left"}
    order : int, optional
        Number of series terms ``k < order`` (as for :func:`dexpinv`); None for the exact map.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    sign = _side_sign(side)
    th = _vec_c(theta_vec)
    t2 = _sq(th)
    if order is None:
        h, c = 0.5, _dexp3_coefficient(t2)
    else:
        h, poly = _dexpinv_so3_series(order)
        c = _dexpinv_so3_poly(t2, poly)
    # c θ × (θ × a) = c (θ·a) θ − c θ² a
    return _so3_lin(1.0 - c * t2, -h * sign, c, th, _vec_c(a_vec), theta_vec.shape[:-1], a_vec.shape[:-1])


def dexpinv_skew3(Theta: np.ndarray, A: np.ndarray, side: str = "right") -> np.ndarray:
    """Exact ``dexp⁻¹`` for 3×3 skew matrices: ``A ∓ ½[Θ, A] + c(θ)[Θ, [Θ, A]]`` (see :func:`dexpinv_so3`).

    Parameters
    ----------
    Theta, A : ndarray, shape (..., 3, 3)
        Skew-symmetric.
    side : {"right", "left"}

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    sign = _side_sign(side)
    th = _vee_c(Theta)
    t2 = _sq(th)
    c = _dexp3_coefficient(t2)
    # in the vector form (no 3×3 products), back to a matrix by hat
    return _hat_c(_so3_lin_c(1.0 - c * t2, -0.5 * sign, c, th, _vee_c(A)), Theta.shape[:-2], A.shape[:-2])


def dcayinv(Theta: np.ndarray, A: np.ndarray, side: str = "right") -> np.ndarray:
    """Exact inverse derivative of the Cayley map, any square matrices, batched.

    With ``cay(Θ) = −I + 2 (I − Θ/2)⁻¹``: ``d/dt cay(Θ) = (I − Θ/2)⁻¹ Θ' (I − Θ/2)⁻¹``, hence

    - ``side="left"`` (``Y = cay(Θ) Y0``, ``Y' = A Y``): ``Θ' = (I − Θ/2) A (I + Θ/2)``;
    - ``side="right"`` (``g = g0 cay(Θ)``, ``g⁻¹ ġ = Ω``): ``Θ' = (I + Θ/2) Ω (I − Θ/2)``
      ``= Ω + ½[Θ, Ω] − ¼ Θ Ω Θ``.

    Computed as ``M ∓ ½ M Θ`` with ``M = A ± ½ Θ A`` (two products).

    Parameters
    ----------
    Theta, A : ndarray, shape (..., n, n)
    side : {"right", "left"}

    Returns
    -------
    ndarray, shape (..., n, n)
    """
    h = -0.5 * _side_sign(side)  # +½ on the right, −½ on the left
    M = A + h * (Theta @ A)
    return M - h * (M @ Theta)


def dcayinv_so3(theta_vec: np.ndarray, a_vec: np.ndarray, side: str = "right") -> np.ndarray:
    """:func:`dcayinv` in the so(3) vector form: ``a ∓ ½ θ × a + ¼ (θ·a) θ`` (upper sign: left).

    From ``hat θ hat a hat θ = −(θ·a) hat θ``.

    Parameters
    ----------
    theta_vec, a_vec : ndarray, shape (..., 3)
    side : {"right", "left"}

    Returns
    -------
    ndarray, shape (..., 3)
    """
    return _so3_lin(1.0, -0.5 * _side_sign(side), 0.25, _vec_c(theta_vec), _vec_c(a_vec),
                    theta_vec.shape[:-1], a_vec.shape[:-1])


def dcayinv_skew3(Theta: np.ndarray, A: np.ndarray, side: str = "right") -> np.ndarray:
    """:func:`dcayinv` for 3×3 skew matrices by components (no 3×3 products): hat of :func:`dcayinv_so3`.

    Parameters
    ----------
    Theta, A : ndarray, shape (..., 3, 3)
        Skew-symmetric (only ``vee`` of each is read).
    side : {"right", "left"}

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    return _hat_c(_so3_lin_c(1.0, -0.5 * _side_sign(side), 0.25, _vee_c(Theta), _vee_c(A)),
                  Theta.shape[:-2], A.shape[:-2])
