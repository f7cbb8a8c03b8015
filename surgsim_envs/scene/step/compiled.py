"""Compiled physics substeps: a registry of numba loops that run a whole control step (every
physics substep of it) in one call, MuJoCo's ``mj_step1``/``mj_step2`` included.

Each substep is the documented order (:mod:`surgsim_envs.scene.simulation`): controls ->
``mj_step1`` -> gather tool geoms -> contact -> tissue integration -> fixed nodes -> the guard's
checks -> reaction wrench into ``xfrc_applied`` -> ``mj_step2``. The generic loop does that with a
few Python calls per substep; a registered loop does it without returning to Python, except when
a check fails (then Python repeats the check on the same state, so the error raised is the same
error with the same message) and, for integrator "auto", when the model's ``critical_dt()`` is
due again (every ``AUTO_RECHECK_STEPS`` steps, evaluated in Python as ``TissueModel._auto_choice``
does; the per-step choice with the contact stiffness is made in the loop).

Registration is keyed by (contact model class, tissue model class, integrator) with exact
classes: a subclass, another integrator, another guard class, several tissues, or a scene
without tools keep the generic loop. The physics is the same operations in the same order, so
results are bit-for-bit those of the generic loop (tests/test_compiled_substeps.py). Built in:
``MassSpringModel`` and ``CalibratedMassSpringModel`` with "symplectic" and "auto"
(:mod:`surgsim_envs.scene.step.loop`: one loop, the model step through a function pointer).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from surgsim_envs.tissue.guard import StabilityGuard

#: statuses a compiled loop returns with the substep index it stopped at
DONE, CONTACT_ERROR, NON_FINITE_INPUT, GUARD_FAILED, AUTO_RECHECK = 0, 1, 2, 3, 4

_REGISTRY: dict[tuple[type, type, str], Callable] = {}


def register_compiled_substeps(contact_cls: type, tissue_cls: type, integrator: str, factory: Callable) -> None:
    """Offer ``factory(sim, tissue, contact, step_functions) -> runner`` for scenes whose only
    tissue is exactly ``tissue_cls`` stepping with ``integrator`` against exactly ``contact_cls``.
    The runner has ``run(count, ctrl_ids, ctrl_values)`` (see
    :class:`surgsim_envs.scene.step.loop.SubstepsRunner`)."""
    _REGISTRY[(contact_cls, tissue_cls, str(integrator))] = factory


def registered() -> list[tuple[str, str, str]]:
    """(contact class, tissue class, integrator) names of the registered compiled loops."""
    _register_builtin()
    return [(c.__name__, t.__name__, i) for (c, t, i) in _REGISTRY]


def key_of(sim) -> tuple | None:
    """The registry key of ``sim``'s scene, or None if no compiled loop can apply (not exactly one
    tissue, no tool geoms, a guard that is not exactly :class:`StabilityGuard`)."""
    if len(sim._pairs) != 1 or not sim._has_tools:
        return None
    tissue, contact = sim._pairs[0]
    if type(tissue.guard) is not StabilityGuard:
        return None
    return (type(contact), type(tissue), str(tissue.integrator))


def compiled_substeps_for(sim):
    """A runner of the compiled loop registered for ``sim``'s scene, or None (generic loop)."""
    _register_builtin()
    key = key_of(sim)
    factory = _REGISTRY.get(key) if key is not None else None
    if factory is None:
        return None
    from surgsim_envs.scene.step.mujoco_native import step_functions

    try:
        fns = step_functions()
    except OSError:
        return None
    tissue, contact = sim._pairs[0]
    runner = factory(sim, tissue, contact, fns)
    runner.key = key
    return runner


NO_IDS = np.zeros(0, dtype=np.int64)
NO_VALUES = np.zeros((0, 0))


_BUILTIN_LOADED = False


def _register_builtin() -> None:
    """Import the built-in registrations on first use (not at import time: they import this module)."""
    global _BUILTIN_LOADED
    if not _BUILTIN_LOADED:
        _BUILTIN_LOADED = True
        from surgsim_envs.scene import substeps_calibrated, substeps_mass_spring  # noqa: F401  (register themselves)
