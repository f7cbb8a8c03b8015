"""How a task sets up its tissue through the tissue contract (never by model name): the integrator it
asks for, whether the explicit one stays stable over the stiffness randomisation, and the mask of
an inclusion."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from surgsim_envs.envs.checks import integrator_names_of
from surgsim_envs.geometry.sphere_fraction import mixed_young_factors, sphere_volume_fractions


def sphere_mask(centroids: np.ndarray, centre, radius: float) -> np.ndarray:
    """(T,) bool: elements whose rest centroid (``model.element_centroids()``, (T,3) m) lies within
    ``radius`` m of ``centre`` (3,) m; at least the nearest one."""
    d = np.linalg.norm(np.asarray(centroids) - np.asarray(centre, dtype=float)[None], axis=1)
    mask = d < radius
    if not mask.any():
        mask[np.argmin(d)] = True
    return mask


def inclusion_young_factors(tissue, centre, radius: float, contrast: float, scale: float = 1.0) -> np.ndarray:
    """(T,) Young's modulus factors (for ``tissue.scale_material("young", ...)``) of a sphere
    (``centre`` (3,) m, ``radius`` m) ``contrast`` x stiffer than the rest of ``tissue``, the whole
    scaled by ``scale``: each element mixes the two by the fraction of its volume inside the sphere
    (:mod:`surgsim_envs.geometry.sphere_fraction`), so the inclusion keeps its volume on any lattice.
    A sphere too small for the sampling to see puts its whole volume into the nearest element."""
    vertices = tissue.element_vertices()
    frac = sphere_volume_fractions(vertices, centre, radius)
    if not frac.any():
        d = np.linalg.norm(vertices.mean(axis=1) - np.asarray(centre, dtype=float)[None], axis=1)
        i = int(np.argmin(d))
        share = 1.0
        if vertices.shape[1] == 4:
            e = vertices[i, 1:] - vertices[i, 0]
            share = min(1.0, (4.0 / 3.0) * math.pi * float(radius) ** 3 / (abs(np.linalg.det(e)) / 6.0))
        frac[i] = share
    return mixed_young_factors(frac, contrast, scale)


def tissue_options(model: str, integrator: str) -> dict[str, Any]:
    """Constructor options of a task's tissue: ``integrator`` if model ``model`` has it, else its
    "auto" choice (explicit when stable, implicit otherwise), else the model's default."""
    from surgsim_envs.tissue.registry import get as model_class

    names = integrator_names_of(model_class(model))
    if integrator in names:
        return {"integrator": integrator}
    return {"integrator": "auto"} if "auto" in names else {}


def explicit_stable_over(tissue, dt: float, max_scale: float) -> bool:
    """True if tissue ``tissue`` (built, unscaled) steps explicitly at ``dt`` s with every element's
    Young's modulus scaled by up to ``max_scale``: ``dt <= stable_dt()`` with the whole tissue at
    ``max_scale`` (a bound for any local scaling up to it: the stiffest node limits the step). The
    material is restored (``scale_material`` is relative to the build) before returning."""
    tissue.scale_material("young", float(max_scale))
    try:
        return float(dt) <= tissue.stable_dt()
    finally:
        tissue.scale_material("young", 1.0)


def integrator_for_range(tissue, dt: float, max_scale: float) -> str | None:
    """The integrator a task must rebuild its tissue with, or None to keep the one built.

    A task asks for "symplectic" by default (the explicit one: fast and, for the mass-spring tasks,
    stable). If the built tissue steps with its explicit integrator (the first of the model's
    ``auto_pair``) but ``dt`` exceeds its :meth:`stable_dt` somewhere in the stiffness
    randomisation (Young's modulus scaled up to ``max_scale``), the task takes the model's "auto"
    instead (explicit while stable at the current state, else implicit). A model without an
    explicit/implicit pair keeps what it has, and the per-episode :func:`check_explicit_step` names
    the problem. Decided from capability (``auto_pair``, ``stable_dt()``), never from a model name."""
    pair = getattr(tissue, "auto_pair", None)
    if pair is None or getattr(tissue, "integrator", None) != pair[0]:
        return None
    return None if explicit_stable_over(tissue, dt, max_scale) else "auto"

