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


def quasi_static_step(tissue, contact, dt: float, result, gpos, gmat, gvel, tcom, friction=None) -> int:
    """Step ``tissue`` by ``dt`` under ``result`` (``contact``'s last compute, at the tissue's
    positions) and solve it again while the contact set moves; returns the number of extra solves.
    ``friction``: ``contact.friction_state()`` from before that compute; each solve again computes the
    contact from it (None: from the anchors the last compute left). The velocities are the finite
    difference over the step, from where it started."""
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


__all__ = ["quasi_static_step"]
