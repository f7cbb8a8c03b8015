"""Scenario files are data: code-loading policies are opt-in and confined to the
scenario's folder; .npz data policies; every bad value is caught at load/--check with its line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from surgsim_envs.cli import main
from surgsim_envs.errors import ConfigError
from surgsim_envs.scenarios import load_scenario, loads_scenario
from surgsim_envs.policies.npz_policy import NpzPolicy
from surgsim_envs.scenarios.policies import check_policy_reference, load_policy

ROOT = Path(__file__).resolve().parents[1]
PHASES = """
[scenario]
name = "ok"
scene = "palpation"

[[phases]]
type = "press"
duration = 1.0
depth = 0.004
"""
ROLLOUT = """
[scenario]
name = "roll"
task = "SurgSim/Palpation-v0"

[policy]
file = "{ref}"
"""
POLICY_PY = """
import pathlib
pathlib.Path(__file__).with_name("ran.txt").write_text("code ran")
def act(obs):
    return obs
"""


def _write(folder: Path, text: str, name: str = "s.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text(text)
    return p


def _line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), start=1) if needle in line)


# -- trust model --------------------------------------------------------------------------------
def test_code_policy_in_a_scenario_file_needs_allow_code_and_does_not_run(tmp_path):
    (tmp_path / "pol.py").write_text(POLICY_PY)
    text = ROLLOUT.format(ref="pol.py:act")
    f = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=rf"s\.toml, line {_line_of(text, 'file =')}: policy\.file: .*--allow-code"):
        load_scenario(f)
    assert not (tmp_path / "ran.txt").exists()
    sc = load_scenario(f, allow_code=True)  # opted in: the file in the scenario's folder loads
    policy = load_policy(sc.policy.file, sc.folder, allow_code=True)
    assert (tmp_path / "ran.txt").read_text() == "code ran" and policy(3) == 3


@pytest.mark.parametrize("ref, message", [
    ("../outside/pol.py:act", "outside the scenario's folder"),
    ("os:system", "installed module 'os'"),
    ("../outside/model.zip", "outside the scenario's folder"),
])
def test_with_allow_code_a_scenario_still_cannot_reach_outside_its_folder(tmp_path, ref, message):
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "pol.py").write_text(POLICY_PY)
    (tmp_path / "outside" / "model.zip").write_bytes(b"PK")
    f = _write(tmp_path / "scen", ROLLOUT.format(ref=ref))
    with pytest.raises(ConfigError, match=message):
        load_scenario(f, allow_code=True)
    assert not (tmp_path / "outside" / "ran.txt").exists()


def test_symlink_out_of_the_folder_is_outside(tmp_path):
    (tmp_path / "elsewhere.py").write_text(POLICY_PY)
    (tmp_path / "scen").mkdir()
    (tmp_path / "scen" / "link.py").symlink_to(tmp_path / "elsewhere.py")
    with pytest.raises(ConfigError, match="outside the scenario's folder"):
        check_policy_reference("link.py:act", tmp_path / "scen", allow_code=True)
    # the user's own --policy is trusted (still only with allow_code)
    assert check_policy_reference(str(tmp_path / "elsewhere.py") + ":act", None, allow_code=True, trusted=True) == "code"
    with pytest.raises(ConfigError, match="--allow-code"):
        check_policy_reference("os:system", None, allow_code=False, trusted=True)


def test_builtin_and_data_policies_need_no_flag(tmp_path):
    assert check_policy_reference("builtin:palpation_scan") == "builtin"
    assert load_policy("surgsim_envs.scenarios.policies:hold_still")({"offset": 1, "opening": 2}) == {
        "offset": 1, "opening": 2}
    with pytest.raises(ConfigError, match="built-in policies"):
        check_policy_reference("builtin:nope")
    NpzPolicy([np.eye(2)], [np.zeros(2)]).save(tmp_path / "p.npz")
    sc = load_scenario(_write(tmp_path, ROLLOUT.format(ref="p.npz")))
    assert sc.policy.file == "p.npz"


# -- npz data policies ------------------------------------------------------------------------
def test_npz_policy_forward_pass_matches_the_formula(tmp_path):
    rng = np.random.default_rng(3)
    w0, b0, w1, b1 = rng.normal(size=(5, 8)), rng.normal(size=8), rng.normal(size=(8, 3)), rng.normal(size=3)
    mean, std = rng.normal(size=5), rng.uniform(0.5, 2.0, size=5)
    scale, bias = np.array([2.0, 0.5, 1.0]), np.array([0.1, -0.2, 0.0])
    pol = NpzPolicy([w0, w1], [b0, b1], activation="tanh", output_activation="tanh", obs_mean=mean, obs_std=std,
                    obs_clip=1.5, action_scale=scale, action_bias=bias, action_low=[-1, -1, -0.3],
                    action_high=[1, 1, 0.3])
    path = pol.save(tmp_path / "mlp.npz")
    loaded = NpzPolicy.load(path)
    obs = rng.normal(size=5) * 3
    x = np.clip((obs - mean) / std, -1.5, 1.5)
    expected = np.clip(bias + scale * np.tanh(np.tanh(x @ w0 + b0) @ w1 + b1), [-1, -1, -0.3], [1, 1, 0.3])
    np.testing.assert_allclose(loaded(obs), expected, rtol=1e-6)  # float32 actions
    with np.load(path, allow_pickle=False) as z:  # plain arrays only
        assert str(z["format"]) == "surgsim-mlp-v1" and z["W1"].shape == (8, 3)


def test_npz_policy_dict_observations_and_actions(tmp_path):
    w = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 2.0]])
    pol = NpzPolicy([w], [np.zeros(4)], activation="relu", obs_keys=["offset", "opening"],
                    action_keys=["offset", "opening"], action_sizes=[3, 1])
    NpzPolicy.load(pol.save(tmp_path / "d.npz"))
    out = pol({"offset": [0.01, 0.02, 0.03], "opening": 0.004})
    np.testing.assert_allclose(out["offset"], [0.01, 0.02, 0.03]) and None
    assert out["opening"] == pytest.approx(0.008)
    with pytest.raises(ConfigError, match=r"lacks keys \['opening'\]"):
        pol({"offset": [0, 0, 0]})


@pytest.mark.parametrize("arrays, message", [
    (dict(W0=np.full((2, 2), np.nan), b0=np.zeros(2)), "W0 holds NaN"),
    (dict(W0=np.eye(2), b0=np.zeros(3)), "b0 has 3 values"),
    (dict(W0=np.eye(2), b0=np.zeros(2), W1=np.ones((3, 1)), b1=np.zeros(1)), "W1 takes 3 inputs"),
    (dict(W0=np.eye(2), b0=np.zeros(2), activation=np.array("sigmoid")), "activation 'sigmoid' unknown"),
    (dict(W0=np.eye(2), b0=np.zeros(2), obs_std=np.array([1.0, 0.0])), "obs_std must be > 0"),
    (dict(W0=np.eye(2)), "needs its b"),
    (dict(W0=np.array([object()], dtype=object), b0=np.zeros(2)), "member 'W0' has dtype object"),
])
def test_malformed_npz_policies_are_config_errors(tmp_path, arrays, message):
    f = tmp_path / "bad.npz"
    np.savez(f, format=np.array("surgsim-mlp-v1"), **arrays)
    with pytest.raises(ConfigError, match=message):
        NpzPolicy.load(f)


def test_npz_policy_rejects_wrong_observation_size_and_nan():
    pol = NpzPolicy([np.eye(2)], [np.zeros(2)])
    with pytest.raises(ConfigError, match="expects 2 observation values, got 3"):
        pol([1.0, 2.0, 3.0])
    with pytest.raises(ConfigError, match="NaN or inf"):
        pol([math.nan, 0.0])


# -- values caught at load / --check ------------------------------------------------------------
@pytest.mark.parametrize("old, new, key, message", [
    ("depth = 0.004", "depth = -0.004", "depth", r"phases\[0\]\.depth: -0\.004 is out of range"),
    ("depth = 0.004", "depth = 0.004\ntype2 = 1", "type2", "unknown key 'type2'"),
    ('type = "press"', 'type = "palpate"\ngrid = [1000, 1000]', "grid", r"phases\[0\]\.grid\[0\]: 1000 is out of range"),
    ('type = "press"', 'type = "palpate"\ngrid = [30, 30]', "grid", "asks for 900 presses"),
    ('scene = "palpation"', 'scene = "palpation"\n[scene]\ndt = 1.0', "dt =", r"scene\.dt: 1\.0 is out of range"),
    ('scene = "palpation"', 'scene = "palpation"\n[scene]\nspacing = 1e-5', "spacing", "scene.spacing"),
    ('scene = "palpation"', 'scene = "palpation"\n[scene]\nmaterial = "cheese"', "material",
     "unknown material preset 'cheese'"),
    ('scene = "palpation"', 'scene = "palpation"\n[scene]\nmodel = "magic"', "model", "unknown tissue model 'magic'"),
    ('scene = "palpation"', 'scene = "palpation"\n[scene]\norgan = "heart2"', "organ", "unknown organ 'heart2'"),
    ('scene = "palpation"', 'scene = "palpation"\n[sweep]\nspacing = [0.005, 1e-6]', "spacing",
     r"sweep\.spacing\[1\]: 1e-06 is out of range"),
    ("duration = 1.0", "duration = 1e12", "duration = 1e12", r"phases\[0\]\.duration: 1000000000000\.0 is out of range"),
    ('name = "ok"', 'name = ".."', "name", "not starting with '.'"),
    ('name = "ok"', 'name = "../../etc"', "name", "names the output folder"),
    ('name = "ok"', 'name = "ok"\nseed = -1', "seed", r"scenario\.seed: -1 is out of range"),
    ('scene = "palpation"', 'scene = "palpation"\n[trainee]\ndriver = "device"\ndevice = "replay:nope.csv"',
     "device =", "replay file 'nope.csv' not found"),
    ('scene = "palpation"', 'scene = "palpation"\n[trainee]\ndriver = "device"\ndevice = "udp:99999"',
     "device =", "PORT must be an integer in"),
])
def test_bad_values_fail_at_load_with_their_line(tmp_path, old, new, key, message):
    text = PHASES.replace(old, new)
    assert text != PHASES
    f = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=rf"s\.toml, line {_line_of(text, key)}: .*{message}"):
        load_scenario(f)


def test_run_duration_is_capped_also_through_the_duration_scale():
    text = PHASES.replace("duration = 1.0", "duration = 500.0") + '\n[[phases]]\ntype = "press"\nduration = 500.0\n'
    sc = loads_scenario(text.replace("duration = 500.0", "duration = 100.0"))
    with pytest.raises(ConfigError, match="3600 s limit"):
        sc.scaled(50.0)
    loads_scenario(text)  # 1,000 s is fine
    with pytest.raises(ConfigError, match="3600 s limit"):
        loads_scenario(text.replace('name = "ok"', 'name = "ok"\nduration_scale = 4.0'))


def test_unknown_task_id_fails_at_load():
    pytest.importorskip("gymnasium")
    text = ROLLOUT.format(ref="builtin:palpation_scan").replace("Palpation-v0", "Palpaton-v9")
    with pytest.raises(ConfigError, match=r"line 4: scenario\.task: unknown task id 'SurgSim/Palpaton-v9'"):
        loads_scenario(text, "x.toml")


def test_replay_file_next_to_the_scenario_is_found(tmp_path):
    (tmp_path / "hand.csv").write_text("t,x,y,z\n0,0,0,0\n")
    text = PHASES.replace('scene = "palpation"', 'scene = "palpation"\n[trainee]\ndriver = "device"\n'
                                                 'device = "replay:hand.csv"')
    assert load_scenario(_write(tmp_path, text)).trainee.device == "replay:hand.csv"


def test_deep_nesting_and_huge_files_are_config_errors(tmp_path):
    deep = 'a = ' + '[' * 3000 + ']' * 3000 + '\n'
    with pytest.raises(ConfigError, match="nested too deeply"):
        loads_scenario(deep, "deep.toml")
    with pytest.raises(ConfigError, match="nested|unknown top-level"):
        loads_scenario('[scenario]\nname = "x"\nscene = "grasp"\n[[phases]]\ntype = "hold"\nlabel = '
                       + '[' * 500 + ']' * 500 + '\n', "deep.toml")
    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * 1_100_000 + "\n")
    with pytest.raises(ConfigError, match="at most 1000000"):
        load_scenario(big)


def test_cli_check_reports_the_line_and_refuses_code_without_the_flag(tmp_path, capsys):
    (tmp_path / "pol.py").write_text(POLICY_PY)
    text = ROLLOUT.format(ref="pol.py:act")
    f = _write(tmp_path, text)
    assert main(["run", str(f), "--check"]) == 2
    err = capsys.readouterr().err
    assert "line 7" in err and "--allow-code" in err
    assert main(["run", str(f), "--check", "--allow-code"]) == 0
    assert not (tmp_path / "ran.txt").exists()  # --check validates, runs nothing
    bad = _write(tmp_path, PHASES.replace("depth = 0.004", "depth = -1.0"), "neg.toml")
    assert main(["run", str(bad), "--check"]) == 2
    assert f"line {_line_of(PHASES, 'depth')}: phases[0].depth: -1.0" in capsys.readouterr().err
    good = _write(tmp_path, PHASES, "good.toml")
    assert main(["run", str(good), "--check", "--policy", "os:system"]) == 2
    assert "--allow-code" in capsys.readouterr().err


def test_shipped_scenarios_still_load():
    for p in sorted((ROOT / "tasks").glob("*.toml")):
        load_scenario(p)


def test_cli_checks_the_device_file_and_a_non_string_phase_type(tmp_path, capsys):
    good = _write(tmp_path, PHASES, "good.toml")
    assert main(["run", str(good), "--check", "--device", "replay:missing.csv"]) == 2
    assert "replay file 'missing.csv' not found" in capsys.readouterr().err
    with pytest.raises(ConfigError, match=r"phases\[0\]\.type: give the phase type as a string, got \[1\]"):
        loads_scenario(PHASES.replace('type = "press"', "type = [1]"), "x.toml")


def test_npz_policy_drives_a_task_rollout(tmp_path):
    gym = pytest.importorskip("gymnasium")
    import surgsim_envs.envs  # noqa: F401
    from surgsim_envs.scenarios import run_scenario

    env = gym.make("SurgSim/Palpation-v0")
    n_obs, n_act = env.observation_space.shape[0], env.action_space.shape[0]
    low, high = env.action_space.low, env.action_space.high
    env.close()
    rng = np.random.default_rng(0)
    NpzPolicy([rng.normal(size=(n_obs, 16)) * 0.1, rng.normal(size=(16, n_act))], [np.zeros(16), np.zeros(n_act)],
              output_activation="tanh", action_low=low, action_high=high).save(tmp_path / "scan.npz")
    text = ROLLOUT.format(ref="scan.npz") + "episodes = 1\nmax_steps = 5\n"
    sc = load_scenario(_write(tmp_path, text))  # no --allow-code needed: data
    (res,) = run_scenario(sc, progress=False)
    assert res.error is None or "max_steps" in res.error
    assert len(res.recording.t) == 5 and np.all(np.isfinite(res.recording.normal))


def test_scene_organ_may_be_a_mesh_file_next_to_the_scenario(tmp_path):
    """[scene] organ = "kidney.stl": checked at load (file found next to the scenario, else an error
    with its line), resolved against the scenario's folder, and built into the scene's tissue."""
    trimesh = pytest.importorskip("trimesh")
    from surgsim_envs.scene import build_scene
    from surgsim_envs.scenarios.runner import scene_config

    text = PHASES.replace('scene = "palpation"', 'scene = "grasp"').replace(
        'type = "press"\nduration = 1.0\ndepth = 0.004', 'type = "hold"\nduration = 0.1') + \
        '\n[scene]\norgan = "kidney.stl"\n'
    with pytest.raises(ConfigError, match=r"line \d+: scene\.organ: organ mesh file 'kidney\.stl' not found"):
        load_scenario(_write(tmp_path, text))
    trimesh.creation.capsule(height=0.05, radius=0.012).export(tmp_path / "kidney.stl")
    sc = load_scenario(_write(tmp_path, text))
    cfg = scene_config(sc)
    assert cfg.tissues[0].organ == str(tmp_path / "kidney.stl")
    scene = build_scene(cfg)
    nodes = next(iter(scene.tissues.values())).rest_positions
    assert np.ptp(nodes, axis=0).max() == pytest.approx(0.074, abs=0.015)   # the capsule's 7.4 cm length
    with pytest.raises(ConfigError, match="unknown organ 'kidnee'"):
        loads_scenario(text.replace('"kidney.stl"', '"kidnee"'))
