"""The ``surgsim`` command (``python -m surgsim_envs.cli``).

Each sub-command lives in its own module exposing ``add_arguments(parser)`` and
``run(args) -> int``: the modules that only parse arguments and print are in this package
(``models``, ``material``, ``run``, ``grow``, ``validate``, ``bench_soak``); the benchmarks and
the commands whose module also holds domain code stay in their packages. This file only wires
them up, importing a module when its command runs (so ``surgsim models`` never pays for MuJoCo
or numba start-up).
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: command -> (module, help). "bench X" are sub-commands of "bench".
COMMANDS: dict[str, tuple[str, str]] = {
    "models": ("surgsim_envs.cli.models", "list registered tissue models"),
    "choose": ("surgsim_envs.cli.choose", "the cheapest model and spacing within a task's force tolerance (task-accuracy table)"),
    "demo": ("surgsim_envs.scene.demo", "palpate and grasp on built-in defaults; writes ./surgsim-out/"),
    "warmup": ("surgsim_envs.warmup", "compile the physics kernels ahead (numba caches) for the demo and every task"),
    "material": ("surgsim_envs.cli.material", "virtual material tests (indent, relax, slip)"),
    "fit": ("surgsim_envs.bench.fit", "fit model parameters to measured force data"),
    "teleop": ("surgsim_envs.haptics.teleop", "teleoperate a task with a (simulated) haptic device"),
    "run": ("surgsim_envs.cli.run", "run a trainee scenario file and write a report"),
    "record": ("surgsim_envs.integrations.minari_datasets", "record demonstrations of a task as a Minari dataset"),
    "grow": ("surgsim_envs.cli.grow", "tissue growth after a bone displacement (Vandewalle et al. 2003): basic vs growth"),
    "validate": ("surgsim_envs.cli.validate", "signed surface distances of a prediction to a reference (Vandewalle et al. 2003)"),
}
BENCH: dict[str, tuple[str, str]] = {
    "speed": ("surgsim_envs.bench.speed", "tissue model step time per model, integrator, node count"),
    "loop": ("surgsim_envs.bench.loop", "full physics step (MuJoCo + contact + tissue) vs MuJoCo flex"),
    "envs": ("surgsim_envs.bench.envs_speed", "Gymnasium env steps per second"),
    "sb3-vec": ("surgsim_envs.bench.sb3_vec", "stable-baselines3 DummyVecEnv vs SubprocVecEnv(n) env steps per second"),
    "haptics": ("surgsim_envs.bench.haptics_speed", "haptic servo loop period"),
    "haptics-flood": ("surgsim_envs.bench.haptics_flood", "haptic servo period while its UDP port is flooded"),
    "accuracy": ("surgsim_envs.bench.accuracy", "speed against accuracy chart (Pareto front)"),
    "calibrated-cost": ("surgsim_envs.bench.calibrated_cost",
                        "calibrated vs plain mass-spring: critical dt, step cost per simulated ms"),
    "stability": ("surgsim_envs.bench.stability", "largest stable dt map"),
    "task-accuracy": ("surgsim_envs.bench.task_accuracy",
                      "probe forces in each task's own scene, every model against converged fem"),
    "soak": ("surgsim_envs.cli.bench_soak", "long random-action runs: NaN, exceptions, force bounds, memory growth"),
    "diffusion": ("surgsim_envs.bench.diffusion_bench", "diffusion model (Zhong et al. 2016) update time vs the paper's Table 9.1"),
    "growth": ("surgsim_envs.bench.growth_speed", "tissue growth iteration time (Vandewalle et al. 2003) on a ~10,000-node mesh"),
    "memory": ("surgsim_envs.bench.fractional_memory", "fractional model: error and step cost against short memory L"),
    "trajectory": ("surgsim_envs.bench.trajectory_check",
                   "record seeded task trajectories, or compare two records bit for bit"),
    "layers": ("surgsim_envs.bench.layers", "layered model (Lin et al. 2008) at haptic rate: step time, active nodes, force vs all-node"),
    "batch": ("surgsim_envs.bench.batch_speed", "batched Warp backend: env and physics steps/s, memory, phase shares"),
    "cuda-build": ("surgsim_envs.bench.cuda_build",
                   "build the batched backend's kernels for CUDA GPUs here (no GPU needed): registers, spills, occupancy"),
}


def _attach(sub, name: str, module: str, help_text: str) -> None:
    parser = sub.add_parser(name, help=help_text, description=help_text)
    parser.set_defaults(cli_module=module, cli_command=name)
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        if exc.name and module.startswith(exc.name) or (exc.name or "").startswith("surgsim_envs"):
            parser.set_defaults(cli_missing=f"'{name}' is not available in this build ({exc})")
            return
        raise
    mod.add_arguments(parser)


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="surgsim", description="surgsim_envs: soft-tissue surgical training environments")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    # Only import the module of the command being run (fast --help for the others).
    wanted = argv[0] if argv else None
    wanted_bench = argv[1] if len(argv) > 1 and wanted == "bench" else None
    for name, (module, help_text) in COMMANDS.items():
        if name == wanted:
            _attach(sub, name, module, help_text)
        else:
            sub.add_parser(name, help=help_text)
    bench = sub.add_parser("bench", help="benchmarks (timings are medians over repeated runs)")
    bsub = bench.add_subparsers(dest="bench_command", metavar="BENCH")
    for name, (module, help_text) in BENCH.items():
        if name == wanted_bench:
            _attach(bsub, name, module, help_text)
        else:
            bsub.add_parser(name, help=help_text)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "cli_module", None):
        parser.print_help()
        return 0 if not argv else 2
    if getattr(args, "cli_missing", None):
        print(f"surgsim: {args.cli_missing}", file=sys.stderr)
        return 2
    module = importlib.import_module(args.cli_module)
    from surgsim_envs.errors import SurgSimError

    try:
        return int(module.run(args) or 0)
    except SurgSimError as exc:
        print(f"surgsim {args.cli_command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:   # a path the command reads or writes: name it instead of a traceback
        where = f" {exc.filename!r}" if getattr(exc, "filename", None) else ""
        print(f"surgsim {args.cli_command}: error: cannot use{where}: {exc.strerror or exc}; give a path to an "
              "existing file to read, or a writable folder to write to (--out)", file=sys.stderr)
        return 2
