"""Pinning vs unilateral probe contact on LayeredPalpation-v0's wall (the figures in
docs/models/layered.md, "Probe contact").

For each probe: 60 press pairs at the same site with two random presses between (fraction of
pairs differing by > 5 %, worst difference, number of 0 N reads), the largest pull of a contact
node on the probe (N, > 0 = tensile), and a depth sweep 0.5-8 mm from deep to shallow at three
sites (number of sites where the force falls with depth). Usage:
``python scripts/layered_contact_check.py``."""

from __future__ import annotations

import numpy as np

from surgsim_envs.contact.kinematic_probe import KinematicProbe
from surgsim_envs.contact.unilateral_probe import UnilateralProbe
from surgsim_envs.envs.layered_palpation import LayeredPalpationConfig
from surgsim_envs.geometry.anatomy import abdominal_wall_volume
from surgsim_envs.tissue import make


def run(kind: str, seed: int = 5) -> dict:
    cfg = LayeredPalpationConfig()
    vol = abdominal_wall_volume(cfg.spacing, size=cfg.size)
    model = make("layered", vol, fixed=vol.face_nodes(4))
    top = np.flatnonzero(vol.neighbours[:, 5] < 0)
    z_top = float(vol.nodes[top, 2].max())
    probe = (UnilateralProbe if kind == "unilateral" else KinematicProbe)(model, top, cfg.probe_radius)
    pull = 0.0

    def press(a):
        nonlocal pull
        x, y = a[0] * 0.5 * cfg.size[0], a[1] * 0.5 * cfg.size[1]
        c = (x, y, z_top + cfg.probe_radius - (a[2] + 1) / 2 * cfg.max_depth)
        if kind == "unilateral":
            probe.press(c, model.static_solve, warm=True)
        else:
            probe.move_to(c)
            model.static_solve()
        if len(probe.nodes):
            pull = max(pull, float(-model.internal_forces()[probe.nodes, 2].min()))
        return float(probe.force()[2])

    rng = np.random.default_rng(seed)
    diffs, zeros = [], 0
    for _ in range(60):
        a = rng.uniform(-1, 1, 3)
        f1 = press(a)
        for _ in range(2):
            press(rng.uniform(-1, 1, 3))
        f2 = press(a)
        zeros += (f1 == 0) + (f2 == 0)
        diffs.append(abs(f1 - f2) / max(f1, f2) if max(f1, f2) > 0 else 0.0)
    falls = 0
    for x, y in ((0.0013, 0.0007), (-0.012, 0.009), (0.021, -0.004)):
        f = [press((x / 0.04, y / 0.03, d / cfg.max_depth * 2 - 1)) for d in np.arange(0.008, 0.00049, -0.0005)]
        falls += bool(np.any(np.diff(f[::-1]) < 0))
    diffs = np.asarray(diffs)
    return {"probe": kind, "pairs_over_5pct": float((diffs > 0.05).mean()), "worst_pair_difference": float(diffs.max()),
            "zero_reads": int(zeros), "largest_node_pull_N": pull, "sites_where_force_falls_with_depth": falls}


if __name__ == "__main__":
    for kind in ("pinned", "unilateral"):
        print(run(kind))
