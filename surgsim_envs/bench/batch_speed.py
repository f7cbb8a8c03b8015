"""``surgsim bench batch``: speed of the batched Warp backend (surgsim_envs/batch, docs/batch.md).

For each world count W: env steps/s of the batched vector env of ``--task`` (Palpation-v0 by
default, or any task with a batched env, e.g. Grasp-v0; random actions, autoreset), physics
world-steps/s of the bare :class:`BatchSimulation` (W x physics steps per second), the wall time
of one world's new episode (``reset(options={"reset_mask": ...})``, the others kept), the share of
each phase of a physics step (rate limiter, MuJoCo Warp step1, contact, tissue, reaction, MuJoCo
Warp step2; timed with the device synchronised after each phase, in a
separate run), and the memory of the batched state per tissue node-world (the backend's arrays,
and with MuJoCo Warp's data). Medians over ``--repeats``; the load average is recorded.
Warp's CPU device runs kernels on one thread: CPU figures are for checking, not for speed.
``--outputs host,device`` measures each world count twice in the same process: the task's
bookkeeping, observations and rewards on the host in numpy (``host``, the default) and on the
device (``device``: the env built with ``device_outputs=True``; Palpation-v0, Grasp-v0 and Slippage-v0).
``--graphs auto`` (the default) replays the physics of each call as a CUDA graph on a GPU
(``batch/step_graph.py``; plain launches on the CPU, where Warp cannot capture); ``off`` measures
plain launches there too; the rows record which ran. The phase shares come from plain launches
(each phase synchronises the device).
Writes batch_speed.json, batch_speed.md (the table) and batch_speed.png (the chart) to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

from surgsim_envs.errors import ConfigError

PHASES = ("rate_limit", "mujoco_warp.step1", "contact", "tissue", "reaction", "mujoco_warp.step2")
MAX_WORLDS = 1 << 20
OUTPUTS = ("host", "device")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", default="cpu", help="Warp device: cpu (default) or cuda")
    parser.add_argument("--task", default="SurgSim/Palpation-v0",
                        help="a task with a batched env (default SurgSim/Palpation-v0; also SurgSim/Grasp-v0)")
    parser.add_argument("--worlds", default="1,256,4096", help="comma-separated world counts (default 1,256,4096)")
    parser.add_argument("--steps", type=int, default=3, help="env steps per timed run (default 3)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per figure; medians reported (default 3)")
    parser.add_argument("--outputs", default="host",
                        help="where the task's observations and rewards are computed: host (numpy, default), "
                             "device (device_outputs=True; Palpation-v0, Grasp-v0, Slippage-v0), or host,device for both")
    parser.add_argument("--graphs", default="auto", choices=("auto", "on", "off"),
                        help="CUDA graphs of the physics calls: auto (on a GPU; default), on, off")
    parser.add_argument("--json", action="store_true", help="print the results as JSON instead of the table")
    parser.add_argument("--out", default="surgsim-out/bench_batch", help="output directory")


def parse_worlds(text: str) -> list[int]:
    """World counts from "1,256,4096" (ConfigError naming the bad entry)."""
    out = []
    for part in str(text).split(","):
        try:
            w = int(part)
        except ValueError:
            raise ConfigError(f"--worlds: {part!r} is not an integer; give world counts like 1,256,4096") from None
        if not 1 <= w <= MAX_WORLDS:
            raise ConfigError(f"--worlds: {w} must lie in [1, {MAX_WORLDS}]")
        out.append(w)
    return out


def parse_outputs(text: str) -> list[str]:
    """Output modes from "host,device" (ConfigError naming the bad entry)."""
    out = []
    for part in str(text).split(","):
        if part not in OUTPUTS:
            raise ConfigError(f"--outputs: {part!r} is not one of {list(OUTPUTS)}; give e.g. host,device")
        if part not in out:
            out.append(part)
    return out


def _data_bytes(data) -> int:
    """Bytes of every Warp array in MuJoCo Warp's Data."""
    import warp as wp

    total = 0
    for name in dir(data):
        if name.startswith("__"):
            continue
        value = getattr(data, name, None)
        if isinstance(value, wp.array):
            total += value.capacity
    return total


