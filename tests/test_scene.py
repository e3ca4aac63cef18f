"""Scene files: the example scenes round-trip and run; every bad field is named in the error."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import liesuslov as ls
from liesuslov.scene import DEFAULT_SCENE, Scene, default_scene, load_scene, scene_from_dict, scene_from_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"
EXAMPLES = sorted(SCENES.glob("*.toml"))

BODY = """
[body]
algebra = "so"
n = 4
mass_tensor = [1.0, 2.0, 3.0, 4.0]

[potential]
kind = "quadratic"
B = [4.0, 3.0, 2.0, 1.0]

[initial]
xi = [0.4, -0.3, 0.2]
Gamma = [0.36, 0.48, 0.0, 0.8]

[integrate]
t_span = [0.0, 1.0]
backend = "numpy"
"""


def _load(text: str) -> Scene:
    return scene_from_text(text, source="scene.toml")


def _same_build(a: Scene, b: Scene) -> None:
    sa, ka = a.build()
    sb, kb = b.build()
    assert sa.algebra.name == sb.algebra.name
    np.testing.assert_array_equal(sa.inertia.matrix, sb.inertia.matrix)
    np.testing.assert_array_equal(sa.constraints.basis, sb.constraints.basis)
    assert sa.potential.kind == sb.potential.kind
    assert sa.gyroscopic == sb.gyroscopic
    assert ka.keys() == kb.keys()
    for k in ka:
        if isinstance(ka[k], np.ndarray) or isinstance(kb[k], np.ndarray):
            np.testing.assert_array_equal(ka[k], kb[k])
        else:
            assert ka[k] == kb[k], k


# ---------------------------------------------------------------------- the examples and the default
def test_the_five_example_scenes_exist():
    names = {p.stem for p in EXAMPLES}
    assert {"klebsh_tisserand4", "lagrange3", "kharlamova5", "suslov3", "chaplygin_sleigh_se2"} <= names


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_scene_round_trip_and_run(path):
    scene = load_scene(path)
    again = scene_from_dict(tomllib.loads(scene.to_toml()), source="round-trip")
    _same_build(scene, again)
    assert again.name == scene.name and again.out_dir == scene.out_dir
    short = scene.with_options(t_end=scene.t_span[0] + 0.5)
    system, kwargs = short.build()
    sol = ls.integrate(system, **kwargs)  # build() feeds the library's front door directly
    assert sol.success
    E = system.energy(sol.omega, sol.Gamma)
    assert np.max(np.abs(E - E[0])) < 1e-8
    assert sol.t[-1] == pytest.approx(scene.t_span[0] + 0.5)


def test_default_scene_is_the_documented_text():
    s = default_scene()
    assert s.case is not None and s.case.name == "klebsh_tisserand"
    assert s.reconstruct and s.system.n == 4
    _same_build(s, scene_from_dict(tomllib.loads(DEFAULT_SCENE)))
    _same_build(s, scene_from_dict(tomllib.loads(s.to_toml())))
    assert set(s.integrals) == {"energy", "F_1", "F_2", "F_3"}


def test_run_and_options():
    s = default_scene().with_options(t_end=1.0, out_dir="x", figures=False)
    assert s.t_span == (0.0, 1.0) and s.out_dir == "x" and not s.figures
    assert s.data["integrate"]["t_span"] == [0.0, 1.0] and s.data["output"]["dir"] == "x"
    sol = s.run()
    assert sol.success and sol.g is not None and sol.t.size == s.n_out
    sol2 = s.run(t_eval=None)  # overrides replace the integrate keywords
    assert sol2.t.size != sol.t.size


def test_max_steps_from_the_scene_and_the_overrides():
    """[integrate].max_steps reaches integrate (a run that needs more fails there, with the time); the
    CLI's override replaces it; a non-integer or a value below 1 is refused naming the field."""
    s = _load(BODY + "max_steps = 5\n")
    assert s.max_steps == 5 and s.build()[1]["max_steps"] == 5
    sol = s.run()
    assert sol.status == -1 and sol.message.startswith("max_steps reached at t = ")
    assert sol.stats["steps"] + sol.stats["rejected"] == 5
    assert "max_steps" not in _load(BODY).build()[1]  # unset: integrate's default
    longer = s.with_options(max_steps=10_000)
    assert longer.run().success and longer.data["integrate"]["max_steps"] == 10_000
    assert _load(longer.to_toml()).max_steps == 10_000
    with pytest.raises(ValueError, match=r"\[integrate\].max_steps must be an integer >= 1, got 0"):
        _load(BODY + "max_steps = 0\n")
    with pytest.raises(TypeError, match=r"\[integrate\].max_steps must be an integer"):
        _load(BODY + "max_steps = 2.5\n")
    with pytest.raises(ValueError, match="max_steps must be a positive integer"):
        s.with_options(max_steps=0)
    with pytest.raises(TypeError, match="max_steps must be an integer"):
        s.with_options(max_steps=10.0)


