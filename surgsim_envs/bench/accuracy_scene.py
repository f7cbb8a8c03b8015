"""The indentation of the speed-against-accuracy chart (``surgsim bench accuracy``) and its error
measure, shared by every contender (our models, MuJoCo flex, PyBullet): a sphere of
:data:`RADIUS` pressed into a bonded slab of :data:`THICKNESS` of :data:`MATERIAL`, compared with
Dimitriadis et al.'s thin-layer force."""

from __future__ import annotations

import numpy as np

from surgsim_envs.bench.references import dimitriadis_valid_depth

RADIUS, THICKNESS, MATERIAL = 0.005, 0.03, "liver"  # liver made elastic (relax_fraction = 0)


def force_error(depth, force, ref_force, valid_depth: float) -> float:
    """Mean relative error of ``force`` against ``ref_force`` at depths in [valid_depth/4, valid_depth]."""
    depth, force, ref_force = map(np.asarray, (depth, force, ref_force))
    sel = (depth >= 0.25 * valid_depth - 1e-12) & (depth <= valid_depth + 1e-12)
    return float(np.mean(np.abs(force[sel] / ref_force[sel] - 1.0)))


def add_self_error(rows: list[dict]) -> None:
    """``self_error`` of every row: its force error against the same model's finest row."""
    dv = dimitriadis_valid_depth(RADIUS, THICKNESS)
    for r in rows:
        finest = min((q for q in rows if q["model"] == r["model"]), key=lambda q: q["spacing"])
        r["self_error"] = force_error(r["depth"], r["force"], finest["force"], dv)
