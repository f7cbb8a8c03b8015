"""scripts/train_batched.py: its --help works and, without torch, it exits 0 with a message saying so
(torch is not a test dependency; where it is importable its absence is simulated)."""

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "train_batched.py"


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, str(SCRIPT), *args], capture_output=True, text=True,
                          timeout=120, cwd=SCRIPT.parents[1])


RUN = "import runpy, sys; sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')"
NO_TORCH = "import sys; sys.modules['torch'] = None; " + RUN      # a None entry makes `import torch` raise ImportError


def test_help_lists_the_options():
    out = _run(RUN, "--help")
    assert out.returncode == 0, out.stderr
    for flag in ("--device", "--worlds", "--iterations", "--seed", "--out"):
        assert flag in out.stdout


def test_without_torch_it_exits_0_and_says_why(tmp_path):
    out = _run(NO_TORCH, "--device", "cpu", "--worlds", "2", "--iterations", "1", "--out", str(tmp_path / "run"))
    assert out.returncode == 0, out.stderr
    assert "torch is not installed" in out.stdout
    assert not (tmp_path / "run").exists(), "nothing is trained or written without torch"


def test_a_bad_count_is_refused_with_its_bound():
    out = _run(NO_TORCH, "--worlds", "0")
    assert out.returncode == 2
    assert "--worlds=0 must be >= 1" in out.stderr


def test_device_and_host_outputs_train_the_same_curve_with_torch(tmp_path):
    """With torch (not a test dependency: skipped without it) and the [batch] extra, the PPO taking the env's
    outputs as Warp arrays without copies (--outputs device) sees the same numbers as through numpy (host):
    the same curve, episode ends included (0.5 s episodes end inside the 60-step rollouts)."""
    import importlib.util

    import pytest

    if importlib.util.find_spec("torch") is None:
        pytest.skip("torch is not installed (not a test dependency)")
    from surgsim_envs.batch.backend import available

    if not available():
        pytest.skip("the [batch] extra (warp-lang, mujoco-warp) is not installed")
    curves = {}
    for outputs in ("host", "device"):
        out = _run(RUN, "--device", "cpu", "--worlds", "4", "--iterations", "2", "--rollout-steps", "60",
                   "--episode-seconds", "0.5", "--seed", "0", "--outputs", outputs, "--out", str(tmp_path / outputs))
        assert out.returncode == 0, out.stderr
        rows = (tmp_path / outputs / "curve.csv").read_text().splitlines()
        curves[outputs] = [",".join(v for k, v in enumerate(r.split(",")) if k != 2) for r in rows]   # drop seconds
    assert curves["device"] == curves["host"]
    assert int(curves["device"][1].split(",")[3]) == 4, "every world ended an episode in the first rollout"
