"""Tool-tissue contact: signed distances of tool shapes, penalty normal force, Coulomb friction
with a stick state, and per-tool reports (numpy + numba; no MuJoCo import).

>>> import numpy as np
>>> from surgsim_envs.contact import ContactModel, ContactParams, SPHERE
>>> cm = ContactModel(n_nodes=1, candidate_nodes=[0], tool_friction=[0.5], params=ContactParams(stiffness=100.0))
>>> res = cm.compute(np.zeros((1, 3)), np.zeros((1, 3)), [SPHERE], [0], [[0.01, 0, 0]], [[0, 0, 0.009]],
...                  [np.eye(3).ravel()], np.zeros((1, 6)), np.zeros((1, 3)), 1e-3)
>>> round(float(res.forces[0, 2]), 6)   # k_n * depth = 100 N/m * 1 mm, pushing the node out (-z)
-0.1

See docs/contact.md for the contact law and its parameters.
"""

from surgsim_envs.contact.friction import stick_slip
from surgsim_envs.contact.model import (AUTO_STIFFNESS_RATIO, ContactModel, ContactParams, ContactResult,
                                        auto_stiffness)
from surgsim_envs.contact.report import ContactReport
from surgsim_envs.contact.shapes import (BOX, CAPSULE, CYLINDER, ROUNDED_BOX, SHAPE_NAMES, SPHERE, check_shape,
                                         signed_distance)
from surgsim_envs.contact.surface_points import subdivisions_for_spacing, surface_samples

__all__ = ["SPHERE", "CAPSULE", "BOX", "CYLINDER", "ROUNDED_BOX", "SHAPE_NAMES", "signed_distance", "check_shape",
           "ContactParams", "ContactModel", "ContactResult", "ContactReport", "auto_stiffness",
           "AUTO_STIFFNESS_RATIO", "stick_slip", "surface_samples", "subdivisions_for_spacing"]
