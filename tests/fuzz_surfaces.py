"""Hostile-input surfaces and their hypothesis strategies, shared by tests/test_fuzz_*.py and
scripts/fuzz_counts.py. Each surface is ``name -> (strategy, run)``: ``run(case)`` feeds one
drawn case to the package and returns what it gave (checked for NaN by the harness)."""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import math
import struct
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

REPO = Path(__file__).resolve().parents[1]

# -- hostile values -------------------------------------------------------------------------------
EDGE_NUMBERS = [0, -1, 1, 10**12, 2**63, -(2**63), 10**400, 1e308, -1e308, 1e-308, 5e-324, 1e300,
                float("nan"), float("inf"), -float("inf"), 0.5, 3, 50, 1e-6]
hostile_scalar = st.one_of(
    st.sampled_from(EDGE_NUMBERS),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.integers(-(2**70), 2**70),
    st.none(),
    st.booleans(),
    st.text(max_size=6),
    st.complex_numbers(max_magnitude=1e3, allow_nan=False, allow_infinity=False),
    st.sampled_from(["", "auto", "symplectic", "implicit", "raise", "terminate", "overview", "liver"]),
)
hostile_value = st.one_of(
    hostile_scalar,
    st.lists(hostile_scalar, max_size=4).map(tuple),
    st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2).map(lambda v: tuple(sorted(v))),
)


# -- config fields ----------------------------------------------------------------------------------
def config_classes() -> dict:
    from surgsim_envs.envs.grasp import GraspConfig
    from surgsim_envs.envs.layered_palpation.config import LayeredPalpationConfig
    from surgsim_envs.envs.palpation import PalpationConfig
    from surgsim_envs.envs.palpation_press import PalpationPressConfig
    from surgsim_envs.envs.slippage import SlippageConfig

    return {"Palpation-v0": PalpationConfig, "PalpationPress-v0": PalpationPressConfig, "Grasp-v0": GraspConfig,
            "Slippage-v0": SlippageConfig, "LayeredPalpation-v0": LayeredPalpationConfig}


def config_case():
    classes = config_classes()
    return st.sampled_from(sorted(classes)).flatmap(
        lambda task: st.tuples(st.just(task), st.sampled_from([f.name for f in dataclasses.fields(classes[task])
                                                                 if f.name != "organ"]),
                               hostile_value))


def run_config(case):
    """Build and validate a task config with one hostile field (what ``gym.make`` checks first)."""
    from surgsim_envs.envs.checks import apply_overrides

    task, field, value = case
    cls = config_classes()[task]
    config = apply_overrides(cls(), {field: value})
    config.validate()
    return [getattr(config, f.name) for f in dataclasses.fields(config)
            if isinstance(getattr(config, f.name), (int, float)) and not isinstance(getattr(config, f.name), bool)]


#: reward fields of each task: an accepted value is stepped once (the env is reused) and the reward
#: must be finite
REWARD_FIELDS = {"Palpation-v0": ("shaping_weight", "time_cost", "press_reward", "cell_reward", "damage_weight",
                                  "localisation_weight", "success_bonus")}


# -- reset options ---------------------------------------------------------------------------------
PALPATION_OPTIONS = ("inclusion_position", "inclusion_xy", "inclusion_depth", "inclusion_radius", "stiffness_contrast", "young_scale")


def reset_case():
    return st.tuples(st.sampled_from(PALPATION_OPTIONS + ("bogus",)), hostile_value)


def run_reset(env, case):
    key, value = case
    obs, info = env.reset(seed=0, options={key: value})
    return obs


# -- actions ------------------------------------------------------------------------------------
def action_case():
    shapes = st.sampled_from([(4,), (3,), (5,), (1, 4), (4, 1), (), (0,), (2, 2)])
    dtypes = st.sampled_from(["float64", "float32", "int64", "complex128", "bool", "U3", "object", "float16"])
    return st.tuples(shapes, dtypes, st.lists(hostile_scalar.filter(lambda v: not isinstance(v, str)),
                                              min_size=1, max_size=1).map(lambda v: v[0]))


def make_action(case):
    shape, dtype, fill = case
    try:
        return np.full(shape, fill, dtype=object).astype(dtype)
    except (TypeError, ValueError, OverflowError):
        return np.full(shape, fill, dtype=object)


def run_action(env, case):
    obs, reward, terminated, truncated, info = env.step(make_action(case))
    return obs, reward


