"""Group maps: exponential and Cayley charts, their inverse derivatives, and closed forms.

Everything here is batch-first and allocation-light, because the RKMK integrator calls it inside
its stage loop: matrices have shape ``(..., n, n)``, vectors ``(..., n)``, and leading axes
broadcast. No function validates its input (callers do, with :mod:`liesuslov._validation`), none
loops over the batch in Python, and cross products are written by components (``np.cross`` costs
~15 µs a call). This module imports only numpy and scipy: it is the layer below the mechanics.

Speed: numpy spends ~0.3–1 µs per call on tiny arrays, so a single element (shape (3, 3), (1, 3, 3),
(3,), …) takes a Python-float path in the n = 3 closed forms (~1.5 µs instead of ~13), and a batch
takes component-wise 1-D arithmetic (np.matmul on stacked 3×3 matrices costs ~70 ns each). Both
paths evaluate the same expressions (``_so3_lin_c``, ``_so3_mat``) and are tested against each other.

Conventions (``docs/notation.md``, ``MATH.md``)
-----------------------------------------------
- so(n): skew ``n×n`` matrices; for n = 3, ``hat(w) v = w × v`` and ``w = (X21, X02, X10)``
  (0-based), ``[hat a, hat b] = hat(a × b)``.
- ``a ∧ b = a bᵀ − b aᵀ``; ``θ² = |a|²|b|² − (a·b)²`` is the squared rotation angle of its
  exponential (the Fedorov–Kozlov distribution ``D = span{E_in}`` consists of such elements,
  ``Ω = u ∧ e_n``).
- Cayley map: ``cay(X) = (I − X/2)⁻¹ (I + X/2)``.
- Side of the chart, for the inverse derivatives:

  * ``side="right"`` — the body-frame reconstruction ``g⁻¹ ġ = Ω`` written ``g = g0 φ(Θ)``:
    ``Θ' = dexp⁻¹_{−Θ}(Ω) = Ω + ½[Θ, Ω] + 1/12 [Θ, [Θ, Ω]] − …`` (exp) and
    ``Θ' = (I + Θ/2) Ω (I − Θ/2)`` (Cayley);
  * ``side="left"`` — ``Y' = A Y`` written ``Y = φ(Θ) Y0``:
    ``Θ' = dexp⁻¹_Θ(A) = A − ½[Θ, A] + 1/12 [Θ, [Θ, A]] − …`` and ``Θ' = (I − Θ/2) A (I + Θ/2)``.

  Only the odd (first-order) term changes sign between the sides; the wrong side silently turns
  RKMK4 into an order-2 method (``tests/test_groups.py`` shows it).

Truncating dexp⁻¹ for an RKMK method of order p: keep the terms ``k <= p − 2`` of
``Σ B_k/k! ad^k``, i.e. ``dexpinv(Theta, A, order=dexpinv_terms(p))`` with
``dexpinv_terms(p) = p − 1``. Each dropped term ``ad^k_Θ`` contributes ``O(h^{k+2})`` to the step,
not ``O(h^{k+1})``, because ``Θ = h c A + O(h²)`` and ``[A, A] = 0`` (Hairer–Lubich–Wanner,
*Geometric Numerical Integration*, IV.8.2; Munthe-Kaas 1999).
"""

from __future__ import annotations

from .cayley import (  # noqa: F401
    _CAYLEY_LIMIT,
    _CAYLEY_POLISH,
    cayley,
    cayley_apply,
    cayley_skew,
    cayley_skew_apply,
    cayley_so3,
    cayley_so3_apply,
)
from .common import (  # noqa: F401
    _DEXP3_TAYLOR,
    _I,
    _J,
    _SINC_TAYLOR,
    _cayley_coefficients,
    _Coef,
    _dot,
    _eye,
    _rodrigues,
    _solve,
    cross3,
)
from .dexp import (  # noqa: F401
    _dexp3_coefficient,
    _dexpinv_so3_poly,
    _dexpinv_so3_series,
    _side_sign,
    bernoulli_coefficients,
    bracket,
    bracket_skew,
    dcayinv,
    dcayinv_skew3,
    dcayinv_so3,
    dexp,
    dexpinv,
    dexpinv_skew3,
    dexpinv_so3,
    dexpinv_terms,
)
from .expm import (  # noqa: F401
    _PADE_B,
    _PADE_THETA,
    _expm_pade,
    _pade_coefficients,
    _pade_uv,
    expm,
    expm_skew,
    expm_skew_apply,
    expm_so3,
    expm_so3_apply,
)
from .rank2 import (  # noqa: F401
    _rank2_apply,
    _rank2_apply_vec,
    _rank2_factors,
    _rank2_matrix,
    apply_cayley_rank2,
    apply_exp_rank2,
    cayley_rank2,
    cayley_rank2_apply_vec,
    exp_rank2,
    exp_rank2_apply_vec,
    orthonormalize,
)
from .so3 import (  # noqa: F401
    _POLY_MIN_SIZE,
    _POLY_T2,
    _POLY_TERMS,
    _SINC_POLY,
    _VERS_POLY,
    _dexp3_series,
    _hat_c,
    _horner,
    _rodrigues_dexp3,
    _rodrigues_fast,
    _rodrigues_poly,
    _sinc_half,
    _so3_lin,
    _so3_lin_c,
    _so3_mat,
    _sq,
    _stack,
    _vec4_c,
    _vec_c,
    _vee_c,
)
from .so4 import (  # noqa: F401
    _SO4_CAYLEY_MIN_BATCH,
    _SO4_EXP_MIN_BATCH,
    _cos_sinc,
    _so4_cayley_coefficients,
    _so4_dcayinv_c,
    _so4_dexpinv_c,
    _so4_exp_apply_c,
    _so4_exp_coefficients,
    _so4_exp_mat_c,
    _so4_lin_apply_c,
    _so4_mat_c,
    _so4_pq_c,
    _so4_pv_c,
    _so4_qv_c,
    so4_join,
    so4_split,
)

__all__ = [
    "expm_skew", "expm", "expm_skew_apply", "expm_so3", "expm_so3_apply",
    "cayley", "cayley_apply", "cayley_skew", "cayley_skew_apply", "cayley_so3", "cayley_so3_apply",
    "so4_split", "so4_join",
    "exp_rank2", "apply_exp_rank2", "exp_rank2_apply_vec",
    "cayley_rank2", "apply_cayley_rank2", "cayley_rank2_apply_vec",
    "bracket", "bracket_skew", "cross3", "orthonormalize",
    "dexp", "dexpinv", "dexpinv_terms", "dexpinv_so3", "dexpinv_skew3",
    "dcayinv", "dcayinv_so3", "dcayinv_skew3", "bernoulli_coefficients",
]
