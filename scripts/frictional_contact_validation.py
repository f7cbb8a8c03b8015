"""The suite's penalty contact with Coulomb friction against the analytic references
(surgsim_envs.bench.contact_references) on a quasi-static FEM slab (surgsim_envs.bench.frictional_press).

press: normal force of a straight press, frictionless / mu / (nearly) full stick, against Hertz,
    Dimitriadis (bonded layer) and the no-slip factor kappa(nu);
slide: the tangential force Q against the sphere's displacement at constant depth, against
    Cattaneo-Mindlin (with the measured P and Hertz contact radius) and mu P.

python scripts/frictional_contact_validation.py press --spacing 0.001 --poisson 0.45
python scripts/frictional_contact_validation.py sweep --poisson 0.45
python scripts/frictional_contact_validation.py punch --radius 0.005 --depth 0.00005 --spacing 0.0015
python scripts/frictional_contact_validation.py slide --radius 0.04 --depth 5e-5 --thickness 0.014 --spacing 4.7e-4 \
    --slide 1e-4 --slide-steps 100 --steps 5 --penalty 2
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from surgsim_envs.bench import contact_references as cr
from surgsim_envs.bench.frictional_press import frictional_press
from surgsim_envs.bench.references import dimitriadis_force, hertz_force


def press(a):
    mat = {"preset": "liver", "relax_fraction": 0.0, "poisson": a.poisson}
    rows = {}
    for mu in (0.0, 0.5, 5.0):
        t = time.perf_counter()
        r = frictional_press(mat, mu=mu, radius=a.radius, depth=a.depth, thickness=a.thickness, spacing=a.spacing,
                             press_steps=a.steps, iterations=a.iterations, penalty_ratio=a.penalty)
        rows[mu] = r
        print(f"mu {mu}: P {r.normal[-1]:.6f} N, nodes {r.info['nodes']}, penetration {r.penetration[-1] * 1e6:.1f} um,"
              f" sliding {r.sliding_fraction[-1]:.2f}, {time.perf_counter() - t:.0f} s", flush=True)
    d = a.depth
    e = rows[0.0].info["young"]
    out = {"spacing": a.spacing, "poisson": a.poisson, "depth": d, "radius": a.radius, "thickness": a.thickness,
           "hertz": float(hertz_force(d, a.radius, e, a.poisson)),
           "dimitriadis": float(dimitriadis_force(d, a.radius, e, a.poisson, a.thickness)),
           "kappa": cr.no_slip_stiffness_factor(a.poisson),
           "P": {str(mu): float(r.normal[-1]) for mu, r in rows.items()},
           "ratio_mu0.5": float(rows[0.5].normal[-1] / rows[0.0].normal[-1]),
           "ratio_mu5": float(rows[5.0].normal[-1] / rows[0.0].normal[-1])}
    print(json.dumps(out, indent=1))


def sweep(a):
    """Friction's raise of the press force against a / R, on meshes scaled with the contact radius a
    (spacing a / 2.5, thickness 10 a): full stick (mu 5) over frictionless."""
    mat = {"preset": "liver", "relax_fraction": 0.0, "poisson": a.poisson}
    kappa = cr.no_slip_stiffness_factor(a.poisson)
    print(f"kappa(nu={a.poisson}) = {kappa:.5f}")
    print("d/R     a/R    P0 N       P_stick N  ratio    ratio - kappa")
    for d in (0.0025, 0.01, 0.04, 0.1):
        depth = d * a.radius
        ca = (a.radius * depth) ** 0.5
        p = [frictional_press(mat, mu=mu, radius=a.radius, depth=depth, thickness=10 * ca, spacing=ca / 2.5,
                              press_steps=a.steps, iterations=a.iterations, penalty_ratio=a.penalty).normal[-1]
             for mu in (0.0, 5.0)]
        ratio = p[1] / p[0]
        print(f"{d:.4f} {ca / a.radius:.4f} {p[0]:.4e} {p[1]:.4e} {ratio:.5f} {ratio - kappa:+.5f}", flush=True)


def punch(a):
    """A flat-ended punch (radius a = ``--radius``) pressed ``--depth``: full stick (mu 5) over
    frictionless against Mossakovskii's kappa(nu), the frictionless force against Sneddon's 2 E* a d."""
    print("nu    kappa    P0/(2E*ad)  P_stick/P0  diff")
    for nu in (0.0, 0.3, 0.45):
        mat = {"preset": "liver", "relax_fraction": 0.0, "poisson": nu}
        p = [frictional_press(mat, mu=mu, radius=a.radius, depth=a.depth, thickness=10 * a.radius,
                              spacing=a.spacing, press_steps=a.steps, iterations=a.iterations,
                              penalty_ratio=a.penalty, tool="punch").normal[-1] for mu in (0.0, 5.0)]
        kappa = cr.no_slip_stiffness_factor(nu)
        sneddon = 2 * 4000.0 / (1 - nu * nu) * a.radius * a.depth
        print(f"{nu:.2f} {kappa:.5f} {p[0] / sneddon:.4f} {p[1] / p[0]:.5f} {p[1] / p[0] - kappa:+.5f}", flush=True)


def slide(a):
    mat = {"preset": "liver", "relax_fraction": 0.0, "poisson": a.poisson}
    t = time.perf_counter()
    r = frictional_press(mat, mu=a.mu, radius=a.radius, depth=a.depth, thickness=a.thickness, spacing=a.spacing,
                         slide=a.slide, press_steps=a.steps, slide_steps=a.slide_steps, iterations=a.iterations,
                         penalty_ratio=a.penalty)
    n = a.steps
    p = r.normal[n:]
    e, nu = r.info["young"], a.poisson
    p0 = float(r.normal[n - 1])
    radius_c = float(cr.hertz_contact_radius(p0, a.radius, e, nu))
    ds = cr.mindlin_slip_displacement(a.mu, p0, radius_c, e, nu)
    ref = cr.cattaneo_mindlin_force(r.x[n:], a.mu, p0, radius_c, e, nu)
    print(f"nodes {r.info['nodes']}, P after press {p0:.6f} N, Hertz a {radius_c * 1e3:.3f} mm, "
          f"delta_s {ds * 1e6:.1f} um, {time.perf_counter() - t:.0f} s")
    print(" x um   P N      Q N      Q/(mu P)  CM Q/(mu P0)  sliding")
    for x, pp, q, qr, s in zip(r.x[n:], p, r.tangential[n:], ref, r.sliding_fraction[n:]):
        print(f"{x * 1e6:6.1f} {pp:.6f} {q:.6f} {q / (a.mu * pp):8.4f} {qr / (a.mu * p0):8.4f}  {s:.2f}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("case", choices=("press", "slide", "sweep", "punch"))
    ap.add_argument("--spacing", type=float, default=0.001)
    ap.add_argument("--poisson", type=float, default=0.45)
    ap.add_argument("--radius", type=float, default=0.01)
    ap.add_argument("--depth", type=float, default=0.001)
    ap.add_argument("--thickness", type=float, default=0.03)
    ap.add_argument("--mu", type=float, default=0.5)
    ap.add_argument("--slide", type=float, default=0.0006)
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument("--slide-steps", type=int, default=12)
    ap.add_argument("--iterations", type=int, default=200)
    ap.add_argument("--penalty", type=float, default=10.0)
    a = ap.parse_args()
    {"press": press, "slide": slide, "sweep": sweep, "punch": punch}[a.case](a)
