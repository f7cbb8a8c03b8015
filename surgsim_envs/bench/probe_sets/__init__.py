"""Probe sets of tasks whose scenes are not driven like Palpation-v0's, one module per task.

Each module names its ``TASK`` and has ``FULL`` and ``QUICK`` (:class:`~surgsim_envs.bench.probe_set.ProbeSet`),
``measure(task, model, spacing, probes) -> row`` (a row of :func:`surgsim_envs.bench.task_accuracy.measure`'s
form, or a refusal; a refusal marked ``spacing_specific``, such as an instability at one lattice, does
not stop the model's other spacings) and ``reference_row(task, probes, fine) -> row`` (the reference at fine spacing
``fine``); a module whose readings are not presses (closures, pulls) also has ``compare(row,
reference, probes) -> row`` scoring them. Registering a task's probe set is one line in :data:`DRIVERS`; ``surgsim bench
task-accuracy`` reads its force tolerance from the task registry (``TaskSpec.force_tolerance``).
"""

from __future__ import annotations

from surgsim_envs.bench.probe_sets import grasp_closure, layered_palpation, slippage_pull

#: task id -> the module driving its probe set
DRIVERS = {layered_palpation.TASK: layered_palpation, grasp_closure.TASK: grasp_closure,
           slippage_pull.TASK: slippage_pull}

__all__ = ["DRIVERS"]