def test_explicit_t_eval_and_every_step():
    s = _load(BODY + "t_eval = [0.0, 0.25, 0.5, 1.0]\n")
    np.testing.assert_array_equal(s.run().t, [0.0, 0.25, 0.5, 1.0])
    assert s.with_options(t_end=0.3).t_eval.tolist() == [0.0, 0.25, 0.3]
    steps = _load(BODY + 't_eval = "steps"\n')
    assert steps.output_times() is None and steps.run().t.size == steps.run().stats["steps"] + 1


def test_se2_and_custom_algebras():
    sleigh = load_scene(SCENES / "chaplygin_sleigh_se2.toml")
    assert sleigh.system.algebra.name == "se(2)" and not sleigh.system.constraints.is_subalgebra()
    C = ls.so(3).structure_constants.tolist()
    custom = _load(f"""
[body]
structure_constants = {C}
inertia = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]]
[constraints]
annihilator = [[0.0, 0.0, 1.0]]
[initial]
omega = [0.5, 1.0, 0.0]
[integrate]
t_span = [0.0, 1.0]
backend = "numpy"
""")
    assert custom.system.algebra.name == "custom" and custom.run().success


def test_case_with_string_form_and_gyroscopic_potential_table():
    s = _load('case = "lagrange3"\n[initial]\nw = [0.4, 0.3, 0.0]\nGamma = [0.36, 0.48, 0.8]\n'
              '[integrate]\nt_span = [0.0, 1.0]\nbackend = "numpy"\n')
    assert s.case.parameters == {"J1": 2.0, "J3": 1.5, "B3": 1.0}
    g = _load('[case]\nname = "gyroscopic3"\n[case.parameters]\nJ = [1.0, 2.0, 2.5]\neps = 0.5\n'
              'potential = {kind = "linear", B = [1.0, 0.5, 0.0]}\n'
              '[initial]\nxi = [0.1, 0.2]\nGamma = [0.6, 0.0, 0.8]\n[integrate]\nt_span = [0.0, 1.0]\n')
    assert g.system.gyroscopic == 0.5 and g.system.potential.kind == "linear"


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="nope.toml"):
        load_scene("nope.toml")


# ---------------------------------------------------------------------- bad files
def _sub(old: str, new: str, text: str = BODY) -> str:
    assert old in text
    return text.replace(old, new)


