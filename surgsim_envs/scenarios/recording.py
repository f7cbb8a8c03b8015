"""What one scenario run records (:class:`Recording`, the force and motion time series) and its
outcome (:class:`RunResult`), for the phase runner and the policy rollout alike."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from surgsim_envs.scenarios.schema import Scenario


class Recording:
    """Time series of one run (arrays after :meth:`finish`). Units: s, N, m.

    t, phase (index into ``phase_names``), normal / tangential (total over the tool, N),
    pull_force (N, against the pull direction), slipping / contacts (node counts),
    penetration (m), position (n, 3) tool origin (m, world), opening (m, grasper jaws; nan else).
    """

    FIELDS = ("t", "phase", "normal", "tangential", "pull_force", "slipping", "contacts", "penetration", "opening")

    def __init__(self):
        self._rows: list[tuple] = []
        self._pos: list[np.ndarray] = []
        self.phase_names: list[str] = []
        self.phase_spans: list[dict] = []

    def add(self, t, phase, normal, tangential, pull, slipping, contacts, penetration, position, opening) -> None:
        self._rows.append((t, phase, normal, tangential, pull, slipping, contacts, penetration, opening))
        self._pos.append(np.asarray(position, dtype=float))

    def finish(self) -> "Recording":
        arr = np.asarray(self._rows, dtype=float).reshape(-1, len(self.FIELDS))
        for i, name in enumerate(self.FIELDS):
            setattr(self, name, arr[:, i].copy())
        self.phase = self.phase.astype(int)
        self.position = np.asarray(self._pos, dtype=float).reshape(-1, 3)
        return self

    def phase_mask(self, phase_type: str) -> np.ndarray:
        """Boolean mask of the samples inside phases of type ``phase_type``."""
        ids = [i for i, span in enumerate(self.phase_spans) if span["type"] == phase_type]
        return np.isin(self.phase, ids)

    def as_dict(self) -> dict:
        out = {name: getattr(self, name).tolist() for name in self.FIELDS}
        out["position"] = self.position.tolist()
        return out


@dataclass
class RunResult:
    """One run's outcome. ``values``: the sweep values of this run ({} without a sweep)."""

    scenario: Scenario
    values: dict
    recording: Recording
    completed: bool
    error: str | None
    metrics: dict
    score: float
    criteria: list
    violations: list
    wall_time: float
    info: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.criteria)
