"""Per-tool contact summary (what observations, haptics and scoring read)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ContactReport:
    """Per-tool contact summary; every array has shape (T,).

    normal_force: N, sum of the normal force magnitudes of the tool's contacts.
    tangential_force: N, magnitude of the summed tangential (friction) force vector.
    contacts: number of tissue nodes touching the tool (a node touching two geoms of one tool counts once).
    slipping: number of those nodes sliding (tangential force at the Coulomb cap mu * f_n) on some geom.
    penetration: m, largest penetration depth of any node into the tool's geoms (0 without contact).

    The arrays are owned by the :class:`~surgsim_envs.contact.ContactModel` and overwritten by its
    next ``compute`` call; copy them (or use :meth:`as_dict`) to keep a snapshot.
    """

    normal_force: np.ndarray
    tangential_force: np.ndarray
    contacts: np.ndarray
    slipping: np.ndarray
    penetration: np.ndarray

    @classmethod
    def zeros(cls, n_tools: int) -> "ContactReport":
        return cls(np.zeros(n_tools), np.zeros(n_tools), np.zeros(n_tools, dtype=np.int64),
                   np.zeros(n_tools, dtype=np.int64), np.zeros(n_tools))

    @property
    def n_tools(self) -> int:
        return len(self.normal_force)

    def as_dict(self) -> dict:
        """Plain-Python snapshot {field: list per tool} (safe to keep, JSON-serialisable)."""
        return {
            "normal_force": [float(v) for v in self.normal_force],
            "tangential_force": [float(v) for v in self.tangential_force],
            "contacts": [int(v) for v in self.contacts],
            "slipping": [int(v) for v in self.slipping],
            "penetration": [float(v) for v in self.penetration],
        }