BAD = [
    ("B of the wrong length", _sub("B = [4.0, 3.0, 2.0, 1.0]", "B = [4.0, 3.0, 2.0]"),
     r"\[potential\]\.B must be a list of 4 numbers.*got a list of 3 numbers"),
    ("B a string", _sub("B = [4.0, 3.0, 2.0, 1.0]", 'B = "x"'), r"\[potential\]\.B must be .*got the string"),
    ("potential kind", _sub('kind = "quadratic"', 'kind = "cubic"'), r"\[potential\]\.kind must be one of"),
    ("mass tensor shape", _sub("[1.0, 2.0, 3.0, 4.0]", "[[1.0, 2.0], [3.0]]"), r"\[body\]\.mass_tensor must be"),
    ("mass tensor not SPD", _sub("[1.0, 2.0, 3.0, 4.0]", "[-1.0, -2.0, 3.0, 4.0]"),
     r"\[body\]\.mass_tensor: .*positive definite"),
    ("principal moments n", _sub("mass_tensor = [1.0, 2.0, 3.0, 4.0]", "principal_moments = [1.0, 2.0, 3.0]"),
     r"\[body\]\.principal_moments are for n = 3"),
    ("two inertias", _sub("n = 4\n", "n = 4\ninertia = [[1.0]]\n"), r"\[body\] takes one of"),
    ("algebra", _sub('algebra = "so"', 'algebra = "so3"'), r"\[body\]\.algebra must be one of"),
    ("t_span", _sub("t_span = [0.0, 1.0]", "t_span = 5"), r"\[integrate\]\.t_span must be a list of 2 numbers"),
    ("t_span equal", _sub("t_span = [0.0, 1.0]", "t_span = [1.0, 1.0]"), r"\[integrate\]\.t_span must have t0"),
    ("method", BODY + 'method = "rk45"\n', r"\[integrate\]\.method must be one of .*did you mean 'rkmk45'"),
    ("chart", BODY + 'chart = "cay"\n', r"\[integrate\]\.chart must be one of"),
    ("h missing", BODY + 'method = "rkmk4"\n', r"\[integrate\]\.h .*required by the fixed-step method"),
    ("h negative", BODY + 'method = "rkmk4"\nh = -0.1\n', r"\[integrate\]\.h must be a positive number"),
    ("rtol bool", BODY + "rtol = true\n", r"\[integrate\]\.rtol must be a number, got the boolean"),
    ("rtol inf", BODY + "rtol = inf\n", r"\[integrate\]\.rtol must be finite"),
    ("n_out", BODY + "n_out = 1\n", r"\[integrate\]\.n_out must be an integer >= 2"),
    ("n_out float", BODY + "n_out = 10.5\n", r"\[integrate\]\.n_out must be an integer"),
    ("n_out and t_eval", BODY + "n_out = 5\nt_eval = [0.0, 1.0]\n", r"\[integrate\] takes n_out or t_eval"),
    ("t_eval outside", BODY + "t_eval = [0.0, 2.0]\n", r"\[integrate\]\.t_eval must lie within"),
    ("reconstruct", BODY + 'reconstruct = "yes"\n', r"\[integrate\]\.reconstruct must be true or false"),
    ("form", BODY.replace("mass_tensor = [1.0, 2.0, 3.0, 4.0]", "mass_tensor = [[1.0, 0.0, 0.0, 0.1], "
                          "[0.0, 2.0, 0.0, 0.0], [0.0, 0.0, 3.0, 0.0], [0.1, 0.0, 0.0, 4.0]]") + 'form = "symmetric"\n',
     r"\[integrate\]\.form = 'symmetric' does not hold"),
    ("no initial data", _sub("xi = [0.4, -0.3, 0.2]\n", ""), r"\[initial\] needs exactly one of omega"),
    ("two initial data", _sub("xi = [0.4, -0.3, 0.2]", "xi = [0.4, -0.3, 0.2]\nomega = [0, 0, 0.4, 0, -0.3, 0.2]"),
     r"\[initial\] needs exactly one of .*got omega, xi"),
    ("xi length", _sub("xi = [0.4, -0.3, 0.2]", "xi = [0.4, -0.3]"), r"\[initial\]\.xi must be a list of 3 numbers"),
    ("Gamma missing", _sub("Gamma = [0.36, 0.48, 0.0, 0.8]\n", ""), r"\[initial\]\.Gamma is required"),
    ("w on so(4)", _sub("xi = [0.4, -0.3, 0.2]", "w = [1.0, 0.0, 0.0]"), r"\[initial\]\.w .*so\(3\) only"),
    ("g without reconstruct", _sub("[integrate]", "g = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n"
                                                   "[integrate]"), r"\[initial\]\.g .*reconstruct = true"),
    ("g not a rotation", _sub("[integrate]", "g = [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n"
                                              "[integrate]") + "reconstruct = true\n",
     r"\[initial\]\.g: g must be in SO\(4\)"),
    ("gyroscopic on so(4)", "gyroscopic = 0.5\n" + BODY, r"gyroscopic must be 0 here"),
    ("constraints kind", "constraints = \"suslov\"\n" + BODY, r"constraints must be \"fedorov_kozlov\" or \"none\""),
    ("dependent covectors", BODY + "[constraints]\nannihilator = [[1, 0, 0, 0, 0, 0], [2, 0, 0, 0, 0, 0]]\n",
     r"\[constraints\]\.annihilator: covectors are linearly dependent"),
    ("annihilator width", BODY + "[constraints]\nannihilator = [[1, 0, 0]]\n",
     r"\[constraints\]\.annihilator must be a list of covectors of 6 numbers"),
    ("two constraint kinds", BODY + "[constraints]\nannihilator = [[1, 0, 0, 0, 0, 0]]\nspan = [[0, 0, 1, 0, 0, 0]]\n",
     r"\[constraints\] takes exactly one of"),
    ("output figures", BODY + "[output]\nfigures = 1\n", r"\[output\]\.figures must be true or false"),
    ("check tol", BODY + "[check]\ntol = 0\n", r"\[check\]\.tol must be a positive number"),
    ("no integrate", BODY.split("[integrate]")[0], r"the table \[integrate\] is required"),
    ("empty file", "", r"needs \[body\] .* or \[case\]"),
    ("not TOML", "x = = 1", r"scene\.toml: not valid TOML"),
    ("section as value", "body = 3\n", r"\[body\] must be a table"),
    ("n_out huge", _sub('backend = "numpy"', 'backend = "numpy"\nn_out = 1000000000000'),
     r"\[integrate\]\.n_out must be an integer <= 10000000 \(the output times are held in memory"),
    ("n_out huge float", _sub('backend = "numpy"', 'backend = "numpy"\nn_out = 1e12'),
     r"\[integrate\]\.n_out must be an integer <= 10000000 .*got 1000000000000"),
    ("h below rounding", _sub('backend = "numpy"', 'backend = "numpy"\nh = 1e-300'),
     r"\[integrate\]\.h = 1e-300 is below the resolution of t"),
    ("h too many steps", _sub('backend = "numpy"', 'backend = "numpy"\nmethod = "rkmk4"\nh = 1e-9'),
     r"\[integrate\]\.h = 1e-09 would take 1e\+09 fixed steps"),
]

