"""Trained policies shipped with the package, as numpy ``.npz`` MLPs (no torch needed to run them).

Each file is the ``surgsim-mlp-v1`` format of :mod:`surgsim_envs.policies.npz_policy` (plain
arrays, loaded with ``allow_pickle=False``; numpy only, no torch): exported from
stable-baselines3 by ``scripts/train_sb3.py --export-npz`` (:mod:`surgsim_envs.integrations.sb3`), except
LayeredPalpation-v0's: a scripted raster-and-threshold expert written as an exact network by
``scripts/make_layered_policy.py``. Their training and evaluation are in docs/training.md.

>>> from surgsim_envs.policies import load_shipped
>>> policy = load_shipped("SurgSim/PalpationPress-v0")     # doctest: +SKIP
>>> action = policy(obs)                                   # doctest: +SKIP

``surgsim run --policy shipped`` and scenario files (``"policy": "shipped:SurgSim/PalpationPress-v0"``)
use them.
"""

from __future__ import annotations

from pathlib import Path

from surgsim_envs.errors import ConfigError

POLICY_DIR = Path(__file__).resolve().parent

#: task id -> shipped policy file in this folder
SHIPPED = {
    "SurgSim/PalpationPress-v0": "palpation_press_v0.npz",
    "SurgSim/Grasp-v0": "grasp_v0.npz",
    "SurgSim/Slippage-v0": "slippage_v0.npz",
    "SurgSim/Palpation-v0": "palpation_v0.npz",
    "SurgSim/LayeredPalpation-v0": "layered_palpation_v0.npz",
}


def shipped_tasks() -> list[str]:
    """Task ids with a shipped policy whose file is present."""
    return [t for t, f in SHIPPED.items() if (POLICY_DIR / f).is_file()]


def shipped_path(task: str) -> Path:
    """Path of the shipped policy of ``task`` (ConfigError naming the tasks that have one)."""
    if task not in SHIPPED or not (POLICY_DIR / SHIPPED[task]).is_file():
        raise ConfigError(f"no shipped policy for task {task!r}; shipped: {shipped_tasks()}")
    return POLICY_DIR / SHIPPED[task]


def load_shipped(task: str, mode: str | None = None, seed: int | None = 0):
    """The shipped :class:`~surgsim_envs.policies.npz_policy.NpzPolicy` of ``task``, acting in the
    file's recorded ``mode`` (PalpationPress-v0: stochastic) unless ``mode`` is given; ``seed``
    seeds its action sampler (``policy.reset(seed)`` reseeds it per episode)."""
    from surgsim_envs.policies.npz_policy import NpzPolicy

    return NpzPolicy.load(shipped_path(task), mode=mode, seed=seed)


__all__ = ["POLICY_DIR", "SHIPPED", "shipped_tasks", "shipped_path", "load_shipped"]
