"""One physics step of a quasi-static tissue that meets its tools through a linearised penalty: solved
again from its start, about the positions it reached, while the contact set there differs from the
one it was solved with (:mod:`surgsim_envs.contact.contact_set`: why, and what it measured).

The scene's reference loop calls :func:`quasi_static_step` in place of ``tissue.step_prevalidated``
for models with ``resolves_contact_set``. Each solve after the first restores the model to the
step's start (:meth:`~surgsim_envs.tissue.base.TissueModel.restore_step_state`) with the reached
positions as the linearisation point, and recomputes the contact there, so the contact result, the
force the tissue integrates and the tools' reaction (``attribute_increment``, after this call)
belong to the same, last solve. A step whose contact set holds after its first solve is the
single-pass step, bit for bit. Units: s, m.
"""

from __future__ import annotations

import numpy as np

from surgsim_envs.contact.contact_set import MAX_CONTACT_SET_SOLVES

#: whether each solve after the first computes the contact from the friction state (stick anchors)
#: before the step's first contact call (True), or from the anchors that call left (False, the
#: default). In Palpation-v0's pressed slide at 1 ms steps the drag reads 2.0x (False) and 1.2x
#: (True) its value at 0.25 ms steps, but with True the contact set settles within
#: MAX_CONTACT_SET_SOLVES less often (10x the extra solves): docs/contact.md, "Quasi-static steps";
#: ``python scripts/palpation_slide_dt.py``.
RESTORE_FRICTION = False
#: ``ContactModel.set_friction_cap("solved")``: a step is solved again while a contact pair's
#: integrated normal force (its friction cap) moves by more than this share of the largest
FRICTION_CAP_TOLERANCE = 0.01


def plane_law_step(tissue, contact, dt: float, gpos, gmat, gvel, tcom, friction) -> int:
    """Step ``tissue`` by ``dt`` with ``contact``'s plane law (``contact.set_contact_law("plane")``)
    built from its last compute, at the tissue's positions, and the friction state ``friction`` from
    before that compute; then compute the contact again where the step reached (with the velocities
    the step started from), from ``friction``, so that the stick anchors, the contact states and the
    readings are those of the solved step. The law opens a contact that separates; while a point
    outside the law's pairs touches a tool where the step reached, the step is solved again from its
    start with the law built there (up to ``MAX_CONTACT_SET_SOLVES`` solves). Returns the number of
    extra solves."""
    start = tissue.step_state()
    start_vel = start[1]
    tissue.step_prevalidated(dt, contact.result.forces, contact.plane_law(friction))
    used = contact.points_in_contact
    extra = 0
    while True:
        contact.restore_friction_state(friction)
        contact.compute_prepared(tissue.positions, start_vel, gpos, gmat, gvel, tcom)
        now = contact.points_in_contact
        if extra + 1 >= MAX_CONTACT_SET_SOLVES or not (now & ~used).any():
            break
        tissue.restore_step_state(start, tissue.positions.copy())
        tissue.step_prevalidated(dt, contact.result.forces, contact.plane_law(friction))
        used |= now
        extra += 1
    if extra:
        np.subtract(tissue.positions, start[0], out=tissue.velocities)
        tissue.velocities /= dt
        tissue.velocities[tissue.fixed] = 0.0
    return extra


def quasi_static_step(tissue, contact, dt: float, result, gpos, gmat, gvel, tcom, friction=None) -> int:
    """Step ``tissue`` by ``dt`` under ``result`` (``contact``'s last compute, at the tissue's
    positions) and solve it again while the contact set moves; returns the number of extra solves.
    ``friction``: ``contact.friction_state()`` from before that compute; each solve again computes the
    contact from it (None: from the anchors the last compute left). The velocities are the finite
    difference over the step, from where it started."""
    if contact.solves_plane_law:
        return plane_law_step(tissue, contact, dt, gpos, gmat, gvel, tcom, friction)
    start = tissue.step_state()
    tissue.step_prevalidated(dt, result.forces, result.stiffness)
    extra = 0
    while extra + 1 < MAX_CONTACT_SET_SOLVES:
        capped = (contact.solves_friction_cap
                  and contact.update_pair_normals(tissue.integrated_external_forces) > FRICTION_CAP_TOLERANCE)
        if not capped and not contact.contact_set_changes(tissue.positions, gpos, gmat):
            break
        tissue.restore_step_state(start, tissue.positions.copy())
        if friction is not None:
            contact.restore_friction_state(friction)
        result = contact.compute_prepared(tissue.positions, tissue.velocities, gpos, gmat, gvel, tcom)
        tissue.step_prevalidated(dt, result.forces, result.stiffness)
        extra += 1
    if extra:
        np.subtract(tissue.positions, start[0], out=tissue.velocities)
        tissue.velocities /= dt
        tissue.velocities[tissue.fixed] = 0.0          # held nodes: at rest, as every step leaves them
    return extra


__all__ = ["plane_law_step", "quasi_static_step"]
