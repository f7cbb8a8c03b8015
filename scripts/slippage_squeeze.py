"""What sets Slippage-v0's squeeze in its reference: the settle alone (close to the probe set's closure,
hold), per lattice spacing, friction and contact sampling.

For each spacing it prints the three jaws' normal forces at the end of the hold (N), their sum, and
where the contact points sit across each jaw's face: the largest |y| / half width of a point in
contact (1 = the jaw's long edge). Uses the reference's own scene
(:func:`surgsim_envs.bench.grasp_reference.reference_simulation`: fem_static, elastic, 1e8 N/m^3 per
area) and the probe set's settle (:mod:`surgsim_envs.bench.probe_sets.slippage_pull`).

    python scripts/slippage_squeeze.py --mu 0.6 --samples 1 --spacings 0.011,0.00778,0.0055,0.00389,0.00275

``--samples n`` puts n - 1 contact samples on every surface edge (1: the nodes only); ``--jaw-edges
round`` rounds the jaws' edges in the tissue contact (``GrasperConfig.jaw_edges``).
"""

from __future__ import annotations

import argparse
import copy
import json

import mujoco
import numpy as np

from surgsim_envs.bench import grasp_reference as ref
from surgsim_envs.bench.probe_sets import slippage_pull as sp
from surgsim_envs.envs.slippage.terms import control_schedule
from surgsim_envs.envs.terms.action import jaw_closure
from surgsim_envs.scene import Simulation, build_scene


def settle(env, spacing: float, mu: float, samples: int, jaw_edges: str = "sharp") -> Simulation:
    c, g, name = env.config, env.gcfg, env.tool_name
    sim = ref.reference_simulation(env, spacing)
    if samples > 1 or jaw_edges != "sharp":
        cfg = copy.deepcopy(sim.scene.config)
        if samples > 1:
            cfg.contact.surface_samples = samples
        for tool in cfg.tools:
            if hasattr(tool, "jaw_edges"):
                tool.jaw_edges = jaw_edges
        sim = Simulation(build_scene(cfg), dt=sim.dt, substeps=sim.substeps, tissue_subcycles=sim.tissue_subcycles)
    jaw_act, pull_act = sp.motorise(sim, sim.tool(name), float(c.max_pull), float(c.pull_damping))
    n = sim.tissue_subcycles
    dt = sim.dt * n
    goal = jaw_closure(float(c.initial_closure), g.open_radius, g.min_radius)
    sim.reset(seed=0)
    ref.set_friction(sim, mu, c.static_friction_ratio)
    values = np.zeros((-(-int(round(sp.HOLD / sim.dt)) // n), 2))
    control_schedule(values, float(sim.data.ctrl[jaw_act]), goal, float(c.closing_speed) * dt, float(sim.data.time),
                     dt, False, 0.0, 0.0, 0.0, 0.0, 0.0, float(c.max_pull))
    sim.step_with_controls([jaw_act, pull_act], values)
    return sim


def edge_reach(sim, env) -> list[float]:
    """Per jaw: the largest |y| / half width of a contact point inside its box (1 = a long edge)."""
    g = env.gcfg
    half = np.array([g.jaw_thickness, g.jaw_width, g.jaw_length]) / 2.0
    m, d = sim.model, sim.data
    jaws = [i for i in range(m.ngeom) if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_BOX
            and np.allclose(m.geom_size[i], half)]
    contact = list(sim.contacts.values())[0]
    x = sim.tissue().positions
    points = x[contact.candidate_nodes]
    if contact.n_samples:
        points = np.concatenate([points, contact.sample_positions(x)])
    touching = points[contact.points_in_contact.any(axis=1)]
    out = []
    for j in jaws:
        q = (touching - d.geom_xpos[j]) @ d.geom_xmat[j].reshape(3, 3)
        inside = np.all(np.abs(q) <= m.geom_size[j] + 1e-4, axis=1)
        out.append(round(float(np.max(np.abs(q[inside, 1])) / m.geom_size[j][1]), 2) if inside.any() else 0.0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mu", type=float, default=0.6, help="tool friction (default 0.6)")
    parser.add_argument("--samples", type=int, default=1, help="edge subdivisions of the contact samples (1 = nodes)")
    parser.add_argument("--spacings", default="0.011,0.00778,0.0055,0.00389,0.00275", help="lattice spacings, m")
    parser.add_argument("--jaw-edges", default="sharp", choices=("sharp", "round"),
                        help="the jaws' edges in the tissue contact: sharp boxes (the task's) or rounded to half the "
                             "jaw thickness")
    args = parser.parse_args()
    env = sp.make_env(ref.REFERENCE_MODEL, None, sp.CLOSURE)
    try:
        for h in (float(s) for s in args.spacings.split(",")):
            sim = settle(env, h, args.mu, args.samples, args.jaw_edges)
            fn = sim.jaw_forces(env.tool_name)["normal"]
            print(json.dumps({"mu": args.mu, "samples": args.samples, "jaw_edges": args.jaw_edges, "spacing_mm": round(h * 1e3, 3),
                              "nodes": int(len(sim.tissue().positions)), "jaw_normals_N": [round(float(v), 4) for v in fn],
                              "sum_N": round(float(np.sum(fn)), 4), "edge_reach": edge_reach(sim, env)}), flush=True)
    finally:
        env.close()


if __name__ == "__main__":
    main()
