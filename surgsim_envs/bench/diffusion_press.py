"""The paper-000 experiments on the round-cornered cube (Figs. 9.2-9.6), without MuJoCo.

A compressive force (3 kg = 29.4 N in the paper) is spread evenly over the surface nodes within
``radius`` of a contact point on the cube and pushes along the inward normal there. The four
material cases of section 9.6.1 are built by :func:`paper_case`; :func:`press` returns the
equilibrium (``static_solve``) or the state after stepping. Used by tests, figures and benchmarks.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.rounded_cube import rounded_cube_volume

#: the paper's load: 3 kg weight (N)
PAPER_FORCE = 3.0 * 9.81
#: contact point on the +x face (the equator about z, so latitude = y and longitude = z there)
CONTACT = np.array([0.05, 0.0, 0.0])
DIRECTION = np.array([-1.0, 0.0, 0.0])
#: material of the figures: stiffer than liver so that 3 kg dents a 10 cm cube by about 10 %
FIGURE_MATERIAL = {"preset": "liver", "young": 30_000.0, "damping": 20.0}
#: very low omega of the "local deformation" case (Fig. 9.5)
LOW_OMEGA = 1e-6
CASES = ("isotropic", "anisotropic", "inhomogeneous", "local")


def white_portions(nodes: np.ndarray, half_width: float = 0.02) -> np.ndarray:
    """(N,) bool, the "white portions" of Figs. 9.4-9.5: two bands |y| > half_width (m) on either
    side of the contact; the contact lies in the grey band between them."""
    return np.abs(nodes[:, 1]) > half_width


def paper_case(case: str, points: int = 900, material=None, **options):
    """The diffusion model of one of the paper's cases on a ~``points`` round-cornered cube:
    "isotropic" (omega 0.08, Fig. 9.2), "anisotropic" (0.08 latitudinal, 0.24 longitudinal about
    z, Fig. 9.3), "inhomogeneous" (0.08 white, 0.24 grey, Fig. 9.4), "local" (LOW_OMEGA white,
    0.08 grey, Fig. 9.5)."""
    from surgsim_envs import tissue

    if case not in CASES:
        raise ConfigError(f"unknown paper case {case!r}; choose one of {CASES}")
    vol = rounded_cube_volume(points=points)
    mat = FIGURE_MATERIAL if material is None else material
    white = white_portions(vol.nodes)
    if case == "isotropic":
        opts = {"omega": 0.08}
    elif case == "anisotropic":
        opts = {"omega": 0.08, "omega_long": 0.24}
    elif case == "inhomogeneous":
        opts = {"omega": np.where(white, 0.08, 0.24)}
    else:
        opts = {"omega": np.where(white, LOW_OMEGA, 0.08)}
    opts.update(options)
    return tissue.make("diffusion", vol, mat, **opts)


def contact_forces(model, force: float = PAPER_FORCE, contact=CONTACT, direction=DIRECTION,
                   radius: float = 0.012) -> np.ndarray:
    """(N,3) N: ``force`` along ``direction`` shared by the nodes within ``radius`` of ``contact``."""
    p = model.rest_positions
    sel = np.flatnonzero(np.linalg.norm(p - np.asarray(contact, dtype=float), axis=1) < radius)
    if len(sel) == 0:
        raise ConfigError(f"no node within {radius} m of the contact point {list(contact)}; raise radius")
    f = np.zeros_like(p)
    d = np.asarray(direction, dtype=float)
    f[sel] = d / np.linalg.norm(d) * (force / len(sel))
    return f


def press(model, force: float = PAPER_FORCE, *, steps: int = 0, dt: float = 1e-3, **where) -> np.ndarray:
    """(N,3) m displacements under the press: the equilibrium (``steps=0``) or after ``steps``
    explicit steps of ``dt`` from the current state (the model is advanced)."""
    f = contact_forces(model, force, **where)
    if steps <= 0:
        return model.static_solve(f) - model.rest_positions
    for _ in range(int(steps)):
        model.step(dt, f)
    return model.positions - model.rest_positions


def node_near(model, point) -> int:
    """Index of the rest node closest to ``point`` (m)."""
    return int(np.argmin(np.linalg.norm(model.rest_positions - np.asarray(point, dtype=float), axis=1)))


def load_curve(model, forces) -> np.ndarray:
    """(K,) m equilibrium indentation of the contact node under each force (N) of ``forces`` (Fig. 9.6)."""
    i = node_near(model, CONTACT)
    return np.array([float(-press(model, f)[i] @ DIRECTION * -1.0) for f in forces])
