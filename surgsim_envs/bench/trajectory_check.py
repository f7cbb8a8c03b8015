"""``surgsim bench trajectory``: are two trees' trajectories bit for bit the same?

A speed change must not change the physics. ``--record FILE`` steps each task with seeded random
actions (Palpation's report held off for the first 100 steps) and writes every reset's and step's
outputs (observations, rewards, flags, infos) and the final tissue positions (where the task
runs a Simulation) to a pickle;
``--compare A B`` reports, per task, whether two records are identical bit for bit (dtype and
value; NaN equals NaN) and where they first differ. Record once per tree (e.g. main and a
branch, each on ``PYTHONPATH``), then compare. Only load records you wrote: they are pickles.
"""

from __future__ import annotations

import pickle

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

DEFAULT_TASKS = ("SurgSim/Palpation-v0", "SurgSim/Grasp-v0", "SurgSim/Slippage-v0")


def add_arguments(parser) -> None:
    parser.add_argument("--record", metavar="FILE", help="write this tree's trajectories to FILE (a pickle)")
    parser.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two records bit for bit")
    parser.add_argument("--tasks", default=",".join(DEFAULT_TASKS), help="comma-separated task ids or 'all'")
    parser.add_argument("--steps", type=int, default=150, help="random env steps per task (default 150)")


def record(tasks, steps: int) -> dict:
    """Each task's reset and step outputs under seeded random actions, then its tissue positions."""
    import gymnasium as gym
    import numpy as np

    import surgsim_envs  # noqa: F401  (registers the tasks)

    import sys

    from tqdm import tqdm

    out = {}
    for task in tqdm(tasks, desc="bench trajectory", unit="task", file=sys.stderr):
        env = gym.make(task)
        rng = np.random.default_rng(1)
        rec = [env.reset(seed=3)]
        for i in range(steps):
            a = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            if task == "SurgSim/Palpation-v0" and i < 100:
                a[3] = -1.0                      # no report yet: the episode keeps pressing
            r = env.step(a)
            rec.append(r)
            if r[2] or r[3]:
                rec.append(env.reset(seed=i))
        sim = getattr(env.unwrapped, "sim", None)      # a quasi-static task may have no Simulation
        rec.append(sim.tissue().positions.copy() if sim is not None else None)
        out[task] = rec
        env.close()
    return out


def first_difference(x, y, path: str = "") -> str | None:
    """The path of the first entry where ``x`` and ``y`` differ (type, dtype or bits), else None."""
    import numpy as np

    if isinstance(x, dict) or isinstance(y, dict):
        if not (isinstance(x, dict) and isinstance(y, dict)) or set(x) != set(y):
            return f"{path} (keys {sorted(x) if isinstance(x, dict) else type(x).__name__} vs "\
                   f"{sorted(y) if isinstance(y, dict) else type(y).__name__})"
        for k in x:
            d = first_difference(x[k], y[k], f"{path}.{k}")
            if d:
                return d
        return None
    if isinstance(x, (list, tuple)) or isinstance(y, (list, tuple)):
        if type(x) is not type(y) or len(x) != len(y):
            return f"{path} (length or type)"
        for i, (u, v) in enumerate(zip(x, y)):
            d = first_difference(u, v, f"{path}[{i}]")
            if d:
                return d
        return None
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        a, b = np.asarray(x), np.asarray(y)
        same = a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")
    else:
        same = type(x) is type(y) and (x == y or (x != x and y != y))
    return None if same else f"{path}: {x!r} vs {y!r}"


def compare(a: dict, b: dict) -> dict:
    """task -> None (bit for bit identical) or the first difference; tasks in only one record too."""
    out = {}
    for task in sorted(set(a) | set(b)):
        if task not in a or task not in b:
            out[task] = "recorded in one file only"
        else:
            out[task] = first_difference(a[task], b[task], task)
    return out


def _load(path: str) -> dict:
    try:
        with open(path, "rb") as fh:
            data = pickle.load(fh)
    except (OSError, pickle.UnpicklingError, EOFError) as exc:
        raise ConfigError(f"cannot read trajectory record {path!r} ({exc}); write one with "
                          f"'surgsim bench trajectory --record FILE'") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{path!r} is not a trajectory record (a dict of task -> outputs)")
    return data


def run(args) -> int:
    if bool(args.record) == bool(args.compare):
        raise ConfigError("give exactly one of --record FILE or --compare A B")
    if args.compare:
        result = compare(_load(args.compare[0]), _load(args.compare[1]))
        for task, diff in result.items():
            print(f"{task}: " + ("bit for bit identical" if diff is None else f"DIFFERENT, first at {diff}"))
        return 0 if all(d is None for d in result.values()) else 1
    if args.steps <= 0:
        raise ConfigError(f"--steps must be a positive integer, got {args.steps}")
    validate.writable_file(args.record, "--record")
    from surgsim_envs.envs import QUASI_STATIC_TASKS
    from surgsim_envs.envs import TASKS as PHYSICS_RATE_TASKS

    TASKS = {**PHYSICS_RATE_TASKS, **QUASI_STATIC_TASKS}
    tasks = list(TASKS) if args.tasks == "all" else [t.strip() for t in args.tasks.split(",") if t.strip()]
    unknown = [t for t in tasks if t not in TASKS]
    if unknown:
        raise ConfigError(f"unknown task(s) {unknown}; known: {list(TASKS)}")
    with open(args.record, "wb") as fh:
        pickle.dump(record(tasks, args.steps), fh)
    print(f"wrote {args.record}: {len(tasks)} task(s) x {args.steps} steps")
    return 0
