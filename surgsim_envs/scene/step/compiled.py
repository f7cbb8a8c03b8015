"""Which scenes run their substeps compiled: one numba call per control step
(:func:`surgsim_envs.scene.step.loop.run_substeps`), MuJoCo's ``mj_step1``/``mj_step2`` included.

Each substep is the documented order (:mod:`surgsim_envs.scene.simulation`): controls ->
``mj_step1`` -> gather tool geoms -> contact -> tissue integration -> fixed nodes -> the guard's
checks -> reaction wrench into ``xfrc_applied`` -> ``mj_step2``. The Python reference loop does that
with a few Python calls per substep; the compiled loop does it without returning to Python, except
when a check fails (then Python repeats the check on the same state, so the error raised is the same
error with the same message) and, for integrator "auto", when the model's ``critical_dt()`` is due
again (every ``AUTO_RECHECK_STEPS`` steps, evaluated in Python as ``TissueModel`` does; the per-step
choice with the contact stiffness is made in the loop).

A scene runs compiled when it has tool geoms and exactly one tissue, the contact model is exactly
:class:`~surgsim_envs.contact.ContactModel`, the guard exactly
:class:`~surgsim_envs.tissue.guard.StabilityGuard`, and the tissue's exact class declares a compiled
step for its integrator (``compiled_step_module``, :mod:`surgsim_envs.tissue.compiled`; built in:
``MassSpringModel`` "symplectic" and "auto", ``CalibratedMassSpringModel`` "symplectic", "auto" and
"subcycled"). The physics is the same operations in the same order, so results are bit-for-bit those
of the reference loop (tests/test_compiled_substeps.py, tests/test_compiled_calibrated.py).
"""

from __future__ import annotations

from surgsim_envs.contact import ContactModel
from surgsim_envs.scene.step.loop import SubstepsRunner
from surgsim_envs.scene.step.mujoco_native import step_functions
from surgsim_envs.tissue import registry
from surgsim_envs.tissue.compiled import compiled_step_class, compiled_step_of
from surgsim_envs.tissue.guard import StabilityGuard


def registered() -> list[tuple[str, str, str]]:
    """(contact class, tissue class, integrator) names of the combinations that run compiled."""
    out = []
    for name in registry.names():
        cls = registry.get(name)
        ops = compiled_step_class(cls)
        if ops is not None:
            out += [(ContactModel.__name__, cls.__name__, i) for i in ops.integrators]
    return out


def key_of(sim) -> tuple | None:
    """What decides ``sim``'s loop: (contact class, tissue class, integrator), or None if no compiled
    loop can apply (not exactly one tissue, no tool geoms, a guard that is not exactly
    :class:`StabilityGuard`)."""
    pairs = sim.pairs
    if len(pairs) != 1 or not sim.has_tool_geoms:
        return None
    tissue, contact = pairs[0]
    if type(tissue.guard) is not StabilityGuard:
        return None
    return (type(contact), type(tissue), str(tissue.integrator))


def compiled_substeps_for(sim) -> SubstepsRunner | None:
    """A runner of the compiled loop for ``sim``'s scene, or None (the reference loop)."""
    key = key_of(sim)
    if key is None or key[0] is not ContactModel:
        return None
    tissue, contact = sim.pairs[0]
    ops = compiled_step_of(tissue)
    if ops is None or not ops.applies(tissue, sim.tissue_subcycles):
        return None
    try:
        fns = step_functions()
    except OSError:
        return None
    runner = SubstepsRunner(sim, tissue, contact, fns, ops)
    runner.key = key
    return runner
