"""The stage plan of a method: which stages a step evaluates, with which coefficients — one source for both solvers.

A :class:`StagePlan` is derived once from a :class:`~liesuslov.integrators.tableaux.ButcherTableau` and is
all the numpy solver (:mod:`.solve_numpy`) and the compiled kernel (:mod:`.kernel`) know about the method.
Stages are numbered::

    0 … s-1      the method's stages (every trial step);
    s            the derivative at the new point, A row = b, c = 1 (FSAL methods: a copy of stage s-1;
                 evaluated in a trial step only when an error estimator reads it, otherwise only when
                 the continuous extension needs it);
    s+1 … S-1    the extra stages of a continuous extension (DOP853's three), evaluated only for an
                 accepted step whose interior is asked for (t_eval, events, dense output).

A stage's argument is ``Xi_i = xi + h sum_j A[i, j] L_j``, ``Theta_i = h sum_j A[i, j] K_j`` (L the field, K the
chart velocity): the compiled kernel stores ``h L_j``, ``h K_j`` and sums term by term; the numpy stepper
adds ``(A[i, j] h) L_j`` row by row, elementwise over the batch, each trajectory with its own h — the same method,
agreeing to rounding. Neither reduces across trajectories, so a trajectory's numbers do not depend on its
batch mates.

Continuous extension: ``xi(t + theta h) = xi + sum_j b_j(theta) (h L_j)`` and ``Theta(theta) = sum_j
b_j(theta) (h K_j)`` with ``b(theta) = dense @ [theta, …, theta^p]``; then ``g = g0 phi(Theta(theta))`` and
``Gamma = phi(-Theta(theta)) Gamma0``, exact in structure. Methods without their own extension get the
cubic Hermite interpolant in the chart, ``b(theta) = h01(theta) b + h10(theta) e_0 + h11(theta) e_s``, which
uses the derivative at the new point (order 3).

The new-point rule (one rule for nfev in both solvers): the next step's stage 0 reuses stage s of an
accepted step when stage s was evaluated (its field value at the new point); otherwise stage 0 is
evaluated. A rejected step keeps stage 0.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .tableaux import ButcherTableau, get_tableau

__all__ = ["StagePlan", "make_plan", "plan_for", "dense_weights"]


@dataclass(frozen=True, eq=False)
class StagePlan:
    """The stages of a method and their coefficients (read-only arrays).

    Attributes
    ----------
    name : str
        The tableau's name.
    s : int
        Stages of a trial step.
    S : int
        All stages (``s + 1 + extra``).
    A : (S, S) ndarray
        Strictly lower triangular: ``A[i, :i]`` combines the scaled stages of stage i; row s is b.
    c : (S,) ndarray
        Nodes.
    b : (S,) ndarray
        Weights of the step (zero past s - 1).
    err : (ne, S) ndarray
        Error weights (``b - b_hat``, or DOP853's E5 and E3) times the method's ``error_scale``; ``ne = 0`` for
        fixed-step methods.
    dense : (S, p) ndarray
        Continuous-extension weights: ``b_j(theta) = sum_q dense[j, q] theta^(q+1)``.
    order, error_order, dense_order : int
        ``error_order`` is 0 without an estimator.
    error_scale : float
        The factor in ``err`` (the method's calibration of its estimate; 1 for the tableau's own).
    error_exponent : float
        ``-1 / (error_order + 1)`` (0 without an estimator).
    fsal : bool
        Stage s - 1 sits at the new point with A row b: stage s is a copy of it.
    new_in_step : bool
        A trial step evaluates stage s (an estimator reads it and the method is not FSAL).
    step_stages : int
        Stages evaluated by a trial step: ``s`` (+1 when ``new_in_step``).
    """

    name: str
    s: int
    S: int
    A: np.ndarray
    c: np.ndarray
    b: np.ndarray
    err: np.ndarray
    dense: np.ndarray
    order: int
    error_order: int
    dense_order: int
    error_exponent: float
    error_scale: float
    fsal: bool
    new_in_step: bool
    step_stages: int

    @property
    def adaptive(self) -> bool:
        """Whether the method has an error estimator."""
        return self.err.shape[0] > 0

    @property
    def two_estimators(self) -> bool:
        """DOP853's combined estimator (E5 and E3)."""
        return self.err.shape[0] == 2


def make_plan(tableau: ButcherTableau, error_scale: float = 1.0) -> StagePlan:
    """The stage plan of ``tableau`` (see the module docstring); its error weights times ``error_scale`` (a
    method's calibration of its estimate: every norm of :mod:`.control` scales with the weights)."""
    s = tableau.stages
    extra = 0 if tableau.dense_A is None else tableau.dense_A.shape[0]
    S = s + 1 + extra
    A = np.zeros((S, S))
    A[:s, :s] = tableau.A
    A[s, :s] = tableau.b
    c = np.zeros(S)
    c[:s] = tableau.c
    c[s] = 1.0
    if extra:
        A[s + 1:, :] = tableau.dense_A
        c[s + 1:] = tableau.dense_c
    b = np.zeros(S)
    b[:s] = tableau.b
    err = np.zeros((len(tableau.error_weights), S))
    for r, w in enumerate(tableau.error_weights):
        err[r, : len(w)] = error_scale * w
    if tableau.dense is not None:
        dense = np.zeros((S, tableau.dense.shape[1]))
        dense[: tableau.dense.shape[0]] = tableau.dense
        dense_order = int(tableau.dense_order)
    else:  # cubic Hermite in the chart: h01 b + h10 e_0 + h11 e_s (powers theta, theta^2, theta^3)
        dense = np.zeros((S, 3))
        dense[:, 1] += 3.0 * b
        dense[:, 2] += -2.0 * b
        dense[0] += (1.0, -2.0, 1.0)
        dense[s] += (0.0, -1.0, 1.0)
        dense_order = min(3, tableau.order)
    fsal = bool(tableau.fsal)
    new_in_step = bool(np.any(err[:, s] != 0)) and not fsal
    for arr in (A, c, b, err, dense):
        arr.setflags(write=False)
    return StagePlan(name=tableau.name, s=s, S=S, A=A, c=c, b=b, err=err, dense=dense, order=int(tableau.order),
                     error_order=int(tableau.error_order or 0), dense_order=dense_order,
                     error_exponent=float(tableau.error_exponent or 0.0), error_scale=float(error_scale), fsal=fsal,
                     new_in_step=new_in_step,
                     step_stages=s + int(new_in_step))


@functools.cache
def plan_for(name: str, error_scale: float = 1.0) -> StagePlan:
    """The stage plan of the tableau called ``name`` (:func:`~.tableaux.get_tableau`) with the error weights times
    ``error_scale``, built once: a plan is immutable (frozen, read-only arrays), so every solve of the method
    shares it."""
    return make_plan(get_tableau(name), error_scale)


def dense_weights(dense: np.ndarray, theta):
    """``b(theta)``: the continuous-extension weights at ``theta`` (a float, or an array of shape (M,)).

    Horner's scheme on ``dense`` (S, p): returns (S,) for a float theta, (M, S) for an array (the kernel
    runs the same scheme on one theta at a time).
    """
    th = np.asarray(theta, dtype=float)[..., None]
    p = dense.shape[1]
    acc = dense[:, p - 1] * th
    for q in range(p - 2, -1, -1):
        acc = (acc + dense[:, q]) * th
    return acc
