"""The viscoelastic step against the elastic one: a model with the liver preset (relax_fraction 0.5)
and the same model with relax_fraction 0, stepped alternately in one process.

The body and load are ``surgsim bench speed``'s (a liver box on a 5 mm lattice, bottom clamped,
0.5 N on the top face). Both models run at one dt: 1 ms, or the explicit integrator's stable dt if
smaller (the branches do not change the instantaneous stiffness, so the limit is the same). Each
round times ``steps`` steps of one model then of the other; the figures are medians over the rounds.
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np

from surgsim_envs.bench.material import is_explicit

#: models timed by default (those whose step carries Maxwell / Prony branches)
DEFAULT_MODELS = ("fem", "mass_spring", "mass_spring_calibrated")


def relax_row(cls, integrator: str, target: int, repeats: int, steps: int, warmup: int, dt: float = 1e-3) -> dict:
    """``{"model", "integrator", "nodes", "dt_s", "viscoelastic_us", "elastic_us", "viscoelastic_over_elastic"}``."""
    from surgsim_envs.bench.speed_volume import bench_volume, top_load as _load

    vol = bench_volume(target)
    z = vol.nodes[:, 2]
    bottom, top = np.isclose(z, z.min()), np.isclose(z, z.max())
    models = {"viscoelastic": cls(vol, "liver", integrator=integrator, fixed=bottom),
              "elastic": cls(vol, {"preset": "liver", "relax_fraction": 0.0}, integrator=integrator, fixed=bottom)}
    if is_explicit(cls, integrator):
        limit = models["viscoelastic"].stable_dt()
        if math.isfinite(limit):
            dt = min(dt, limit)
    forces = {k: _load(m, top) for k, m in models.items()}
    for k, m in models.items():
        for _ in range(warmup):
            m.step(dt, forces[k])
    times = {k: [] for k in models}
    for _ in range(repeats):
        for k, m in models.items():
            t0 = time.perf_counter()
            for _ in range(steps):
                m.step(dt, forces[k])
            times[k].append((time.perf_counter() - t0) / steps * 1e6)
    v, e = statistics.median(times["viscoelastic"]), statistics.median(times["elastic"])
    return {"model": cls.name, "integrator": integrator, "nodes": int(vol.n_nodes), "dt_s": dt,
            "viscoelastic_us": round(v, 2), "elastic_us": round(e, 2), "viscoelastic_over_elastic": round(v / e, 3)}


def format_rows(rows: list[dict]) -> str:
    header = f"{'model':<24} {'integrator':<12} {'nodes':>6} {'dt ms':>7} {'visco us':>9} {'elastic us':>10} {'ratio':>6}"
    lines = [header, "-" * len(header)]
    for r in rows:
        lines.append(f"{r['model']:<24} {r['integrator']:<12} {r['nodes']:>6} {r['dt_s'] * 1e3:>7.3g} "
                     f"{r['viscoelastic_us']:>9.1f} {r['elastic_us']:>10.1f} {r['viscoelastic_over_elastic']:>6.2f}")
    return "\n".join(lines)
