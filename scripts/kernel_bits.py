"""Fingerprints of the tissue models' numba kernels: a hash of the positions and the elastic energy
after 200 steps of each model and integrator (explicit and implicit ``fem`` on one and two threads,
``mass_spring``, ``mass_spring_calibrated``, ``fractional``) on a small slab with a fixed load.

A change to a kernel that should not change its arithmetic (a faster compile, a refactor) must
leave every line the same. Run before and after and compare::

    python scripts/kernel_bits.py > before.txt
    ... edit ...
    python scripts/kernel_bits.py > after.txt && diff before.txt after.txt

With an empty ``NUMBA_CACHE_DIR`` it also times the kernels' cold compile (the wall time of the run).
"""
import hashlib

import numpy as np

from surgsim_envs.geometry.box import box_volume
from surgsim_envs.tissue.registry import make

CASES = [("fem", {"integrator": "symplectic"}), ("fem", {"integrator": "symplectic", "threads": 2}),
         ("fem", {"integrator": "implicit"}), ("fem", {"integrator": "implicit", "threads": 2}),
         ("mass_spring", {"integrator": "implicit"}), ("mass_spring", {"integrator": "symplectic"}),
         ("mass_spring_calibrated", {}), ("mass_spring_calibrated", {"integrator": "symplectic"}),
         ("fractional", {})]


def fingerprint(name: str, options: dict) -> tuple[str, str]:
    """(hash of the positions after 200 steps of 0.5 ms, repr of the elastic energy J)."""
    model = make(name, box_volume(size=(0.04, 0.04, 0.02), spacing=0.005), "liver", **options)
    top = int(np.argmax(model.rest_positions[:, 2]))
    forces = np.zeros_like(model.positions)
    forces[:, 2] = -0.0005
    forces[top, 0] = 0.01
    for _ in range(200):
        model.step(5e-4, forces)
    return hashlib.sha1(model.positions.tobytes()).hexdigest()[:16], repr(model.elastic_energy())


if __name__ == "__main__":
    for name, options in CASES:
        print(name, options, *fingerprint(name, options), flush=True)
