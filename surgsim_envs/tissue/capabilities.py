"""Capabilities a tissue model declares, so scenes, tasks and benchmarks query them instead of
branching on a model's name (tissue contract v2, docs/models.md).

Every :class:`~surgsim_envs.tissue.base.TissueModel` subclass sets
``capabilities: ClassVar[frozenset[str]]``, a subset of :data:`CAPABILITIES`; a consumer that
needs one calls ``model.require(name, task="...")`` (or :func:`require` on the class), which raises
:class:`CapabilityError` naming the model, the missing capability and the task.
"""

from __future__ import annotations

from typing import Iterable

from surgsim_envs.errors import ConfigError

#: name -> meaning (the table in docs/models.md)
CAPABILITIES: dict[str, str] = {
    "forces": "step(dt, forces) takes external nodal forces (N,3) in N and moves the nodes",
    "implicit_contact": "step(dt, forces, stiffness) integrates the contact stiffness (N,) N/m implicitly; "
                        "integrated_external_forces (N,3) N is the external force actually integrated",
    "plane_contact_law": "step(dt, forces, law) solves the contact's plane law (contact_law.plane.PlaneContactLaw: "
                         "per contact pair a unilateral penalty and Coulomb friction on its tangent plane) with "
                         "the step instead of linearising it (ContactModel.set_contact_law('plane'))",
    "quasi_static": "no inertia: each step returns an equilibrium; velocities are finite differences",
    "surface_only": "only a surface mesh (the volume may have no tets); masses live on surface nodes",
    "history": "internal state depends on the strain history (memory buffer); reset() clears it",
    "viscoelastic": "honours the material's relax_fraction / relax_time",
    "static_solve": "static_solve(forces) returns equilibrium positions",
    "condensed_compliance": "linear and static: compliance_block(nodes) gives the compliance (3m,3m) m/N of free "
                            "nodes and their unloaded displacement (3m,) m; apply_nodal_forces(nodes, forces) sets "
                            "the equilibrium under forces (m,3) N on those nodes alone; compliance_block(nodes, axis=a) and "
                            "apply_axial_forces(nodes, forces (m,), a) do the same for loads along one axis",
    "unstructured_mesh": "runs on any tet mesh (snapped organ lattices, user meshes), not only on regular "
                         "tensor-product grids",
    "subsurface_stiffness": "the interior carries load: a stiffer region below the surface (an inclusion in the "
                            "Young's modulus field) stiffens the surface above it, and the surface dents under a "
                            "pressing tool instead of letting it sink through",
}


class CapabilityError(ConfigError):
    """A model lacks a capability a task, scene or benchmark needs (the message names all three)."""


def check_names(names: Iterable[str], owner: str) -> frozenset[str]:
    """``names`` as a frozenset, each a known capability (ConfigError listing the valid ones)."""
    out = frozenset(names)
    unknown = sorted(out - set(CAPABILITIES))
    if unknown:
        raise ConfigError(f"{owner}: unknown capability name(s) {unknown}; valid capabilities: {sorted(CAPABILITIES)}")
    return out


def require(model_cls, capability: str, task: str = "this task") -> None:
    """Raise :class:`CapabilityError` unless ``model_cls`` (a TissueModel class or instance)
    declares ``capability``."""
    if capability not in CAPABILITIES:
        raise ConfigError(f"unknown capability {capability!r}; valid capabilities: {sorted(CAPABILITIES)}")
    caps = getattr(model_cls, "capabilities", frozenset())
    if capability not in caps:
        name = getattr(model_cls, "name", type(model_cls).__name__)
        raise CapabilityError(f"tissue model '{name}' cannot serve {task}: it lacks the capability "
                              f"{capability!r} ({CAPABILITIES[capability]}); it declares {sorted(caps)}")
