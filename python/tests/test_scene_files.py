"""Scenes from files and from Python dicts: the same scene as the compiled one (trajectories
within 1e-12, measured identical), clear ValueErrors naming the location, and scenes that
travel as data (pickle) with their overrides."""

import os
import pickle

import numpy as np
import pytest

import moreau

SCENES = os.path.join(os.environ.get("MOREAU_EXAMPLES", "examples"), "scenes")
# Same operations in the same order as the compiled lambdas: equal to round-off.
TOLERANCE = 1e-12

S3_DICT = dict(
    name="S3", states=["x1", "x2"], x0=["sqrt(2)", "sqrt(2)"], tf="11*pi/12 + sqrt(3)",
    dynamics=["x2", "-x1"], parameters={"floor": (-1.0, "height of the floor")},
    effects=[{"kind": "moving_set", "name": "floor", "constraint_names": ["c"],
              "constraints": ["x2 - floor"]}])
F1_DICT = dict(
    name="F1", states=["x1", "x2"], x0=["exp(-1)", 0.0], tf="pi/2",
    parameters=[{"name": "omega", "value": 6.283185307179586}],
    effects=[{"kind": "switching", "name": "circle", "surface_names": ["c"],
              "surfaces": ["x1*x1 + x2*x2 - 1"], "mode_names": ["inside", "outside"],
              "modes": [["x1 - omega*x2", "omega*x1 + x2"],
                        ["x1 + omega*x2", "-omega*x1 + x2"]]}])
H1_DICT = dict(
    name="H1", states=["x"], x0=[15.0], tf=15.0,
    parameters={"decay": 0.2, "heat": 5.0, "x_on": 18.0, "x_off": 20.0},
    effects=[{"kind": "hysteresis", "name": "thermostat", "input": "x",
              "lower_threshold": "x_on", "upper_threshold": "x_off",
              "mode_a": ["-decay*x + heat"], "mode_b": ["-decay*x"], "initial_memory": 0}])

# The half-wave rectifier (docs/complementarity.md): a complementarity system with D = R.
RECTIFIER_DICT = dict(
    name="rectifier", states=["v_C", "i_L"], x0=[10.0, 0.0], tf=2e-3,
    dynamics=["-i_L/C", "v_C/L"], parameters={"L": 1e-2, "C": 1e-6, "R": 1e3},
    defaults={"h0": 1e-6, "output_dt": 1e-5},  # the scale the compiled rectifier declares
    effects=[{"kind": "complementarity", "name": "diode", "pair_names": ["D"],
              "output": ["-v_C"], "input_matrix": [["-1/C"], ["0"]], "feedthrough": [["R"]]}])


def _same(a, b):
    assert a.status == b.status == "success"
    assert len(a.events) == len(b.events)
    for ea, eb in zip(a.events, b.events):
        assert abs(ea.t - eb.t) <= TOLERANCE and ea.what == eb.what
    assert a.x.shape == b.x.shape
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=TOLERANCE)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=TOLERANCE)


@pytest.mark.parametrize("name,data", [("S3", S3_DICT), ("F1", F1_DICT), ("H1", H1_DICT)])
def test_dict_file_and_compiled_scenes_agree(name, data):
    options = dict(integrator="fesd", stages=3)
    compiled = moreau.simulate(moreau.scene(name), **options)
    from_file = moreau.simulate(moreau.load_scene(os.path.join(SCENES, name + ".toml")), **options)
    from_dict = moreau.simulate(moreau.scene_from_dict(data), **options)
    _same(compiled, from_file)
    _same(compiled, from_dict)


def test_keyword_form_and_overrides():
    scene = moreau.scene_from_dict(**S3_DICT).set(floor=-0.5, **{"x0.x1": 1.0})
    assert scene.parameters == {"floor": -0.5}
    assert scene.x0[0] == 1.0
    assert moreau.simulate(scene).success


def test_file_scenes_travel_as_data_with_their_overrides():
    scene = moreau.load_scene(os.path.join(SCENES, "H1.toml")).set(heat=6.0)
    copy = pickle.loads(pickle.dumps(scene))
    assert copy.parameters["heat"] == 6.0
    np.testing.assert_array_equal(moreau.simulate(copy).x, moreau.simulate(scene).x)


def test_errors_name_the_location():
    with pytest.raises(ValueError, match=r"<dict>:\d+:\d+ \(effects\[0\]\.constraints\[0\]\): "
                                         r"unknown name 'x3'; did you mean 'x1'\?"):
        moreau.scene_from_dict(dict(S3_DICT, effects=[{"kind": "moving_set", "name": "floor",
                                                       "constraints": ["x3 - floor"]}]))
    with pytest.raises(ValueError, match="'abs' is not smooth"):
        moreau.scene_from_dict(dict(S3_DICT, dynamics=["abs(x2)", "-x1"]))
    with pytest.raises(ValueError, match=r"\(x0\): expected 2 entries"):
        moreau.scene_from_dict(dict(S3_DICT, x0=[1.0]))
    with pytest.raises(ValueError, match="unknown key 'dynamic'; did you mean 'dynamics'"):
        moreau.scene_from_dict(dict(S3_DICT, dynamic=["x2", "-x1"]))
    with pytest.raises(ValueError, match="cannot read scene file 'nope.toml'"):
        moreau.load_scene("nope.toml")
    with pytest.raises(ValueError, match=r"bad.toml:2:\d+: TOML syntax error"):
        moreau.parse_scene('name = "s"\nstates = ["x"\n', "bad.toml")
    with pytest.raises(ValueError, match="expected a number, string, bool, list or dict"):
        moreau.scene_from_dict(dict(S3_DICT, tf=object()))


def test_complementarity_dict_runs_as_the_compiled_rectifier():
    options = dict(integrator="fesd", stages=3, h=1e-5)
    compiled = moreau.simulate(moreau.scene("rectifier"), **options)
    _same(compiled, moreau.simulate(moreau.scene_from_dict(RECTIFIER_DICT), **options))
    assert [e.kind for e in compiled.events] == ["leave", "enter"] * 3
    bad = dict(RECTIFIER_DICT, effects=[dict(RECTIFIER_DICT["effects"][0], feedthrough=[["-R"]])])
    with pytest.raises(ValueError, match="the feedthrough D must be a P-matrix"):
        moreau.scene_from_dict(bad)
