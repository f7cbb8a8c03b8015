"""How a probe sliding while pressed reads against the physics step, in Palpation-v0's default
(``fem_static``, liver friction): pressed 0.6 for 60 control steps from seed 5, then sliding at half
speed in x for 140. For each physics step (``--dts``, s) and each way a re-solved quasi-static step
treats friction (``scene/step/quasi_static.py``, ``RESTORE_FRICTION``: the anchors the step's first
contact call left, or those from before it), prints the normal force at the end of the straight
press, and over the slide: the extra solves, the contact
nodes that flipped out and back in, the mean normal force on the tissue (z) and the mean drag (x),
N, the 99th percentile of the normal force's change from one physics step to the next, and the
median over the slide (after its first 10 control steps) of the probe's tangential reading over mu
times its normal reading (Coulomb's bound on the forces the tissue integrated: at most 1).

    python scripts/palpation_slide_dt.py [--dts 1e-3,5e-4,2.5e-4] [--solves 4] [--friction-cap penalty]
        [--law linearised|plane] [--restore both|after|before]

``--law plane`` solves each step's contact with the step (``ContactModel.set_contact_law``: the
penalty and Coulomb friction on each pair's tangent plane; the friction snapshot is then always taken,
so ``--restore`` does not matter). ``--friction-cap integrated`` caps a sliding contact's friction with the normal force the pair
integrated over the last step instead of the penalty where the step starts, ``solved`` with the
step's own (``ContactModel.set_friction_cap``). A converged contact gives the same forces as the step
shrinks; the spread over ``--dts`` is the time-discretisation error of the task's step (1 ms).
"""

from __future__ import annotations

import argparse
import os

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)
import surgsim_envs.scene.simulation as simulation
import surgsim_envs.scene.step.quasi_static as quasi_static
from surgsim_envs.contact.model import CONTACT_LAWS, FRICTION_CAPS

PRESS, SLIDE = 60, 140


def slide(dt: float, restore: bool, solves: int, cap: str = "penalty", law: str = "linearised") -> dict:
    """One pressed slide at physics step ``dt`` (s); per-physics-step forces after the last solve."""
    sets, fz, fx = [], [], []
    step = quasi_static.quasi_static_step

    def logged(tissue, contact, *args):
        extra = step(tissue, contact, *args)
        sets.append(contact.result.stiffness > 0)
        fz.append(-float(tissue.integrated_external_forces[:, 2].sum()))
        fx.append(-float(tissue.integrated_external_forces[:, 0].sum()))
        return extra

    saved = quasi_static.RESTORE_FRICTION, quasi_static.MAX_CONTACT_SET_SOLVES, simulation.quasi_static_step
    quasi_static.RESTORE_FRICTION, quasi_static.MAX_CONTACT_SET_SOLVES = restore, solves
    simulation.quasi_static_step = logged
    try:
        env = gym.make("SurgSim/Palpation-v0", dt=dt, contact_law=law, disable_env_checker=True).unwrapped
        contact = next(iter(env.sim.contacts.values()))
        contact.set_friction_cap(cap)
        mu = float(np.max(contact.tool_friction))
        env.reset(seed=5)
        coulomb = []
        for i in range(PRESS + SLIDE):
            env.step(np.array([0.0 if i < PRESS else 0.5, 0.0, 0.6, -1.0], dtype=np.float32))
            if i >= PRESS + 10:                  # sliding: the tool's readings of the integrated force
                coulomb.append(float(contact.report.tangential_force[0]) / (mu * float(contact.report.normal_force[0])))
        start = PRESS * env.sim.substeps
        extra = env.sim.contact_set_resolves
        env.close()
    finally:
        quasi_static.RESTORE_FRICTION, quasi_static.MAX_CONTACT_SET_SOLVES, simulation.quasi_static_step = saved
    h, z, x = np.array(sets)[start:], np.array(fz)[start:], np.array(fx)[start:]
    return {"pressed": float(fz[start - 1]), "coulomb": float(np.median(coulomb)), "extra": extra, "flips": int((h[:-2] & ~h[1:-1] & h[2:]).sum()), "normal": float(z.mean()),
            "drag": float(x.mean()), "p99": float(np.percentile(np.abs(np.diff(z)), 99))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dts", default="1e-3,5e-4,2.5e-4", help="comma-separated physics steps, s")
    ap.add_argument("--solves", type=int, default=quasi_static.MAX_CONTACT_SET_SOLVES,
                    help="solves at most per physics step")
    ap.add_argument("--friction-cap", default="penalty", choices=FRICTION_CAPS,
                    help="ContactModel.set_friction_cap: what caps a sliding contact's friction")
    ap.add_argument("--law", default="plane", choices=CONTACT_LAWS,
                    help="ContactModel.set_contact_law: how the quasi-static step takes the contact")
    ap.add_argument("--restore", default="both", choices=("both", "after", "before"),
                    help="which friction state each re-solve starts from (both: one run each)")
    a = ap.parse_args()
    for dt in (float(v) for v in a.dts.split(",")):
        for restore in {"both": (False, True), "after": (False,), "before": (True,)}[a.restore]:
            r = slide(dt, restore, a.solves, a.friction_cap, a.law)
            print(f"dt {dt * 1e3:g} ms  friction from {'before' if restore else 'after '} the first call:  extra solves "
                  f"{r['extra']:5d}  pressed {r['pressed']:.4f} N  flips {r['flips']:3d}  normal {r['normal']:.4f} N  drag {r['drag']:.4f} N  "
                  f"p99 step change {r['p99']:.2e} N  tangential / (mu normal) {r['coulomb']:.2f}", flush=True)
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