CASE = DEFAULT_SCENE
BAD_CASES = [
    ("case name", _sub('name = "klebsh_tisserand"', 'name = "klebsh_tisseran"', CASE),
     r"\[case\]\.name must be one of .*did you mean 'klebsh_tisserand'"),
    ("case parameter value", _sub("B = [4.0, 3.0, 2.5, 1.0]", "B = [1.0, 3.0, 2.5, 2.0]", CASE),
     r"\[case\.parameters\]\.B: the Klebsh–Tisserand tori need B_i > B_n"),
    ("case parameter shape", _sub("B = [4.0, 3.0, 2.5, 1.0]", "B = [3.0, 2.5, 1.0]", CASE),
     r"\[case\.parameters\]\.B must have shape \(4,\)"),
    ("case parameter type", _sub("B = [4.0, 3.0, 2.5, 1.0]", 'B = "x"', CASE),
     r"\[case\.parameters\]\.B must be a number, a list of numbers or a boolean"),
    ("case with body", CASE + "[body]\nn = 3\n", r"\[body\] cannot be combined with \[case\]"),
    ("callable parameter", '[case]\nname = "family3"\n[case.parameters]\nv1 = 1.0\n'
                           '[initial]\nxi = [0.1, 0.2]\nGamma = [0.6, 0.0, 0.8]\n[integrate]\nt_span = [0, 1]\n',
     r"\[case\.parameters\]\.v1 is a Python function"),
    ("potential parameter", '[case]\nname = "gyroscopic3"\n[case.parameters]\nJ = [1, 2, 3]\neps = 0.1\n'
                            'potential = {kind = "linear", B = [1.0, 2.0]}\n[initial]\nxi = [0.1, 0.2]\n'
                            'Gamma = [0.6, 0.0, 0.8]\n[integrate]\nt_span = [0, 1]\n',
     r"\[case\.parameters\]\.potential: LinearPotential needs B = \(B1, B2, 0\)|"
     r"\[case\.parameters\]\.potential.*B"),
]


@pytest.mark.parametrize("text, match", [(t, m) for _, t, m in BAD + BAD_CASES],
                         ids=[i for i, _, _ in BAD + BAD_CASES])
def test_bad_field_is_named(text, match):
    with pytest.raises((ValueError, TypeError), match=match) as info:
        _load(text)
    assert str(info.value).startswith("scene.toml: ")


