"""Hostile ``surgsim`` command lines: every flag either works or is refused with its name, the
bound and the fix, before anything runs or is written (never a traceback, never a hang)."""

from __future__ import annotations

import json
import re

import pytest

pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402

import fuzz_surfaces as fs  # noqa: E402
from fuzz_harness import check  # noqa: E402
from surgsim_envs.cli import main  # noqa: E402

FAST = settings(max_examples=60, deadline=None, database=None, suppress_health_check=list(HealthCheck))
MORE = settings(max_examples=1500, deadline=None, database=None, suppress_health_check=list(HealthCheck))


@FAST
@given(fs.cli_case())
def test_fuzz_teleop_flags(case):
    check(fs.run_teleop_flags, case, timeout_s=20)


@pytest.mark.slow
@MORE
@given(fs.cli_case())
def test_fuzz_teleop_flags_more(case):
    check(fs.run_teleop_flags, case, timeout_s=20)


@FAST
@given(fs.growth_case())
def test_fuzz_bench_growth_flags(case):
    check(fs.run_growth_flags, case, timeout_s=20, names=(case[0],))


def _run(argv, capsys):
    code = main(argv)
    return code, capsys.readouterr().err


@pytest.mark.parametrize("flags, message", [
    (["--seed", "-1"], r"--seed=-1 is outside \[0, "),
    (["--size", "0", "0"], r"--size W=0 px is outside \[16, 4,096\]"),
    (["--fps", "inf"], "--fps=inf Hz must be finite"),
    (["--rate", "1e9"], r"--rate=1000000000.0 Hz is outside \(0, 10000\] Hz"),
    (["--tremor", "1e9"], r"--tremor=1000000000.0 m is outside \[0, 0.01\] m"),
    (["--device", "udp:1"], "PORT must be an integer in 1024..65535"),
    (["--duration", "1e12"], r"--duration=1000000000000.0 s is outside \(0, 3600\] s"),
    (["--spacing", "1e-6"], r"--spacing=1e-06 m is outside \[0.002, 0.05\] m"),
])
def test_teleop_refuses_before_building_the_scene(flags, message, capsys, tmp_path):
    code, err = _run(["teleop", "palpation", "--headless", "--out", str(tmp_path), *flags], capsys)
    assert code == 2
    assert "building the" not in capsys.readouterr().out      # refused up front
    import re
    assert re.search(message, err), err