#: every registered task whose actions are fuzzed (one env each, reused across cases)
ACTION_TASKS = ("Palpation-v0", "PalpationPress-v0", "Grasp-v0", "Slippage-v0", "LayeredPalpation-v0")


def task_action_case():
    """(task, action case): an action of any shape and dtype, or the task's own shape filled with a
    hostile value."""
    return st.tuples(st.sampled_from(ACTION_TASKS), action_case())


def run_task_action(envs: dict, case):
    """Step task ``case[0]``'s env (reset first: a terminated episode is not the case under test)
    with the hostile action ``case[1]``."""
    task, action = case
    env = envs[task]
    env.reset(seed=0)
    return run_action(env, action)


# -- UDP pose packets ------------------------------------------------------------------------------
TEST_KEY = bytes(range(32))


def udp_case():
    """Random datagrams, or well-formed headers whose every field is drawn hostile, sent with or
    without the authentication tag a keyed session requires."""
    any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)
    fields = st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1), any_float,
                       st.tuples(any_float, any_float, any_float), st.tuples(any_float, any_float, any_float, any_float),
                       st.integers(0, 2**32 - 1), st.floats(width=32, allow_nan=True, allow_infinity=True))
    return st.one_of(st.tuples(st.just("bytes"), st.binary(max_size=200), st.booleans()),
                     st.tuples(st.just("fields"), fields, st.booleans()))


def run_udp(case):
    """Decode one datagram as the teleop bridge does (keyed when ``case[2]``)."""
    from surgsim_envs.haptics.pose_protocol import POSE_STRUCT, decode_pose, encode_pose

    kind, payload, keyed = case
    key = TEST_KEY if keyed else None
    if kind == "bytes":
        data = payload
    else:
        session, seq, ts, pos, quat, buttons, grip = payload
        data = POSE_STRUCT.pack(b"SSHP", 2, 1, session, seq, ts, *pos, *quat, buttons, grip)
        if keyed:       # the body re-sealed with the session key: only the values are hostile
            try:
                data = encode_pose(seq, ts, pos, quat, buttons, grip, session=session, key=key)
            except (ValueError, OverflowError, struct.error):
                pass
    p = decode_pose(data, key=key)
    return [p.timestamp, *p.position, *p.quaternion, p.grip]


# -- mesh files ------------------------------------------------------------------------------------
def valid_vtk(binary: bool) -> bytes:
    """A two-tet legacy VTK unstructured grid, ASCII or binary."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0], [1, 1, 1.0]])
    cells = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    head = b"# vtk DataFile Version 3.0\nt\n" + (b"BINARY" if binary else b"ASCII") + b"\nDATASET UNSTRUCTURED_GRID\n"
    if binary:
        raw = np.hstack([np.full((2, 1), 4), cells]).astype(">i4").tobytes()
        return (head + b"POINTS 5 double\n" + pts.astype(">f8").tobytes() + b"\nCELLS 2 10\n" + raw
                + b"\nCELL_TYPES 2\n" + np.full(2, 10).astype(">i4").tobytes() + b"\n")
    body = "POINTS 5 float\n" + "\n".join(" ".join(map(str, p)) for p in pts) + "\nCELLS 2 10\n"
    body += "\n".join("4 " + " ".join(map(str, c)) for c in cells) + "\nCELL_TYPES 2\n10\n10\n"
    return head + body.encode()


def mesh_case():
    """A valid VTK tet mesh with byte edits and a truncation, or random bytes under a surface suffix."""
    edits = st.lists(st.tuples(st.integers(0, 10_000), st.binary(min_size=1, max_size=8)), max_size=6)
    return st.one_of(st.tuples(st.just(".vtk"), st.tuples(st.booleans(), edits, st.integers(0, 400))),
                     st.tuples(st.sampled_from([".stl", ".obj", ".ply", ".off"]), st.binary(max_size=400)))


def run_mesh(case):
    """Load the hostile file with the project's loaders (tet mesh or surface)."""
    from surgsim_envs.geometry.loaders import load_surface, load_tet_mesh

    suffix, arg = case
    if suffix == ".vtk":
        binary, edits, cut = arg
        data = bytearray(valid_vtk(binary))
        for pos, chunk in edits:
            p = pos % (len(data) + 1)
            data[p:p + len(chunk)] = chunk
        if cut:
            data = data[:max(len(data) - cut, 0)]
    else:
        data = bytearray(arg)
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / f"fuzz{suffix}"
        f.write_bytes(bytes(data))
        if suffix == ".vtk":
            vol = load_tet_mesh(f)
            return [vol.nodes, vol.tet_volumes()]
        mesh = load_surface(f)
        return [np.asarray(mesh.vertices)]


