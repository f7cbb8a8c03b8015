"""What solving a quasi-static step again (while its contact set moves) costs in a palpation task, and
how much it removes: two envs of the task with its default model (``fem_static``), one with the
re-solves (the scene's default, up to ``MAX_CONTACT_SET_SOLVES`` solves a step) and one solving each
step once, stepped alternately in one process with the same actions.

    python scripts/quasi_static_resolve_cost.py [--task SurgSim/Palpation-v0] [--repeats 5]

Two loads per repeat: random actions (300 env steps, never reporting) and a pressed slide (pressed
0.6 for 40 control steps, then sliding at half speed in x for 60, seed 5). Prints the median
milliseconds per env step of each, their ratio, the extra solves, and on the slide the contact
nodes flipping out and back in and the 99th percentile of the probe force's step-to-step change
over its mean (after the press). The host's load average is printed with the figures.
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)
import surgsim_envs.scene.simulation as simulation
import surgsim_envs.scene.step.quasi_static as quasi_static

PRESS, SLIDE = 40, 60


def _slide_actions() -> np.ndarray:
    return np.array([[0.0 if i < PRESS else 0.5, 0.0, 0.6, -1.0] for i in range(PRESS + SLIDE)], dtype=np.float32)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", default="SurgSim/Palpation-v0")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    solves = {"re-solved": quasi_static.MAX_CONTACT_SET_SOLVES, "solved once": 1}
    envs = {name: gym.make(args.task, disable_env_checker=True).unwrapped for name in solves}
    if not envs["solved once"].sim.tissue().resolves_contact_set:
        raise SystemExit(f"{args.task}'s default model does not re-solve its steps: nothing to compare")
    random_actions = np.random.default_rng(0).uniform(-1, 1, (300, 4)).astype(np.float32)
    random_actions[:, -1] = -1.0
    slide = _slide_actions()
    cost = {name: {"random": [], "slide": []} for name in solves}
    trace: dict = {}
    step = quasi_static.quasi_static_step

    def logged(tissue, contact, *rest):
        extra = step(tissue, contact, *rest)
        trace.setdefault("sets", []).append(contact.result.stiffness > 0)
        trace.setdefault("fz", []).append(-float(tissue.integrated_external_forces[:, 2].sum()))
        return extra

    chatter = {}
    for rep in range(args.repeats):
        for name, env in envs.items():
            quasi_static.MAX_CONTACT_SET_SOLVES = solves[name]
            for load, actions, seed in (("random", random_actions, rep), ("slide", slide, 5)):
                env.reset(seed=seed)
                logging = load == "slide" and rep == 0
                if logging:
                    trace.clear()
                    simulation.quasi_static_step = logged
                t0 = time.perf_counter()
                for a in actions:
                    env.step(a)
                cost[name][load].append((time.perf_counter() - t0) / len(actions) * 1e3)
                simulation.quasi_static_step = step
                if logging:
                    n = PRESS * env.sim.substeps
                    sets, fz = np.array(trace["sets"])[n:], np.array(trace["fz"])[n:]
                    chatter[name] = (int((sets[:-2] & ~sets[1:-1] & sets[2:]).sum()),
                                     float(np.percentile(np.abs(np.diff(fz)), 99) / fz.mean()), float(fz.mean()))
    quasi_static.MAX_CONTACT_SET_SOLVES = solves["re-solved"]
    print(f"{args.task}, default model, {args.repeats} repeats, load average {os.getloadavg()[0]:.2f}")
    for name, env in envs.items():
        c = cost[name]
        flips, jump, mean = chatter[name]
        print(f"  {name:12s} random actions {np.median(c['random']):6.2f} ms/step, pressed slide "
              f"{np.median(c['slide']):6.2f} ms/step, extra solves {env.sim.contact_set_resolves}; slide: "
              f"{flips} flips, force {mean:.4f} N, p99 step change {100 * jump:.1f} % of it")
    r, o = cost["re-solved"], cost["solved once"]
    print(f"  ratio re-solved / once: random actions {np.median(r['random']) / np.median(o['random']):.2f}, "
          f"pressed slide {np.median(r['slide']) / np.median(o['slide']):.2f}")


if __name__ == "__main__":
    main()