def batched_task(task: str) -> str:
    """``task`` checked against the tasks with a batched env ("module:Class" of that env; ConfigError
    naming them otherwise)."""
    from surgsim_envs.envs import BATCHED

    if task not in BATCHED:
        raise ConfigError(f"--task {task!r} has no batched env; choose one of {sorted(BATCHED)}")
    return BATCHED[task]


def measure(device: str, worlds: int, steps: int, repeats: int, task: str = "SurgSim/Palpation-v0",
            outputs: str = "host", graphs: str = "auto") -> dict:
    """The figures of one world count (module docstring); ``outputs``: "host" or "device"
    (the env's ``device_outputs``); ``graphs``: the batch's CUDA graph mode (the row records
    whether the physics was replayed as graphs)."""
    import warp as wp
    from gymnasium.envs.registration import load_env_creator

    env = load_env_creator(batched_task(task))(worlds, device=device, device_outputs=outputs == "device",
                                               graphs=graphs)
    sim = env.sim
    rng = np.random.default_rng(0)
    shape = (worlds,) + env.single_action_space.shape
    env.reset(seed=0)
    env.step(rng.uniform(-1, 1, shape).astype(np.float32))      # compile / warm
    env_rates, phys_rates = [], []
    for _ in range(repeats):
        acts = [rng.uniform(-1, 1, shape).astype(np.float32) for _ in range(steps)]
        wp.synchronize_device(sim.device)
        t0 = time.perf_counter()
        for a in acts:
            env.step(a)
        wp.synchronize_device(sim.device)
        env_rates.append(steps * worlds / (time.perf_counter() - t0))
        n = steps * env.substeps
        t0 = time.perf_counter()
        sim.step(n)
        wp.synchronize_device(sim.device)
        phys_rates.append(n * worlds / (time.perf_counter() - t0))
    one = np.zeros(worlds, dtype=bool)
    one[min(3, worlds - 1)] = True
    reset_s = []
    for _ in range(max(repeats, 5)):              # one world's new episode (reset_mask), the others kept
        wp.synchronize_device(sim.device)
        t0 = time.perf_counter()
        env.reset(options={"reset_mask": one})
        wp.synchronize_device(sim.device)
        reset_s.append(time.perf_counter() - t0)
    sim.profile(True)
    sim.step(steps * env.substeps)
    phases = dict(sim.phase_seconds)
    sim.profile(False)
    total = sum(phases.values())
    mem = sim.memory_bytes()
    node_worlds = worlds * sim.topology.n_nodes
    backend = sum(mem.values())
    with_mjw = backend + _data_bytes(sim.tools.data)
    out = {"task": task, "worlds": worlds, "outputs": outputs, "graphs": bool(sim.graphs.enabled),
           "graph_failure": sim.graphs.failure, "nodes": sim.topology.n_nodes, "springs": sim.topology.n_springs,
           "tets": sim.topology.n_tets, "substeps": env.substeps,
           "env_steps_per_s": statistics.median(env_rates), "physics_world_steps_per_s": statistics.median(phys_rates),
           "physics_node_steps_per_s": statistics.median(phys_rates) * sim.topology.n_nodes,
           "reset_one_world_ms": 1e3 * statistics.median(reset_s),
           "phase_share": {p: phases.get(p, 0.0) / total for p in PHASES},
           "bytes_per_node_world": backend / node_worlds, "bytes_per_node_world_with_mujoco_warp": with_mjw / node_worlds,
           "memory_bytes": mem, "env_rates": env_rates, "physics_rates": phys_rates}
    env.close()
    return out