# -- CLI flags ------------------------------------------------------------------------------------
TELEOP_FLAGS = ("--seed", "--size", "--fps", "--rate", "--duration", "--tremor", "--max-force", "--max-force-rate",
                "--spacing", "--camera", "--device", "--extrapolation")
flag_text = st.one_of(st.sampled_from(["-1", "0", "1e12", "inf", "nan", "-inf", "1e308", "25", "abc", "", "udp:1",
                                       "udp:70000", "keyboard", "replay:nofile.csv", "scripted", "bogus", "1e-300"]),
                      st.integers(-(2**40), 2**40).map(str), st.floats().map(repr), st.text(max_size=5))


def cli_case():
    return st.tuples(st.sampled_from(TELEOP_FLAGS), flag_text, flag_text)


def run_teleop_flags(case):
    """Parse ``surgsim teleop palpation --headless FLAG VALUE`` and run every check the command runs
    before it builds the scene (argparse errors count as refusals: exit code 2 with a message)."""
    from surgsim_envs.haptics import teleop
    from surgsim_envs.haptics.teleop_args import check_teleop_args

    flag, a, b = case
    parser = argparse.ArgumentParser(exit_on_error=True)
    teleop.add_arguments(parser)
    argv = ["palpation", "--headless", flag, a] + ([b] if flag == "--size" else [])
    import contextlib

    with contextlib.redirect_stderr(io.StringIO()):
        args = parser.parse_args(argv)
    teleop.parse_device(args.device)
    check_teleop_args(args)
    return [args.fps, args.rate, args.tremor]


def growth_case():
    return st.tuples(st.sampled_from(["--nodes", "--repeats", "--k"]), flag_text)


def run_growth_flags(case):
    from surgsim_envs.bench import growth_speed

    flag, value = case
    parser = argparse.ArgumentParser()
    growth_speed.add_arguments(parser)
    import contextlib

    with contextlib.redirect_stderr(io.StringIO()):
        args = parser.parse_args([flag, value])
    growth_speed.check_args(args)
    return [args.nodes, args.repeats, args.k]


# -- scenario values ------------------------------------------------------------------------------
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else ("-inf" if v == -math.inf else repr(v)))
    if isinstance(v, int):
        return str(v)     # tomllib reads integers of any size
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if v is None:
        return '""'
    if isinstance(v, complex):
        return f'"{v}"'
    # a TOML basic string: JSON escapes are TOML escapes, and TOML also refuses a raw DEL
    return json.dumps(str(v), ensure_ascii=False).replace("\x7f", "\\u007f")


ROLLOUT = """[scenario]
name = "fuzz_rollout"
task = "SurgSim/PalpationPress-v0"
[policy]
file = "shipped:SurgSim/PalpationPress-v0"
episodes = 1
max_steps = 5
[policy.env_kwargs]
{key} = {value}
"""
PHASES = """[scenario]
name = "fuzz_phases"
scene = "palpation"
[[phases]]
type = "press"
duration = 0.5
depth = 0.004
[scoring.criteria.peak_force]
{criterion}
"""


def phases_text(key: str, value: str) -> str:
    """The PHASES scenario with criterion key ``key`` set to TOML ``value`` (others: defaults)."""
    crit = {"target": "1.0", "limit": "3.0", "weight": "1.0", key: value}
    return PHASES.format(criterion="\n".join(f"{k} = {v}" for k, v in crit.items()))


def scenario_case():
    from surgsim_envs.envs.palpation_press import PalpationPressConfig

    fields = [f.name for f in dataclasses.fields(PalpationPressConfig)] + ["force_weight", "render_mode", "bogus"]
    return st.one_of(st.tuples(st.just("rollout"), st.sampled_from(fields), hostile_value),
                     st.tuples(st.just("phases"), st.sampled_from(["weight", "target", "limit"]), hostile_value))


def run_scenario_check(case):
    """``surgsim run --check`` of a scenario with one hostile value (env_kwargs or a criterion)."""
    from surgsim_envs.scenarios.loader import loads_scenario

    which, key, value = case
    text = ROLLOUT.format(key=key, value=_toml_value(value)) if which == "rollout" else \
        phases_text(key, _toml_value(value))
    sc = loads_scenario(text, "<fuzz>", folder=Path(tempfile.gettempdir()))
    return [len(sc.runs())]


