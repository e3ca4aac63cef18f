"""The field plan of the compiled kernel (:func:`liesuslov.integrators.compiled.compile_plan`): pure numpy.

The compiled solve itself is tested in ``tests/test_kernel.py``.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import liesuslov as ls
from liesuslov.integrators import compiled


def kt4():
    return ls.cases.klebsh_tisserand([1.0, 1.3, 1.7, 2.0], [4.0, 3.5, 3.0, 1.0])


def test_probing_rejects_a_field_that_is_not_quadratic():
    model = kt4().system.model(gamma=True)

    class Cubic:  # a model-protocol object whose field has a cubic term
        k, n, has_gamma, algebra = model.k, model.n, True, model.algebra
        omega_matrix = staticmethod(model.omega_matrix)

        @staticmethod
        def xi_dot(xi, G):
            return model.xi_dot(xi, G) + 1e-3 * xi ** 3

    with pytest.raises(compiled.NotCompilable, match="not a polynomial of degree <= 2"):
        compiled.compile_plan(Cubic(), "g", "exp")
    plan = compiled.compile_plan(model, "g", "exp")
    assert plan.field_value.size == model.k  # Klebsh–Tisserand: xi_i' = c_i Gamma_i Gamma_n, one term each
    assert plan.omega_value.size == model.k  # Fedorov–Kozlov: Omega = u ∧ e_n
    rng = np.random.default_rng(0)
    xi, G = rng.normal(size=(5, model.k)), rng.normal(size=(5, model.n))
    np.testing.assert_allclose(plan.field(xi, G), model.xi_dot(xi, G), rtol=1e-13, atol=1e-13)
    assert compiled.compile_plan(model, "g", "exp", omega=False).omega_value.size == 0


def test_user_potentials_are_not_compiled():
    pot = ls.Potential(lambda G: np.cos(G[..., 2]), lambda G: np.stack([0 * G[..., 0], 0 * G[..., 1],
                                                                         -np.sin(G[..., 2])], -1), n=3)
    system = ls.SuslovSystem(ls.Inertia.from_principal_moments([1.0, 2.0, 2.5]), potential=pot)
    with pytest.raises(compiled.NotCompilable, match="not a built-in polynomial potential"):
        compiled.compile_plan(system.model(gamma=True), "gamma", "exp")
    assert issubclass(compiled.NotCompilable, ValueError)


def test_general_matrix_algebras_store_every_entry():
    alg = ls.se(3)
    D = ls.Subspace.annihilator(alg, np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]]))
    system = ls.SuslovSystem(ls.Inertia(alg, np.diag([1.0, 2.0, 3.0, 1.5, 2.5, 3.5])), constraints=D)
    model = system.model(gamma=False)
    plan = compiled.compile_plan(model, "g", "exp")
    x = np.random.default_rng(1).normal(size=model.k)
    Om = np.zeros((model.n, model.n))
    for (a, r, c), v in zip(plan.omega_index, plan.omega_value, strict=True):
        Om[r, c] += v * x[a]
    np.testing.assert_allclose(Om, model.omega_matrix(x), atol=1e-15)
    with pytest.raises(compiled.NotCompilable, match="mode"):
        compiled.compile_plan(model, "attitude", "exp")


def test_importing_liesuslov_does_not_import_numba():
    code = ("import sys, liesuslov, liesuslov.integrators, liesuslov.integrators.compiled as c; "
            "c.numba_available(); assert 'numba' not in sys.modules, 'numba imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_compile_plan_is_built_once_per_model_and_use():
    model = ls.SuslovSystem(ls.Inertia.from_mass_tensor(np.diag([1.0, 2.0, 3.0])), constraints="none").model()
    first = compiled.compile_plan(model, "g", "exp")
    assert compiled.compile_plan(model, "g", "exp") is first  # the kernel's packed constants are keyed by it
    assert compiled.compile_plan(model, "g", "cayley") is not first
    assert compiled.compile_plan(model, "none", None) is not first
    assert compiled.compile_plan(model, "g", "exp", omega=False).omega_value.size == 0
