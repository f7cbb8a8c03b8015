"""SurgSim/LayeredPalpation-v0 checks its config, actions and options as the other tasks do, and
renders."""

import math

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401 - registers the tasks
from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig, LayeredPalpationEnv
from surgsim_envs.errors import ConfigError

TASK = "SurgSim/LayeredPalpation-v0"


@pytest.fixture(scope="module")
def env():
    e = gym.make(TASK).unwrapped
    e.reset(seed=0)
    return e


@pytest.mark.parametrize("kwargs, words", [
    ({"size": None}, ["size=None", "pair (x, y)", "e.g. (0.08, 0.06)"]),
    ({"size": "ab"}, ["size='ab'", "pair (x, y)"]),
    ({"size": ()}, ["size=()", "pair (x, y)"]),
    ({"size": (0.08, "x")}, ["size[1]='x'", "[0.02, 0.3]"]),
    ({"size": (0.08, math.inf)}, ["size[1]=inf"]),
    ({"press_cost": float("nan")}, ["press_cost=nan", "finite number in [0, 1000]", "e.g. 0.01"]),
    ({"press_cost": -1.0}, ["press_cost=-1.0"]),
    ({"press_cost": 1e308}, ["press_cost=1e+308"]),
    ({"spacing": 0.0}, ["spacing=0.0", "[0.002, 0.01]"]),
    ({"max_depth": 0.05}, ["max_depth=0.05", "29 mm thick"]),
    ({"max_presses": 0}, ["max_presses=0", "integer in [1, 10000]"]),
    ({"max_presses": 2.5}, ["max_presses=2.5"]),
    ({"max_presses": True}, ["max_presses=True"]),
    ({"nodule_factor": 0.0}, ["nodule_factor=0.0"]),
    ({"nodule_radius": 0.04}, ["nodule_radius=0.04", "does not fit the patch"]),
    ({"size": (0.3, 0.3), "spacing": 0.002}, ["lattice nodes", "limit 60,000", "coarsen spacing"]),
    ({"camera": "bogus"}, ["camera='bogus'", "overview"]),
    ({"bogus": 1}, ["unknown LayeredPalpationConfig field(s) ['bogus']"]),
])
def test_bad_config_is_refused_by_name_bound_and_fix(kwargs, words):
    with pytest.raises(ConfigError) as err:
        gym.make(TASK, **kwargs)
    for w in words:
        assert w in str(err.value)


def test_config_object_and_render_mode_are_checked():
    with pytest.raises(ConfigError, match="config must be a LayeredPalpationConfig, got dict"):
        LayeredPalpationEnv(config={"size": (0.08, 0.06)})
    with pytest.raises(ConfigError, match="render_mode='ansi' is not supported.*'rgb_array'"):
        LayeredPalpationEnv(render_mode="ansi")
    with pytest.raises(ConfigError, match="call reset\\(\\) before step\\(\\)"):
        gym.make(TASK).unwrapped.step(np.zeros(4, np.float32))


@pytest.mark.parametrize("action, words", [
    (np.zeros(3), "shape (3,)"),
    (np.zeros((2, 3)), "shape (2, 3)"),
    (np.array([1j, 0, 0, 0]), "complex"),
    ("abcd", "dtype <U4"),
    (["a", "b", "c", "d"], "dtype <U1"),
    (None, "dtype object"),
    (np.array([np.nan, 0, 0, 0]), "NaN or inf"),
    (np.array([0, np.inf, 0, 0], dtype=np.float32), "NaN or inf"),
])
def test_bad_actions_are_refused(env, action, words):
    with pytest.raises(ConfigError) as err:
        env.step(action)
    assert words in str(err.value)


def test_reset_options_are_checked(env):
    with pytest.raises(ConfigError, match="unknown reset option\\(s\\) \\['nodule'\\]"):
        env.reset(options={"nodule": (0, 0)})
    with pytest.raises(ConfigError, match="reset options must be a dict"):
        env.reset(options=[1])


def test_step_outputs_are_finite_and_the_reward_adds_up(env):
    """Integer and float32 actions, out-of-range entries clipped; the reward is the sum of its
    terms; committing over the nodule succeeds."""
    env.reset(seed=4)
    cfg = env.config
    for a in ([0, 0, 0, -1], np.full(4, 3.0), np.array([-0.3, 0.2, 0.9, -0.5], dtype=np.float32)):
        obs, r, term, trunc, info = env.step(a)
        assert env.observation_space.contains(obs)
        assert r == pytest.approx(sum(info["reward_terms"].values()))
        assert math.isfinite(r)
    ax, ay = env.nodule[0] / (0.5 * cfg.size[0]), env.nodule[1] / (0.5 * cfg.size[1])
    obs, r, term, trunc, info = env.step([ax, ay, 1.0, 1.0])
    assert term and info["success"] and r == pytest.approx(1.0 - cfg.press_cost, abs=1e-6)


