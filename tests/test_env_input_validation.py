"""Env input validation: bad actions, control rates and display settings fail with a clear error,
and a failed reset leaves the env usable. Each test reproduced the failure before the fix."""

import os
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401
from surgsim_envs.envs import TASKS
from surgsim_envs.errors import ConfigError, RenderingUnavailableError


def test_failed_first_reset_does_not_break_later_calls(palpation):
    """Gymnasium's passive checker kept no reset data after a raising first reset, and every later
    step failed with 'TypeError: cannot unpack non-iterable NoneType object'."""
    env = gym.make("SurgSim/Palpation-v0")
    with pytest.raises(ConfigError, match="bogus"):
        env.reset(options={"bogus": 1})
    obs, _ = env.reset(seed=0)
    obs, reward, term, trunc, info = env.step(np.zeros(4, dtype=np.float32))
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    env.close()


@pytest.mark.parametrize("action, kind", [
    (np.array([1 + 2j, 0, 0, 0]), "complex"),
    (["0.1", "0", "0", "0"], "<U"),
    (np.array([True, False, True, False]), "bool"),
    ("abcd", "<U"),
    ([object(), 0, 0, 0], "object"),
])
def test_non_real_actions_are_rejected_by_name(palpation, action, kind):
    """complex actions lost their imaginary part silently, strings were parsed, bools became 0/1."""
    palpation.reset(seed=0)
    with pytest.raises(ConfigError, match=kind):
        palpation.step(action)


@pytest.mark.parametrize("task", sorted(TASKS))      # every physics-rate task of the registry
def test_control_hz_outside_its_physical_range_is_rejected(task):
    """Grasp/Slippage accepted control_hz=1e9 (a control period of 1 ns, shorter than one physics step)."""
    with pytest.raises(ConfigError, match=r"control_hz=1000000000.0 Hz is outside its physical range \[.*\] Hz"):
        gym.make(task, control_hz=1e9)
    with pytest.raises(ConfigError, match="control_hz"):
        gym.make(task, control_hz=1e-6)    # a period longer than the episode


