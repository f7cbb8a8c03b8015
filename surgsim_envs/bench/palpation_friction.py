"""How much the tool's friction raises a straight palpation press, in the converged reference and
in a model: Palpation-v0's probe-set presses over its first lump (5x, radius 7 mm, 11 mm deep) and
at the mirror site, to 3, 5 and 7 mm, with the liver's friction (mu 0.5) and without it.

The reference is the task-accuracy reference (:func:`surgsim_envs.bench.task_reference.reference_row`,
graded ``fem_static``, elastic material) run frictionless; its frictional forces are the shipped
task-accuracy table's at the same fine spacings. Shipped as
``surgsim_envs/tissue/data/palpation_friction_reference.json``; regenerate with
``python -m surgsim_envs.bench.palpation_friction --out FILE`` (about 2 minutes, up to 2.5 GB).

The slab is 2 cm thick, bonded to its bed, and nearly incompressible (nu 0.45); a 7 mm press with
the 10 mm tip has a contact radius near the thickness. Friction holds the surface under the tip
from sliding outwards, and a thin bonded near-incompressible layer that cannot spread sideways is
much stiffer: the reference reads 13-50 % more force with mu 0.5 than frictionless (the friction
effect on a half-space is under 1 %, docs/contact.md).

The history of a press (:func:`slide_forces`): the same 5 mm press over the lump reached straight
down and by pressing :data:`SLIDE` m beside it (-x) and sliding in at depth. With friction the
surface under the tip is dragged along and keeps tangential tractions, so the reference reads
about 30 % less after the slide (its fine region widened to cover the slide); frictionless, the
two agree. Units: m, N.
"""

from __future__ import annotations

import argparse
import json
from importlib import resources

TASK = "SurgSim/Palpation-v0"
DATA_FILE = "palpation_friction_reference.json"
#: the fine spacings of the reference's frictionless runs (m): two of the table's levels
FINE = (0.002 / 2 ** 0.5, 0.001)
#: m, the pressed slide of :func:`slide_forces`, and its press depth
SLIDE = 0.008
SLIDE_DEPTH = 0.005


def probe_set():
    """The probe set's first lump with all its depths, no spacings."""
    from surgsim_envs.bench import task_accuracy as ta
    from surgsim_envs.bench.probe_set import ProbeSet

    full = ta.PROBE_SETS[TASK][0]
    return ProbeSet(inclusions=full.inclusions[:1], depths=full.depths, hold=full.hold, spacings=(),
                    reference_spacings=FINE)


def reference() -> dict:
    """``{"frictionless": {fine: {press: N}}, "friction": {fine: {press: N}}, "mu": 0.5, ...}``."""
    return json.loads(resources.files("surgsim_envs.tissue.data").joinpath(DATA_FILE).read_text())


def press_forces(model: str, spacing: float | None, friction: float) -> dict[str, float]:
    """``{press: F_z (N)}`` of :func:`probe_set` in Palpation-v0 with ``model`` at ``spacing`` (m; None:
    the task's lattice), the liver made elastic, tool friction ``friction``."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401
    from surgsim_envs.bench import task_accuracy as ta

    probes = probe_set()
    kwargs = {"model": model, "material": {"preset": "liver", "friction": float(friction), "relax_fraction": 0.0}}
    if spacing is not None:
        kwargs["resolution"] = float(spacing)
    env = gym.make(TASK, disable_env_checker=True, **kwargs).unwrapped
    try:
        return ta.Presser(env, probes.hold).press_all(probes)
    finally:
        env.close()


def slide_forces(env) -> tuple[float, float]:
    """(straight, slid) F_z (N) of the 5 mm press over the first lump in ``env`` (Palpation-v0,
    unwrapped, already built): straight down, then pressed :data:`SLIDE` m to the -x side and slid in."""
    from surgsim_envs.bench import task_accuracy as ta

    probes = probe_set()
    inc = probes.inclusions[0]
    presser = ta.Presser(env, probes.hold)
    straight = presser.press(inc, inc.position, SLIDE_DEPTH)
    slid = presser.press(inc, inc.position, SLIDE_DEPTH, approach=(inc.position[0] - SLIDE, inc.position[1]))
    return straight, slid


def model_slide_forces(model: str, spacing: float | None, friction: float = 0.5) -> tuple[float, float]:
    """:func:`slide_forces` in Palpation-v0 built with ``model`` at ``spacing`` (m; None: the task's),
    the liver elastic with tool friction ``friction``."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401

    kwargs = {"model": model, "material": {"preset": "liver", "friction": float(friction), "relax_fraction": 0.0}}
    if spacing is not None:
        kwargs["resolution"] = float(spacing)
    env = gym.make(TASK, disable_env_checker=True, **kwargs).unwrapped
    try:
        return slide_forces(env)
    finally:
        env.close()


def reference_slide_forces(fine: float, friction: float = 0.5) -> tuple[float, float]:
    """:func:`slide_forces` on the reference's lattice graded about the lump's site at ``fine`` m, its
    fine region widened by :data:`SLIDE` in x."""
    from surgsim_envs.bench import task_accuracy as ta
    from surgsim_envs.bench import task_reference as tr

    env = ta.make_task_env(TASK, tr.REFERENCE_MODEL, tr.COARSE_SPACING,
                           material={"preset": "liver", "friction": float(friction), "relax_fraction": 0.0})
    try:
        tr.graded_scene(env, probe_set().inclusions[0].position, fine, SLIDE_DEPTH, widen=(SLIDE, 0.0))
        return slide_forces(env)
    finally:
        env.close()


def main(argv=None) -> int:
    from surgsim_envs.bench import task_accuracy as ta
    from surgsim_envs.bench import task_reference as tr

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="the JSON file to write")
    args = parser.parse_args(argv)
    table = json.loads(resources.files("surgsim_envs.tissue.data").joinpath("task_accuracy_table.json").read_text())
    ref = table["references"][TASK]
    probes = probe_set()
    out = {"task": TASK, "mu": 0.5, "frictionless": {}, "friction": {}, "seconds": {}}
    for fine in FINE:
        row = tr.reference_row(TASK, probes, fine, {"preset": "liver", "friction": 0.0}, ta.make_task_env)
        level = min(range(len(ref["spacings"])), key=lambda i: abs(ref["spacings"][i] - fine))
        out["frictionless"][repr(fine)] = row["forces_N"]
        out["friction"][repr(fine)] = {k: ref["forces_by_spacing"][level][k] for k in row["forces_N"]}
        out["seconds"][repr(fine)] = row["seconds"]
        print(f"{fine * 1e3:.3g} mm: {row['seconds']:.0f} s", flush=True)
    out["slide"] = {}
    for fine in (0.002,) + FINE:
        straight, slid = reference_slide_forces(fine)
        out["slide"][repr(fine)] = {"straight": straight, "slid": slid}
        print(f"slide at {fine * 1e3:.3g} mm: {straight:.4f} -> {slid:.4f} N", flush=True)
    out["finest"] = repr(FINE[-1])
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
