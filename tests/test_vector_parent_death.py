"""A vector env whose main process is SIGKILLed leaves no worker and no shared-memory block
behind (surgsim_envs/vector/parent.py), and its inputs are refused by name."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from surgsim_envs.vector import SurgSimVectorEnv
from surgsim_envs.errors import ConfigError

REPO = Path(__file__).resolve().parents[1]

CHILD = textwrap.dedent("""
    import sys, time
    from surgsim_envs.vector import SurgSimVectorEnv
    ctx = sys.argv[1] if sys.argv[1] != "default" else None
    vec = SurgSimVectorEnv("CartPole-v1", num_envs=2, workers=2, context=ctx)
    vec.reset(seed=0)
    print(vec._shm.name, *[p.pid for p, _, _ in vec._workers.values()], flush=True)
    time.sleep(300)
""")


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split()[2]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and /dev/shm are Linux's")
@pytest.mark.parametrize("context", ["default", "forkserver"])
def test_sigkill_of_the_main_process_leaves_no_worker_and_no_shared_memory(context):
    proc = subprocess.Popen([sys.executable, "-c", CHILD, context], stdout=subprocess.PIPE, text=True, cwd=REPO,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        line = proc.stdout.readline().split()
        assert line, "the child did not start its vector env"
        shm, pids = Path("/dev/shm") / line[0].lstrip("/"), [int(p) for p in line[1:]]
        assert shm.exists() and len(pids) == 2 and all(_alive(p) for p in pids)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 15.0          # the forkserver workers poll once a second
        while time.monotonic() < deadline and (shm.exists() or any(_alive(p) for p in pids)):
            time.sleep(0.1)
        left = [p for p in pids if _alive(p)]
        for p in left:
            os.kill(p, signal.SIGKILL)
        if shm.exists():
            shm.unlink()
        assert not left, f"workers {left} outlived their SIGKILLed parent"
        assert not shm.exists(), f"shared memory {shm} was left behind"
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()


def test_vector_env_refuses_bad_options_and_actions_by_name():
    with pytest.raises(ConfigError, match="info_keys must be None .*got 5 of type int"):
        SurgSimVectorEnv("CartPole-v1", num_envs=2, info_keys=5)
    with pytest.raises(ConfigError, match="context='bogus' is not one of"):
        SurgSimVectorEnv("CartPole-v1", num_envs=2, context="bogus")
    vec = SurgSimVectorEnv("Pendulum-v1", num_envs=2, workers=1)
    try:
        vec.reset(seed=0)
        for bad in (np.array([["a"], ["b"]]), np.array([[1j], [2j]]), np.array([[True], [False]]),
                    [[None], [None]]):
            with pytest.raises(ConfigError, match="actions must be real numbers"):
                vec.step(bad)
        obs, reward, *_ = vec.step(np.zeros((2, 1)))          # still usable after the refusals
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
    finally:
        vec.close()