# -- npz policy files -----------------------------------------------------------------------------
def good_policy_bytes() -> bytes:
    from surgsim_envs.policies.npz_policy import NpzPolicy

    p = NpzPolicy([np.full((3, 4), 0.1), np.full((4, 2), -0.2)], [np.zeros(4), np.ones(2)], activation="tanh")
    buf = io.BytesIO()
    np.savez(buf, **p.arrays())
    return buf.getvalue()


def npz_case():
    member = st.sampled_from(["W0", "b0", "W1", "obs_mean", "obs_std", "obs_clip", "action_scale", "action_low",
                              "activation", "format", "mode", "noise_scale", "log_std"])
    array = st.tuples(st.sampled_from([(3, 4), (4,), (2,), (), (0,), (4, 2), (1,), (3, 4, 1)]),
                      st.sampled_from(["float64", "float32", "int8", "complex128", "U4", "bool", "datetime64[s]",
                                       "float16", "uint64"]),
                      hostile_scalar.filter(lambda v: not isinstance(v, str)))
    return st.one_of(
        st.tuples(st.just("truncate"), st.integers(0, 4000)),
        st.tuples(st.just("flip"), st.tuples(st.integers(0, 4000), st.integers(1, 255))),
        st.tuples(st.just("member"), st.tuples(member, array)),
    )


def make_npz(case, folder: Path) -> Path:
    kind, arg = case
    raw = good_policy_bytes()
    path = folder / "fuzz.npz"
    if kind == "truncate":
        path.write_bytes(raw[:arg % max(len(raw), 1)])
    elif kind == "flip":
        i, x = arg
        b = bytearray(raw)
        b[i % len(b)] ^= x
        path.write_bytes(bytes(b))
    else:
        name, (shape, dtype, fill) = arg
        with zipfile.ZipFile(io.BytesIO(raw)) as zin:
            arrays = {n[:-4]: np.load(io.BytesIO(zin.read(n)), allow_pickle=False) for n in zin.namelist()}
        try:
            arrays[name] = np.full(shape, fill, dtype=object).astype(dtype)
        except (TypeError, ValueError, OverflowError):
            arrays[name] = np.full(shape, str(fill))
        np.savez(path, **arrays)
    return path


def run_npz(case):
    """Load a damaged / hostile ``.npz`` policy and act on one observation."""
    from surgsim_envs.policies.npz_policy import NpzPolicy

    with tempfile.TemporaryDirectory() as tmp:
        policy = NpzPolicy.load(make_npz(case, Path(tmp)))
        return policy(np.zeros(policy.obs_size))


# -- vector env options and actions -------------------------------------------------------------
VECTOR_OPTIONS = ("num_envs", "workers", "info_keys", "autoreset_mode", "context", "timeout_s", "spin_us",
                  "worker_spin_us", "in_main", "max_info_keys", "actions")


def vector_case():
    return st.tuples(st.sampled_from(VECTOR_OPTIONS), hostile_value)


def run_vector(case):
    """A 2-env PalpationPress-v0 vector env (one worker) with one hostile option, or hostile actions
    (every entry of the (2, 3) action array set to the drawn value), reset and stepped."""
    from surgsim_envs.vector import SurgSimVectorEnv

    key, value = case
    kwargs = {"num_envs": 2, "workers": 1, "timeout_s": 60.0}
    if key != "actions":
        kwargs[key] = value
        if key == "num_envs":
            kwargs.pop("workers")
    if kwargs.get("num_envs") is not None and validate_int(kwargs["num_envs"]) > 4:
        kwargs["num_envs"] = 4 if kwargs["num_envs"] <= 1024 else kwargs["num_envs"]   # keep valid runs small
    vec = SurgSimVectorEnv("SurgSim/PalpationPress-v0", **kwargs)
    try:
        vec.reset(seed=0)
        actions = np.zeros((vec.num_envs, 3), dtype=np.float32)
        if key == "actions":
            actions = np.empty((vec.num_envs, 3), dtype=object)
            for i in np.ndindex(actions.shape):
                actions[i] = value
            try:
                actions = actions.astype(np.asarray(value).dtype)
            except (TypeError, ValueError, OverflowError):
                pass
        obs, reward, *_ = vec.step(actions)
        return obs, reward
    finally:
        vec.close()


def validate_int(value) -> int:
    """``value`` if it is a plain int (not bool), else 0."""
    return value if isinstance(value, int) and not isinstance(value, bool) else 0
