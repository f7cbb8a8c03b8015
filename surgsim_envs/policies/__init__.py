"""Trained policies shipped with the package, as numpy ``.npz`` MLPs (no torch needed to run them).

Each file is the ``surgsim-mlp-v1`` format of :mod:`surgsim_envs.policies.npz_policy` (plain
arrays, loaded with ``allow_pickle=False``; numpy only, no torch): exported from
stable-baselines3 by ``scripts/train_sb3.py --export-npz`` (:mod:`surgsim_envs.integrations.sb3`), except
LayeredPalpation-v0's: a scripted raster-and-threshold expert written as an exact network by
``scripts/make_layered_policy.py``. Their training and evaluation are in docs/training.md.

Which file belongs to which task is part of the task's spec (``TaskSpec.policy`` in
:mod:`surgsim_envs.envs.registry`), which also loads them:

>>> from surgsim_envs.envs.registry import load_shipped
>>> policy = load_shipped("SurgSim/PalpationPress-v0")     # doctest: +SKIP
>>> action = policy(obs)                                   # doctest: +SKIP

``surgsim run --policy shipped`` and scenario files (``"policy": "shipped:SurgSim/PalpationPress-v0"``)
use them.
"""

from __future__ import annotations

from pathlib import Path

#: the folder of the shipped policy files
POLICY_DIR = Path(__file__).resolve().parent

__all__ = ["POLICY_DIR"]