def test_keyword_overrides_reach_the_config():
    e = gym.make(TASK, max_presses=3, press_cost=0.5).unwrapped
    assert e.config.max_presses == 3 and e.max_episode_steps == 3
    e.reset(seed=0)
    assert e.step([0, 0, 0, -1])[1] == pytest.approx(-0.5)


def test_rgb_array_renders_the_pressed_wall():
    """A frame of the scene whose wall mirrors the task's pressed wall and whose probe sits at the
    press; no OpenGL here means a clear skip, not a failure."""
    from surgsim_envs.errors import RenderingUnavailableError

    e = gym.make(TASK, render_mode="rgb_array", render_width=96, render_height=96).unwrapped
    e.reset(seed=1)
    e.step([0.0, 0.0, 1.0, -1.0])
    try:
        frame = e.render()
    except RenderingUnavailableError as exc:
        pytest.skip(f"no OpenGL for rendering: {exc}")
    assert frame.shape == (96, 96, 3) and frame.dtype == np.uint8 and frame.std() > 5
    np.testing.assert_allclose(e.sim.tissue("wall").positions, e.tissue.positions)
    tip = e.sim.tool_position("probe")
    np.testing.assert_allclose(tip, [0.0, 0.0, e.z_top + e.config.probe_radius - e.config.max_depth], atol=1e-9)
    assert e.sim.time == pytest.approx(1.0 / e.config.control_hz)
    e.close()


def test_default_config_validates():
    LayeredPalpationConfig().validate()


hypothesis = pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

_ACTIONS = st.one_of(
    hnp.arrays(st.sampled_from([np.float32, np.float64, np.int64, np.int8]), st.integers(0, 6)),
    hnp.arrays(np.float64, hnp.array_shapes(max_dims=3, max_side=5)),
    hnp.arrays(st.sampled_from([np.complex128, np.bool_, np.str_]), st.integers(1, 5)),
    st.lists(st.one_of(st.floats(), st.integers(-10**30, 10**30), st.text(max_size=2)), max_size=5),
)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(action=_ACTIONS)
def test_any_action_is_a_finite_step_or_a_config_error(env, action):
    """Property: whatever the action (any shape, dtype, NaN/inf, huge integers, strings), a step
    either returns observations inside the space and a finite reward, or raises ConfigError."""
    if env.presses >= env.config.max_presses - 1:
        env.reset(seed=0)
    try:
        obs, r, term, trunc, _ = env.step(action)
    except ConfigError:
        return
    assert env.observation_space.contains(obs) and math.isfinite(r)
    if term or trunc:
        env.reset(seed=0)


def test_the_nodule_position_option_places_the_nodule_inside_the_patch(env):
    _, info = env.reset(seed=3, options={"nodule_position": (0.01, -0.005)})
    assert info["nodule_centre"][:2] == pytest.approx((0.01, -0.005)) and info["nodule_tets"] > 0
    _, again = env.reset(seed=3)
    assert again["nodule_centre"][:2] != pytest.approx((0.01, -0.005))   # without it: drawn from the seed
    half = 0.5 * env.config.size[0] - env.config.nodule_radius
    with pytest.raises(ConfigError, match=r"nodule_position\[0\].*" + f"{half:g}".replace(".", r"\.")):
        env.reset(options={"nodule_position": (1.0, 0.0)})
    with pytest.raises(ConfigError, match="nodule_position.*pair"):
        env.reset(options={"nodule_position": 0.01})


def test_the_nodule_is_given_at_the_material_points_and_keeps_the_spheres_volume(env):
    """The default wall (fem_hex, 4 mm) takes the nodule at its cells' Gauss points: a cell's Young's
    modulus is scaled by 1 + (factor - 1) x its share of points inside the sphere, and the nodule's
    volume on the lattice stays within 8 % of the sphere's wherever it sits in a cell (0.98-1.07 at
    16 positions); the cells' centres would give 0.90 at the probe set's site (1.92 against 2.14 cm^3)."""
    cfg = env.config
    points = env.tissue.material_points()
    corners = env.tissue.element_vertices()
    cell_volume = (corners.max(axis=1) - corners.min(axis=1)).prod(axis=1)
    sphere = 4.0 / 3.0 * math.pi * cfg.nodule_radius ** 3
    h = cfg.spacing
    for offset in ((0.0, 0.0), (0.5 * h, 0.25 * h), (0.25 * h, 0.75 * h)):
        env.reset(seed=0, options={"nodule_position": (0.02 + offset[0], 0.01 + offset[1])})
        scaled = env.tissue.fields["young"].copy()
        env.tissue.scale_material("young", 1.0)
        share = (np.linalg.norm(points - env.nodule, axis=2) < cfg.nodule_radius).mean(axis=1)
        np.testing.assert_allclose(scaled / env.tissue.fields["young"], 1.0 + (cfg.nodule_factor - 1.0) * share,
                                   rtol=1e-12)
        assert 0 < share.sum() and abs((share * cell_volume).sum() / sphere - 1.0) < 0.08, offset
        env.reset(seed=0)    # the next reset re-applies a nodule to the uniform wall
