"""Measurements behind docs/benchmarks.md, "Env step: fifth pass (issue 18)". Thread CPU time;
run with ``MUJOCO_GL=egl`` and ``PYTHONPATH`` set to the tree to measure.

    python scripts/speed_fifth_pass.py split [TASK ...]      # where a compiled substep goes
    python scripts/speed_fifth_pass.py env-python [TASK ...]  # the env's Python per step, loop stubbed

``split`` writes scratch copies of :mod:`surgsim_envs.scene.substeps_loop` into a temporary directory,
each with one piece of the substep removed (the tissue step call, the contact kernel, ``mj_step1`` /
``mj_step2``, the guard's checks, the copies into ``integrated_external_forces`` and the fixed-node
writes), and times ``Simulation.step()`` of the same env with each of them in turn (round robin, 5
rounds, the first dropped), the probe pressing / the jaws closing so that contact is computed on
every substep. A piece's cost is the full loop's time minus the time without it, per substep
(removing the tissue step also stops the tissue, so the others are taken on a slightly different
state: the figures are a split, not an exact sum).

``env-python`` replaces the compiled loop by a stub that only returns "done" (the reset keeps the
real one) and times ``env.step`` alone: the env's, the wrappers' and the runner's Python per step.
"""

from __future__ import annotations

import importlib
import json
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401
from surgsim_envs.scene import substeps_loop
from surgsim_envs.scene.compiled_substeps import DONE

TASKS = ("SurgSim/Palpation-v0", "SurgSim/Grasp-v0")

#: piece -> (text in substeps_loop.run_substeps, replacement)
PIECES = {
    "tissue_step": [("if _call_step(step_fn, address, rows, dt, 1 if counts[2] == 0 else 0, 1 if implicit else 0):",
                     "if False:")],
    "contact": [("if contact_kernel_prepared(pos, vel, gpos, gmat, gvel, tcom, contact) != 0:", "if False:")],
    "mj_step1_2": [("            call_model_data(step1, m_ptr, d_ptr)\n", ""),
                   ("        call_model_data(step2, m_ptr, d_ptr)\n", "")],
    "guard": [("if not (all_finite(forces) and all_finite(stiffness)):", "if False:"),
              ("                if not speed_within(pos, vel, max_speed2):", "                if False:"),
              ("if counts[0] % check_every == 0:", "if False:")],
    "copies_fixed_nodes": [
        ("                for i in range(forces.shape[0]):\n                    for q in range(3):\n"
         "                        integrated[i, q] = forces[i, q]\n", ""),
        ("                for q in range(fixed_idx.shape[0]):\n                    i = fixed_idx[q]\n"
         "                    for c in range(3):\n                        pos[i, c] = fixed_targets[i, c]\n"
         "                        vel[i, c] = 0.0\n", "")],
}


def _variants(tmp: Path) -> dict:
    src = Path(substeps_loop.__file__).read_text().replace("cache=True", "cache=False")
    out = {}
    for name, reps in {"full": [], **PIECES}.items():
        s = src
        for a, b in reps:
            if a not in s:
                raise SystemExit(f"piece {name!r}: text not found in substeps_loop.py (the loop changed): {a!r}")
            s = s.replace(a, b)
        (tmp / f"_loop_{name}.py").write_text(s)
        out[name] = importlib.import_module(f"_loop_{name}").run_substeps
    return out


def _pressing_actions(env, n, rng):
    a = rng.uniform(-1, 1, (n, env.action_space.shape[0])).astype(np.float32)
    if "Palpation" in env.spec.id:
        a[:, 2] = 0.4          # pressing (5 mm): contact on every substep
        a[:, 3] = -1.0
    else:
        a[:, 3] = 1.0          # jaws closing
    return a


def split(task: str, steps: int = 100, rounds: int = 5) -> dict:
    with tempfile.TemporaryDirectory() as d:
        sys.path.insert(0, d)
        try:
            loops = _variants(Path(d))
        finally:
            sys.path.remove(d)
        env = gym.make(task)
        env.reset(seed=0)
        acts = _pressing_actions(env, steps + 20, np.random.default_rng(0))
        sim = env.unwrapped.sim
        runner = sim._compiled_runner()
        times = {k: [] for k in loops}
        for _ in range(rounds):
            for name, loop in loops.items():
                runner._loop = loop
                env.reset(seed=1)
                for a in acts[:20]:
                    env.step(a)
                total = 0
                for _ in range(steps):
                    t = time.thread_time_ns()
                    sim.step()
                    total += time.thread_time_ns() - t
                times[name].append(total / steps / 1e3)
        med = {k: float(np.median(v[1:])) for k, v in times.items()}
        n = sim.substeps
        out = {"task": task, "substeps": n, "mujoco_steps": n // sim.tissue_subcycles,
               "nodes": int(sim.tissue().n_nodes), "springs": int(len(sim.tissue().si)),
               "control_step_us": round(med["full"], 1), "per_substep_us": round(med["full"] / n, 2)}
        parts = {k: (med["full"] - med[k]) / n for k in PIECES}
        out.update({f"{k}_us": round(v, 2) for k, v in parts.items()})
        out["rest_us"] = round(med["full"] / n - sum(parts.values()), 2)
        env.close()
        return out


def env_python(task: str, steps: int = 400, rounds: int = 5) -> float:
    env = gym.make(task)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, (steps, env.action_space.shape[0])).astype(np.float32)
    if "Palpation" in task:
        acts[:, 2] = np.clip(acts[:, 2], -1, 0.2) - 0.6
        acts[:, 3] = -1
    for a in acts[:20]:
        env.step(a)
    runner = env.unwrapped.sim._compiled_runner()
    real = runner._loop

    def stub(tab, ci, cv, s1, s2, m, d, k, j, count, resume, dt, n, *rest):
        return DONE, count // n, 0

    res = []
    for r in range(rounds):
        total = 0
        runner._loop = real
        env.reset(seed=r)
        runner._loop = stub
        for a in acts:
            t = time.thread_time_ns()
            _, _, term, trunc, _ = env.step(a)
            total += time.thread_time_ns() - t
            if term or trunc:
                runner._loop = real
                env.reset()
                runner._loop = stub
        res.append(total / steps / 1e3)
    runner._loop = real
    env.close()
    return float(np.median(res))


def main() -> None:
    cmd, args = (sys.argv[1] if len(sys.argv) > 1 else ""), sys.argv[2:]
    if cmd == "split":
        for task in (args or TASKS):
            print(json.dumps(split(task)))
    elif cmd == "env-python":
        print(json.dumps({t: round(env_python(t), 1) for t in (args or (*TASKS, "SurgSim/Slippage-v0"))}))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
