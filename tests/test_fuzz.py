"""Property-based fuzzing of everything that takes outside input: the UDP pose decoder
and sequence gate, the scenario schema, the legacy VTK reader and the mesh loaders, and env
actions. No input may crash the process, hang or return NaN; a rejection is a ConfigError (or
ValueError) whose message names the value. Small ``max_examples`` keep the default run fast. No
per-example deadline (the machine's load varies); a hang is caught by the module's pytest
timeout instead."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from surgsim_envs.errors import ConfigError  # noqa: E402
from surgsim_envs.haptics.pose_protocol import POSE_STRUCT, MalformedPacketError, decode_pose, encode_pose  # noqa: E402
from surgsim_envs.haptics.session_gate import SessionGate  # noqa: E402

pytestmark = pytest.mark.timeout(300)

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                        HealthCheck.too_slow])
any_float = st.floats(allow_nan=True, allow_infinity=True, width=64)


# -- UDP --------------------------------------------------------------------------------------
def _check_pose(p):
    assert all(math.isfinite(v) for v in (p.timestamp, *p.position, *p.quaternion, p.grip))
    assert abs(math.fsum(v * v for v in p.quaternion) - 1.0) < 1e-12
    assert 0.0 <= p.grip <= 1.0


@FAST
@given(st.binary(max_size=200))
def test_fuzz_decode_pose_random_bytes(data):
    try:
        p = decode_pose(data)
    except MalformedPacketError as exc:
        assert str(exc)
    else:
        _check_pose(p)


@FAST
@given(st.integers(0, 2**32 - 1), any_float, st.tuples(any_float, any_float, any_float),
       st.tuples(any_float, any_float, any_float, any_float), st.integers(0, 2**32 - 1),
       st.floats(width=32, allow_nan=True, allow_infinity=True))
def test_fuzz_decode_pose_every_field(seq, ts, pos, quat, buttons, grip):
    raw = POSE_STRUCT.pack(b"SSHP", 2, 1, 99, seq, ts, *pos, *quat, buttons, grip)
    try:
        p = decode_pose(raw)
    except MalformedPacketError as exc:
        msg = str(exc)
        nums = (ts, *pos, *quat, grip)
        if not all(math.isfinite(v) for v in nums):
            assert "nan" in msg or "inf" in msg
        elif "quaternion" in msg:
            assert repr(tuple(quat))[:10] in msg or "zero length" in msg
        else:
            assert "grip" in msg and repr(grip)[:4] in msg
    else:
        _check_pose(p)
        assert p.seq == seq and p.buttons == buttons


@FAST
@given(st.lists(st.tuples(st.sampled_from([1, 2, 3]), st.integers(0, 2**32 - 1), st.sampled_from(["a", "b", "c"]),
                          st.floats(0.0, 0.1)), max_size=60))
def test_fuzz_session_gate_never_raises_and_admits_only_its_session_or_a_takeover(packets):
    g = SessionGate()
    t = 0.0
    for session, seq, addr, dt in packets:
        t += dt
        before = (g.session, g.addr, g.last_seq, g.last_time)
        if g.admit(session, seq, addr, t):
            assert (g.session, g.addr, g.last_seq) == (session, addr, seq)
            if before[0] is not None and (session, addr) == before[:2]:
                assert 0 < ((seq - before[2]) & 0xFFFFFFFF) <= g.window  # ahead within the window
            elif before[0] is not None:
                assert t - before[3] > g.session_timeout  # another stream only after silence


# -- scenario schema ----------------------------------------------------------------------------
toml_scalar = st.one_of(st.booleans(), st.integers(-10**12, 10**12), any_float, st.text(max_size=12))
toml_value = st.recursive(toml_scalar, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                               st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                          max_leaves=12)
KEYS = {
    "scenario": ["name", "scene", "task", "seed", "sample_period", "duration_scale", "description"],
    "scene": ["organ", "model", "material", "spacing", "mu", "dt", "inclusion_xy"],
    "trainee": ["driver", "device", "script", "policy", "tremor"],
    "phase": ["type", "duration", "depth", "clearance", "grid", "at", "region", "distance", "force", "opening",
              "driver", "device", "policy"],
}
VALID = {"scenario": {"name": "ok", "scene": "palpation"},
         "phases": [{"type": "press", "duration": 1.0, "depth": 0.004}]}


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(["scenario", "scene", "trainee", "phase"]), st.data())
def test_fuzz_schema_mutations_are_accepted_in_range_or_named(table, data):
    import copy

    from surgsim_envs.scenarios.loader import parse_scenario
    from surgsim_envs.scenarios.schema import LIMITS

    doc = copy.deepcopy(VALID)
    key = data.draw(st.sampled_from(KEYS[table]))
    value = data.draw(toml_value)
    target = doc["phases"][0] if table == "phase" else doc.setdefault(table, {})
    target[key] = value
    try:
        sc = parse_scenario(doc, "fuzz.toml")
    except ConfigError as exc:
        assert "fuzz.toml" in str(exc)
    else:
        # accepted numbers lie within their documented limits
        for (tab, k), v in (((table, key), value),):
            rule = f"{'phase' if tab == 'phase' else tab}.{k}"
            if rule in LIMITS and isinstance(v, (int, float)) and not isinstance(v, bool):
                lo, hi = LIMITS[rule][:2]
                assert lo <= v <= hi
        assert sc.run_duration() <= 3600.0


@settings(max_examples=60, deadline=None)
@given(st.text(max_size=300))
def test_fuzz_scenario_text(text):
    from surgsim_envs.scenarios.loader import loads_scenario

    try:
        loads_scenario(text, "fuzz.toml")
    except ConfigError as exc:
        assert "fuzz.toml" in str(exc)


# -- VTK and mesh loaders -------------------------------------------------------------------------
def _valid_vtk(binary: bool) -> bytes:
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


@FAST
@given(st.booleans(), st.lists(st.tuples(st.integers(0, 10_000), st.binary(min_size=1, max_size=8)), max_size=6),
       st.integers(0, 400))
def test_fuzz_vtk_reader_and_tet_loader(tmp_path_factory, binary, edits, cut):
    from surgsim_envs.geometry.loaders import load_tet_mesh
    from surgsim_envs.geometry.vtk_legacy import read_legacy_vtk

    data = bytearray(_valid_vtk(binary))
    for pos, chunk in edits:
        p = pos % (len(data) + 1)
        data[p:p + len(chunk)] = chunk
    if cut:
        data = data[:max(len(data) - cut, 0)]
    f = tmp_path_factory.mktemp("vtk") / "m.vtk"
    f.write_bytes(bytes(data))
    try:
        pts, (conn, off), types = read_legacy_vtk(f)
    except ConfigError as exc:
        assert "m.vtk" in str(exc)
    else:
        assert np.all(np.isfinite(pts)) and (len(conn) == 0 or 0 <= conn.min() <= conn.max() < len(pts))
        assert off[0] == 0 and off[-1] == len(conn) and len(types) == len(off) - 1
    try:
        vol = load_tet_mesh(f)
    except ConfigError as exc:
        assert "m.vtk" in str(exc)
    else:
        assert np.all(np.isfinite(vol.nodes)) and np.all(vol.tet_volumes() > 0)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from([".stl", ".obj", ".ply", ".off"]), st.binary(max_size=400))
def test_fuzz_surface_loader(tmp_path_factory, suffix, data):
    pytest.importorskip("trimesh")
    from surgsim_envs.geometry.loaders import load_surface

    f = tmp_path_factory.mktemp("surf") / f"s{suffix}"
    f.write_bytes(data)
    try:
        mesh = load_surface(f)
    except ConfigError as exc:
        assert "s" + suffix in str(exc)
    else:
        assert mesh.is_watertight and np.all(np.isfinite(mesh.vertices))


# -- env actions ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def palpation_env():
    gym = pytest.importorskip("gymnasium")
    import surgsim_envs.envs  # noqa: F401

    env = gym.make("SurgSim/Palpation-v0")
    env.reset(seed=0)
    yield env
    env.close()


action_values = st.one_of(st.floats(-2.0, 2.0), any_float)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.lists(action_values, min_size=4, max_size=4), st.lists(action_values, max_size=7)))
def test_fuzz_env_actions(palpation_env, values):
    env = palpation_env
    with np.errstate(over="ignore"):  # 1e308 -> inf in float32: part of the fuzz
        action = np.array(values, dtype=np.float32) if values else np.zeros(0, dtype=np.float32)
    try:
        obs, reward, terminated, truncated, info = env.step(action)
    except ValueError as exc:  # ConfigError is a ValueError: a bad action is named, the env survives
        assert str(exc)
        env.reset(seed=1)
        return
    assert np.all(np.isfinite(obs)) and math.isfinite(reward) and env.observation_space.contains(obs)
    if terminated or truncated:
        env.reset(seed=2)