@pytest.mark.parametrize("text, key, table", [
    (_sub("mass_tensor", "mass_tensr"), "[body].mass_tensr", "[body]"),
    (BODY + "[integrat]\nx = 1\n", "integrat", "the top level"),
    (BODY + "rtoll = 1e-9\n", "[integrate].rtoll", "[integrate]"),
    (_sub("Gamma =", "gamma ="), "[initial].gamma", "[initial]"),
    (BODY + "[output]\nfolder = 'x'\n", "[output].folder", "[output]"),
    (_sub("kind =", "kinds ="), "[potential].kinds", "[potential]"),
    (_sub("I = [", "II = [", DEFAULT_SCENE), "[case.parameters].II", "[case.parameters]"),
    (DEFAULT_SCENE + "[check]\ntolerance = 1e-3\n", None, None),  # duplicate table: a TOML error
])
def test_unknown_keys_are_rejected_with_the_valid_ones(text, key, table):
    with pytest.raises(ValueError) as info:
        _load(text)
    msg = str(info.value)
    if key is None:
        assert "not valid TOML" in msg
        return
    assert f"unknown key {key}" in msg and f"valid keys of {table} are" in msg


def test_non_unit_gamma_is_an_error_with_the_normalised_vector():
    with pytest.raises(ValueError, match=r"\[initial\]\.Gamma must be a unit vector .*normalised it is") as info:
        _load(_sub("0.8]", "0.81]"))
    assert "1e-8" in str(info.value)
    _load(_sub("[0.36, 0.48, 0.0, 0.8]", "[0.36, 0.48, 0.0, 0.800000000001]"))  # within 1e-8: accepted


def test_omega_not_in_D():
    with pytest.raises(ValueError, match=r"\[initial\]\.omega is not in D.*xi = \[0\.4, -0\.3, 0\.2\]"):
        _load(_sub("xi = [0.4, -0.3, 0.2]", "omega = [0.1, 0.0, 0.4, 0.0, -0.3, 0.2]"))
    Om = "Omega = [[0, 0.5, 0, 0.4], [-0.5, 0, 0, -0.3], [0, 0, 0, 0.2], [-0.4, 0.3, -0.2, 0]]"
    with pytest.raises(ValueError, match=r"\[initial\]\.Omega is not in D"):
        _load(_sub("xi = [0.4, -0.3, 0.2]", Om))
    with pytest.raises(ValueError, match=r"\[initial\]\.Omega: .*skew-symmetric"):
        _load(_sub("xi = [0.4, -0.3, 0.2]", Om.replace("[-0.5,", "[0.5,")))
    ok = _load(_sub("xi = [0.4, -0.3, 0.2]", Om.replace("0.5", "0")))
    np.testing.assert_allclose(ok.system.constraints.coordinates(ok.omega0), [0.4, -0.3, 0.2])


def test_se2_errors():
    base = '[body]\nalgebra = "se2"\ninertia = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n'
    tail = "[initial]\nomega = [1, 0, 0]\n[integrate]\nt_span = [0, 1]\n"
    with pytest.raises(ValueError, match=r"\[constraints\] is required on se\(2\)"):
        _load(base + tail)
    with pytest.raises(ValueError, match=r"\[potential\] needs a body in SO\(n\)"):
        _load(base + "[constraints]\nannihilator = [[0, 0, 1]]\n[potential]\nkind = 'linear'\nB = [1, 0]\n" + tail)
    with pytest.raises(ValueError, match=r"\[body\]\.n is only for algebra = \"so\""):
        _load(base + "n = 3\n" + tail)
    with pytest.raises(ValueError, match=r"\[initial\]\.Gamma is for a body in SO\(n\)"):
        _load(base + '[constraints]\nannihilator = [[0, 0, 1]]\n' + tail.replace("omega = [1, 0, 0]",
                                                                                "omega = [1, 0, 0]\nGamma = [1, 0]"))
    free = _load(base.replace("[body]", 'constraints = "none"\n[body]') + tail)
    assert free.system.constraints.dim == 3


def test_n_out_written_as_a_whole_float_is_accepted():
    text = _sub('backend = "numpy"', 'backend = "numpy"\nn_out = 1e2')
    assert scene_from_text(text).n_out == 100


def test_scenes_pickle():
    import pickle

    scene = default_scene()
    again = pickle.loads(pickle.dumps(scene))
    assert again.name == scene.name and again.case.name == scene.case.name
    np.testing.assert_array_equal(again.omega0, scene.omega0)
    assert again.to_toml() == scene.to_toml()