def test_teleop_refuses_a_malformed_or_endless_script(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"waypoints": [[0, 0, 0]')
    code, err = _run(["teleop", "palpation", "--headless", "--out", str(tmp_path), "--script", str(bad)], capsys)
    assert code == 2 and "not valid JSON" in err, err
    listed = tmp_path / "list.json"
    listed.write_text("[1, 2]")
    code, err = _run(["teleop", "palpation", "--headless", "--out", str(tmp_path), "--script", str(listed)], capsys)
    assert code == 2 and "expected a trajectory object" in err, err
    endless = tmp_path / "endless.json"       # 1 cm at 1e-12 m/s: 1e10 s
    endless.write_text(json.dumps({"waypoints": [[0, 0, 0], [0.01, 0, 0]], "speeds": [1e-12], "dwell": [0, 0]}))
    code, err = _run(["teleop", "palpation", "--headless", "--out", str(tmp_path), "--script", str(endless)], capsys)
    assert code == 2 and "lasts 1e+10 s, above the 3600 s" in err and "--duration" in err, err


def test_bench_growth_refuses_a_billion_nodes(capsys, tmp_path):
    code, err = _run(["bench", "growth", "--nodes", "1000000000", "--out", str(tmp_path)], capsys)
    assert code == 2 and r"--nodes=1000000000 is outside [100, 200,000]" in err, err
    assert not any(tmp_path.iterdir())


def test_bench_stability_typo_leaves_the_previous_map(capsys, tmp_path):
    (tmp_path / "stability.json").write_text('[{"kept": true}]')
    code, err = _run(["bench", "stability", "--models", "bogus", "--quick", "--out", str(tmp_path)], capsys)
    assert code == 2 and "unknown model(s) ['bogus']" in err and "nothing was written" in err, err
    assert json.loads((tmp_path / "stability.json").read_text()) == [{"kept": True}]
    code, err = _run(["bench", "stability", "--models", ",", "--out", str(tmp_path)], capsys)
    assert code == 2 and "unknown model(s) []" in err, err


def test_material_relax_refuses_a_hold_of_1e9_seconds(capsys):
    code, err = _run(["material", "relax", "--model", "mass_spring", "--hold-time", "1e9"], capsys)
    assert code == 2 and "relax: ramp_time + hold_time = 1e+09 s" in err and "shorten hold_time" in err, err


@pytest.mark.parametrize("argv, message", [
    (["bench", "envs", "--steps", "1000000000000"], r"--steps=1000000000000 is outside \[1, 1,000,000\]"),
    (["bench", "envs", "--workers", "-1"], r"--workers=-1 is outside \[0, 1,024\]"),
    (["bench", "layers", "--steps", "1000000000000"], r"--steps=1000000000000 is outside \[1, 1,000,000\]"),
])
def test_bench_step_counts_are_bounded(argv, message, capsys):
    import re

    code, err = _run(argv, capsys)
    assert code == 2 and re.search(message, err), err


def test_bench_speed_steps_are_bounded_by_argparse(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "speed", "--steps", "1000000000000"])
    assert exc.value.code == 2
    assert "expected a positive integer of at most 1,000,000" in capsys.readouterr().err


@pytest.mark.parametrize("argv, flag", [
    (["bench", "trajectory", "--record", "{blocked}/x.pkl", "--steps", "2"], "--record"),
    (["bench", "soak", "--task", "SurgSim/PalpationPress-v0", "--steps", "10", "--out", "{blocked}/soak.json"], "--out"),
    (["record", "SurgSim/PalpationPress-v0", "--episodes", "1", "--out", "{blocked}/data"], "--out"),
])
def test_unwritable_outputs_are_refused_before_the_run(argv, flag, capsys, tmp_path):
    """An output under a path that is a file (so no folder can be made there) was a raw
    FileNotFoundError, for --record only after every trajectory had run: now exit 2 naming it."""
    blocked = tmp_path / "a_file"
    blocked.write_text("")
    code, err = _run([a.replace("{blocked}", str(blocked)) for a in argv], capsys)
    assert code == 2 and flag in err and "cannot write" in err and "Traceback" not in err, err


@pytest.mark.parametrize("argv, message", [
    (["grow", "--spacing", "1e308"], r"--spacing=1e\+308 m is outside \[0.0015, 0.02\] m"),
    (["grow", "--translation-mm", "1e308"], r"--translation-mm=1e\+308 mm is outside \[-30, 30\] mm"),
    (["grow", "--rotation-deg", "1e308"], r"--rotation-deg=1e\+308 deg is outside"),
    (["grow", "--alpha", "nan"], r"--alpha='nan' must be a positive finite number"),
    (["material", "indent", "--width", "1e308"], r"--width=1e\+308 m is outside \[0.0001, 0.5\] m"),
    (["material", "relax", "--spacing", "1e308"], r"--spacing=1e\+308 m is outside"),
    (["material", "slip", "--mu", "1e308"], r"--mu=1e\+308 is outside \[0, 5\]"),
    (["material", "slip", "--max-pull-time", "1e308"], r"--max-pull-time=1e\+308 s is outside"),
    (["material", "slip", "--material", "abc"], r"--material 'abc'"),
    (["bench", "speed", "--models", "abc"], r"--models='abc': unknown name\(s\) \['abc'\]"),
    (["bench", "accuracy", "--models", "abc"], r"--models='abc': unknown name\(s\) \['abc'\]"),
    (["bench", "envs", "--spin-us", "nan"], r"--spin-us=nan us must be finite"),
    (["bench", "envs", "--vector-envs", "-1"], r"--vector-envs='-1': each env count must lie in \[1, 1024\]"),
    (["bench", "envs", "--vector-spin-us", "1e308"], r"--vector-spin-us=1e\+308 us is outside"),
    (["bench", "haptics", "--duration", "1e308"], r"--duration=1e\+308 s is outside \(0, 600\] s"),
    (["bench", "haptics-flood", "--flood-rate", "-1"], r"--flood-rate=-1.0 is outside \[0, 1e\+07\]"),
    (["bench", "haptics-flood", "--pose-hz", "1e308"], r"--pose-hz=1e\+308 Hz is outside"),
])
def test_out_of_range_flags_are_refused_before_the_run(argv, message, capsys):
    """Each was accepted (and ran for hours, overflowed or raised a raw error, or was ignored): now
    exit 2 naming the flag, its bound and the fix."""
    code, err = _run(argv, capsys)
    assert code == 2 and "Traceback" not in err, err
    assert re.search(message, err), err


@pytest.mark.parametrize("argv, message", [
    (["bench", "soak", "--task", "SurgSim/PalpationPress-v0", "--steps", "5", "--seed", "-1"], r"--seed=-1 is outside \[0, "),
    (["bench", "soak", "--task", "SurgSim/PalpationPress-v0", "--steps", "5", "--checkpoint-every", "-1"],
     r"--checkpoint-every=-1 is outside \[1, "),
    (["bench", "soak", "--task", "SurgSim/PalpationPress-v0", "--steps", "5", "--force-bound", "1e308"],
     r"--force-bound=1e\+308 N is outside \(0, 10000\] N"),
    (["bench", "memory", "--duration", "nan"], r"--duration=nan s must be finite"),
    (["bench", "memory", "--nodes", "-1"], r"--nodes=-1 is outside \[8, "),
    (["bench", "memory", "--repeats", "-1"], r"--repeats=-1 is outside \[1, 100\]"),
    (["bench", "layers", "--spacing", "1e308"], r"--spacing=1e\+308 m is outside \[0.001, 0.02\] m"),
    (["bench", "layers", "--depth", "-1"], r"--depth=-1.0 m is outside \(0, 0.015\] m"),
    (["bench", "layers", "--speed", "nan"], r"--speed=nan m/s must be finite"),
    (["bench", "layers", "--block-radius", "1e308"], r"--block-radius=1e\+308 m is outside"),
])
def test_bench_flags_out_of_range_are_refused_before_the_run(argv, message, capsys):
    code, err = _run(argv, capsys)
    assert code == 2 and "Traceback" not in err and re.search(message, err), err