def _table(rows: list[dict], device: str) -> str:
    head = ("| worlds | outputs | graphs | env steps/s | physics world-steps/s | node-steps/s | one-world reset | "
            "B per node-world (with MJW) | " + " | ".join(PHASES) + " |")
    lines = [head, "|" + "---|" * (8 + len(PHASES))]
    for r in rows:
        shares = " | ".join(f"{100 * r['phase_share'][p]:.0f} %" for p in PHASES)
        lines.append(f"| {r['worlds']} | {r.get('outputs', 'host')} | {'yes' if r.get('graphs') else 'no'} | "
                     f"{r['env_steps_per_s']:,.0f} | "
                     f"{r['physics_world_steps_per_s']:,.0f} | "
                     f"{r['physics_node_steps_per_s']:.3g} | {r.get('reset_one_world_ms', float('nan')):.2f} ms | "
                     f"{r['bytes_per_node_world']:.0f} "
                     f"({r['bytes_per_node_world_with_mujoco_warp']:.0f}) | {shares} |")
    return "\n".join(lines)


def _chart(rows: list[dict], path: str, device: str, task: str = "SurgSim/Palpation-v0") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = list(dict.fromkeys(r.get("outputs", "host") for r in rows))
    by_mode = {m: [r for r in rows if r.get("outputs", "host") == m] for m in modes}
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for mode, mine in by_mode.items():
        a1.loglog([r["worlds"] for r in mine], [r["env_steps_per_s"] for r in mine], "o-",
                  label=f"{task.split('/')[-1]} env steps/s ({mode} outputs)")
    rows = by_mode[modes[0]]            # the physics and its phases: the same in every mode, shown once
    w = [r["worlds"] for r in rows]
    a1.loglog(w, [r["physics_world_steps_per_s"] for r in rows], "s-", label="physics world-steps/s")
    a1.set_xlabel("worlds")
    a1.set_ylabel("per second")
    a1.set_title(f"batched backend on Warp device '{device}'")
    a1.legend()
    bottom = np.zeros(len(rows))
    for p in PHASES:
        share = np.array([r["phase_share"][p] for r in rows])
        a2.bar([str(x) for x in w], share, bottom=bottom, label=p)
        bottom += share
    a2.set_xlabel("worlds")
    a2.set_ylabel("share of a physics step")
    a2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from surgsim_envs import validate
    from surgsim_envs.batch.backend import device_name

    worlds = parse_worlds(args.worlds)
    validate.integer(args.steps, "--steps", lo=1, hi=100_000, fix="env steps per timed run, e.g. 3")
    validate.integer(args.repeats, "--repeats", lo=1, hi=1000, fix="e.g. 3")
    outputs = parse_outputs(args.outputs)
    device = device_name(args.device)
    env_class = batched_task(args.task)
    if "device" in outputs:
        from gymnasium.envs.registration import load_env_creator

        if not getattr(load_env_creator(env_class), "DEVICE_OUTPUTS", False):
            raise ConfigError(f"--outputs device: {args.task}'s batched env computes its observations and rewards on "
                              "the host; only SurgSim/Palpation-v0, SurgSim/Grasp-v0 and SurgSim/Slippage-v0 have device "
                              "outputs. Use --outputs host")
    load_before = os.getloadavg()
    rows = []
    for w in worlds:
        for mode in outputs:
            print(f"bench batch: {args.task}, {w} worlds on {device}, {mode} outputs ...", file=sys.stderr)
            rows.append(measure(device, w, args.steps, args.repeats, args.task, mode, args.graphs))
    load = os.getloadavg()
    result = {"task": args.task, "device": device, "load_average": load, "load_average_before": load_before,
              "steps": args.steps, "repeats": args.repeats, "rows": rows,
              "note": "Warp's CPU device runs each kernel on one thread" if device == "cpu" else ""}
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "batch_speed.json"), "w") as fh:
        json.dump(result, fh, indent=1)
    table = _table(rows, device)
    with open(os.path.join(args.out, "batch_speed.md"), "w") as fh:
        fh.write(f"{args.task}: device {device}, load average {load_before[0]:.2f} before, {load[0]:.2f} after; "
                 f"medians over {args.repeats} runs of {args.steps} env steps\n\n"
                 + table + "\n")
    _chart(rows, os.path.join(args.out, "batch_speed.png"), device, args.task)
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        print(table)
        print(f"device {device} (Warp CPU kernels are single-threaded), load average {load_before[0]:.2f} before, "
              f"{load[0]:.2f} after; "
              f"wrote {args.out}/batch_speed.{{json,md,png}}")
    return 0
