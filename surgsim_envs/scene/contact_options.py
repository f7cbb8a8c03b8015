"""Per-tissue contact options of a scene: static friction ratio, implicit damping and the contact
stiffness per unit surface area.

``ContactConfig.static_friction_ratio`` (mu_s / mu >= 1) gives every tool a static friction
coefficient above its kinetic one (:mod:`surgsim_envs.contact.friction`).
``ContactConfig.implicit_damping`` ("auto", True, False) decides per tissue whether the contact
damping enters the tissue's solve as the stiffness c_n / dt (``ContactParams.implicit_damping``):
"auto" turns it on for tissue models that declare the capabilities ``quasi_static`` (their
velocities are finite differences of equilibria, and explicit damping c_n / dt above about half a
node's stiffness makes the sequence of equilibria diverge; see docs/models/fem_static.md) and
``implicit_contact`` (their solve takes the reported stiffness, which now carries the damping).
``ContactConfig.stiffness_per_area`` (N/m^3; None, a number or "auto") sets the normal penalty per
node from the tissue's lattice: ``k = stiffness_per_area x h^2``, h the median surface edge (the
surface area a node carries on a lattice), so the penalty's own indentation under a contact
pressure p, ``p / stiffness_per_area``, does not change with the spacing. A per-node penalty
(``ContactConfig.stiffness``, 200 N/m) is the stiffness an explicit step keeps stable, but per unit
area it softens as the lattice coarsens: on a 10 mm lattice a 2.5 kPa contact pressure sinks the
probe 1.25 mm into the surface, on a 5 mm one 0.31 mm, and the force of a press of a few mm
falls with it. "auto" gives :data:`QUASI_STATIC_STIFFNESS_PER_AREA` to tissue models that declare
``quasi_static`` and ``implicit_contact`` (each step is an equilibrium solve that takes the
stiffness: no step limit) and keeps the per-node penalty for the others.
"""

from __future__ import annotations

import dataclasses

import math

from surgsim_envs.contact import ContactParams
from surgsim_envs.contact.model import CONTACT_LAWS
from surgsim_envs.contact.surface_points import typical_edge_length
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


#: N/m^3, the contact stiffness per unit area "auto" gives quasi-static tissue models: a 2.5 kPa contact
#: pressure (0.5 N over the contact of a 7 mm palpation press) penetrates 25 um. It is the value of the
#: task-accuracy reference (surgsim_envs.bench.task_reference), which is converged in it; much stiffer
#: penalties lock flat facets off the sphere (docs/task_accuracy.md)
QUASI_STATIC_STIFFNESS_PER_AREA = 1e8


def _takes_stiff_contact(tissue) -> bool:
    caps = getattr(tissue, "capabilities", ())
    return "quasi_static" in caps and "implicit_contact" in caps


def stiffness_per_area_for(contact_cfg, tissue) -> float | None:
    """The contact stiffness per unit area (N/m^3) ``contact_cfg.stiffness_per_area`` gives ``tissue``:
    None (the per-node ``stiffness`` holds), a positive number, or for "auto"
    :data:`QUASI_STATIC_STIFFNESS_PER_AREA` when the tissue declares ``quasi_static`` and
    ``implicit_contact``, else None."""
    opt = getattr(contact_cfg, "stiffness_per_area", None)
    if opt is None:
        return None
    if isinstance(opt, str):
        if opt != "auto":
            raise ConfigError(f"ContactConfig.stiffness_per_area={opt!r}; use None (the per-node stiffness), "
                              "'auto' or a stiffness per unit area in N/m^3, e.g. 1e8")
        return QUASI_STATIC_STIFFNESS_PER_AREA if _takes_stiff_contact(tissue) else None
    return validate.positive(opt, "ContactConfig.stiffness_per_area", unit="N/m^3", hi=1e13,
                             fix="a contact stiffness per unit area, e.g. 1e8 (a 2.5 kPa pressure then "
                                 "penetrates 25 um), 'auto' or None")


def static_friction_ratio(contact_cfg) -> float:
    """mu_s / mu of a ContactConfig (or a task config with that field), checked (a number >= 1)."""
    r = getattr(contact_cfg, "static_friction_ratio", 1.0)
    return validate.real(r, f"{type(contact_cfg).__name__}.static_friction_ratio", lo=1.0, hi=100.0,
                         fix="a number >= 1 (static friction mu_s as a multiple of the kinetic mu; 1 = one "
                             "coefficient)")


def contact_params_for(params: ContactParams, contact_cfg, tissue) -> ContactParams:
    """``params`` for ``tissue``: ``implicit_damping`` from ``contact_cfg.implicit_damping`` and, where
    ``contact_cfg.stiffness_per_area`` gives one (:func:`stiffness_per_area_for`), the normal
    stiffness per node from it (the tangential one too unless set)."""
    per_area = stiffness_per_area_for(contact_cfg, tissue)
    if per_area is not None:
        h = typical_edge_length(getattr(tissue, "rest_positions", tissue.positions), tissue.surface)
        k = per_area * h * h
        if not (math.isfinite(k) and k > 0.0):
            raise ConfigError(f"ContactConfig.stiffness_per_area={per_area:g} N/m^3 on a surface with median edge "
                              f"{h:g} m gives no finite positive stiffness per node ({k:g} N/m)")
        params = dataclasses.replace(params, stiffness=k)
    opt = getattr(contact_cfg, "implicit_damping", "auto")
    if isinstance(opt, str):
        if opt != "auto":
            raise ConfigError(f"ContactConfig.implicit_damping={opt!r}; use 'auto' (on for quasi-static tissue "
                              "models), True or False")
        caps = getattr(tissue, "capabilities", ())
        on = "quasi_static" in caps and "implicit_contact" in caps   # the solve must take the stiffness
    elif isinstance(opt, bool):
        on = opt
    else:
        raise ConfigError(f"ContactConfig.implicit_damping={opt!r}; use 'auto', True or False")
    return dataclasses.replace(params, implicit_damping=on) if on != params.implicit_damping else params


def contact_law_for(contact_cfg, tissue, n_samples: int) -> str:
    """How ``tissue``'s quasi-static step takes the contact (``ContactModel.set_contact_law``):
    ``contact_cfg.law``, where "auto" gives "plane" to tissue models with the capability
    ``plane_contact_law`` whose contact has no surface samples (``n_samples`` 0), else "linearised".
    An explicit "plane" for a model or contact that cannot take it is refused by name."""
    opt = getattr(contact_cfg, "law", "linearised")
    caps = getattr(tissue, "capabilities", ())
    fits = "plane_contact_law" in caps and n_samples == 0
    if opt == "auto":
        return "plane" if fits else "linearised"
    law = validate.choice(opt, "ContactConfig.law", CONTACT_LAWS + ("auto",),
                          fix="'linearised', 'plane' or 'auto'")
    if law == "plane" and not fits:
        why = (f"its contact has {n_samples} surface samples (set ContactConfig.surface_samples=None)" if n_samples
               else f"tissue model '{getattr(tissue, 'name', type(tissue).__name__)}' lacks the capability "
                    "'plane_contact_law'")
        raise ConfigError(f"ContactConfig.law='plane' cannot apply: {why}; use 'auto' or 'linearised'")
    return law