def test_human_render_without_display_raises_instead_of_exiting():
    """render_mode='human' without a display made MuJoCo exit the process (GLFW init failure),
    also inside gymnasium's check_env. Run in a child process so an exit would show."""
    code = textwrap.dedent("""
        import gymnasium as gym, surgsim_envs
        from surgsim_envs.errors import RenderingUnavailableError
        try:
            gym.make("SurgSim/Palpation-v0", render_mode="human")
        except RenderingUnavailableError as exc:
            print("RAISED", exc)
        env = gym.make("SurgSim/Palpation-v0")
        env.unwrapped.render_mode = "human"          # the path check_env's render check takes
        try:
            env.reset(seed=0)
        except RenderingUnavailableError:
            print("RAISED-IN-RESET")
        print("ALIVE")
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "RAISED render_mode='human' needs a display" in out.stdout
    assert "RAISED-IN-RESET" in out.stdout and "ALIVE" in out.stdout


def test_require_display_names_the_fix(monkeypatch):
    from surgsim_envs.scene.display import require_display

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if not sys.platform.startswith("linux"):
        pytest.skip("the DISPLAY check applies on Linux")
    with pytest.raises(RenderingUnavailableError, match="DISPLAY.*rgb_array"):
        require_display()


@pytest.mark.parametrize("task", ["SurgSim/Palpation-v0", "SurgSim/Grasp-v0", "SurgSim/Slippage-v0",
                                  "SurgSim/PalpationPress-v0", "SurgSim/LayeredPalpation-v0"])
@pytest.mark.parametrize("options", [5, [1, 2], "inclusion_position"])
def test_reset_options_that_are_not_a_dict_are_refused_by_name(task, options):
    """A list or a number as ``options`` raised a raw TypeError in four tasks."""
    env = gym.make(task)
    try:
        with pytest.raises(ConfigError, match="reset options must be a dict"):
            env.reset(seed=0, options=options)
    finally:
        env.close()


@pytest.mark.parametrize("task, field, value, match", [
    ("SurgSim/Palpation-v0", "tip_radius", 5e-324, r"tip_radius=5e-324 m is outside \[0.0001, 1\] m"),   # overflowed
    ("SurgSim/Palpation-v0", "max_depth", 1e-9, r"max_depth=1e-09 m is outside \[0.0001, 1\] m"),
    ("SurgSim/Grasp-v0", "tolerance", 5e-324, r"tolerance=5e-324 m is outside \[0.0001, 1\] m"),
    ("SurgSim/Grasp-v0", "max_step", 1e-12, r"max_step=1e-12 m is outside \[1e-06, 1\] m"),
    ("SurgSim/Grasp-v0", "closing_speed", 5e-324, r"closing_speed=5e-324 m/s must be >= 0.0001"),
    ("SurgSim/PalpationPress-v0", "clearance", 5e-324, r"clearance=5e-324 m is outside \[0.0001, 1\] m"),
    ("SurgSim/LayeredPalpation-v0", "spacing", 10 ** 400, r"spacing=1000000.*\.\.\. (m )?(must be finite|is outside)"),
])
def test_degenerate_sizes_are_refused_with_the_bound(task, field, value, match):
    """Lengths of 1e-300 m were accepted (a probe tip of 5e-324 m then overflowed), and a 400-digit
    integer raised a raw OverflowError."""
    with pytest.raises(ConfigError, match=match):
        gym.make(task, **{field: value})


def test_an_exact_fraction_is_a_valid_length():
    """A Fraction workspace raised a raw TypeError while the error message was formatted."""
    from fractions import Fraction

    env = gym.make("SurgSim/Grasp-v0", workspace=Fraction(3, 50))
    env.close()


@pytest.mark.parametrize("task, kwargs, message", [
    ("SurgSim/Palpation-v0", {"slab_size": np.array(0.002)}, r"slab_size=array\(0.002\) is a 0-d array"),
    ("SurgSim/LayeredPalpation-v0", {"size": np.array(0.002)}, r"size=array\(0.002\) is a 0-d array"),
    ("SurgSim/LayeredPalpation-v0", {"control_hz": np.array(2.0)}, r"control_hz=array\(2.\) is a 0-d array; pass the number itself"),
    ("SurgSim/Palpation-v0", {"tip_radius": 1.7976931348623157e308}, r"tip_radius=1.7976931348623157e\+308 m is outside \[0.0001, 1\] m"),
    ("SurgSim/PalpationPress-v0", {"map_half_width": 1e300}, r"map_half_width=1e\+300 m is outside"),
    ("SurgSim/Grasp-v0", {"resolution": 1e-320}, r"resolution=1e-320 must be 'auto', a spacing in m in \[0.0001, 0.1\)"),
])
def test_numpy_0d_values_and_extreme_lengths_are_refused_by_name(task, kwargs, message):
    """A 0-d array passed validation and then failed len() / round(); a 1.8e308 m probe tip
    overflowed the surface sampling, a 1e300 m press map gave NaN observations, a subnormal
    resolution overflowed the node count: each is refused up front with the field and its bound."""
    with pytest.raises(ConfigError, match=message):
        gym.make(task, **kwargs)


@pytest.mark.parametrize("seed, message", [(-1, r"reset seed=-1 is outside \[0, "), ("a", "reset seed='a' must be an integer"),
                                           (1.5, "reset seed=1.5 must be an integer")])
def test_reset_refuses_bad_seeds_by_name_and_takes_numpy_integers(seed, message):
    env = gym.make("SurgSim/PalpationPress-v0")
    with pytest.raises(ConfigError, match=message):
        env.reset(seed=seed)
    a = env.reset(seed=np.int64(3))[0]
    b = env.reset(seed=3)[0]
    assert np.array_equal(a, b)
    env.close()
