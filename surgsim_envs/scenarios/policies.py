"""Built-in policies, and loading policy references under the scenario trust model.

Built-in policies (scenario files name them ``"builtin:NAME"`` or
``"surgsim_envs.scenarios.policies:NAME"``; no stable-baselines3 needed):

* :func:`palpation_scan` (task ``SurgSim/Palpation-v0``, a factory taking ``env``): presses on a
  raster, then reports at the stiffest site.
* :func:`hold_still` (phase scenarios): keeps the tool where it is.


Trained policies shipped with the package (:mod:`surgsim_envs.policies`, .npz data):
``"shipped:SurgSim/PalpationPress-v0"``.

Loading (:func:`load_policy`): built-ins, shipped and ``.npz`` data policies
(:mod:`~surgsim_envs.policies.npz_policy`) always; code (``file.py:function``,
``module:function``, stable-baselines3 ``.zip``) only with ``allow_code`` (``--allow-code``), and
from a scenario file only from ``.py``/``.zip`` files inside the scenario's own folder.
"""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path
from typing import Callable

import numpy as np

from surgsim_envs.errors import ConfigError


def palpation_scan(env, grid: int = 4, settle_steps: int = 12, press: float = 0.6):
    """Factory: a raster palpation policy for SurgSim/Palpation-v0 (action ``[vx, vy, press, report]``).

    Moves over a ``grid`` x ``grid`` raster spanning the inclusion's possible positions, presses
    ``settle_steps`` control steps at each site, records force / depth (N/m) from the observation
    (``obs[5]`` force z, ``obs[6]`` depth), then goes to the stiffness-weighted centroid of the
    stiffest sites and reports."""
    c = env.unwrapped.config
    lim = float(min(max(abs(v) for v in c.inclusion_xy), c.xy_limit))
    xs = np.linspace(-lim, lim, grid)
    sites = [np.array([x, y]) for j, y in enumerate(xs) for x in (xs if j % 2 == 0 else xs[::-1])]
    step = float(c.max_xy_step)
    state = {"i": 0, "n": 0, "k": [], "goal": None}

    def move(pos, goal, pressing):
        d = np.clip((goal - pos[:2]) / step, -1.0, 1.0)
        return np.array([d[0], d[1], press if pressing else -1.0, -1.0], dtype=np.float32)

    def policy(obs):
        pos = np.asarray(obs[:3], dtype=float)
        if state["goal"] is not None:
            if np.hypot(*(state["goal"] - pos[:2])) < 0.001:
                return np.array([0.0, 0.0, -1.0, 1.0], dtype=np.float32)
            return move(pos, state["goal"], False)
        site = sites[state["i"]]
        if np.hypot(*(site - pos[:2])) > 0.0015 and state["n"] == 0:
            return move(pos, site, False)
        state["n"] += 1
        if state["n"] < settle_steps:
            return move(pos, site, True)
        state["k"].append(float(obs[5]) / max(float(obs[6]), 1e-4))
        state["n"] = 0
        state["i"] += 1
        if state["i"] == len(sites):
            k = np.asarray(state["k"])
            w = np.clip(k - np.median(k), 0.0, None) ** 2
            pts = np.asarray(sites)
            state["goal"] = (w[:, None] * pts).sum(0) / w.sum() if w.sum() > 0 else pts[int(np.argmax(k))]
        return move(pos, site, False)

    return policy


def hold_still(obs: dict) -> dict:
    """Phase-scenario policy: keep the current tool offset and jaw opening."""
    return {"offset": obs["offset"], "opening": obs["opening"]}


# ----------------------------------------------------------------------------------------------
# Loading a policy reference, with the trust model of docs/scenarios.md
BUILTIN = {"palpation_scan": palpation_scan, "hold_still": hold_still}
BUILTIN_MODULES = ("builtin", "surgsim_envs.scenarios.policies")
#: ``shipped:TASK_ID`` names the trained .npz policy shipped for a task (surgsim_envs.policies)
SHIPPED_PREFIX = "shipped:"


def policy_kind(ref: str) -> str:
    """``"builtin"`` | ``"data"`` (.npz) | ``"code"`` (a .py file, an installed module or a
    stable-baselines3 .zip, which unpickles objects and so runs code). ConfigError for a
    reference of no known form."""
    if not isinstance(ref, str) or not ref.strip():
        raise ConfigError(f"policy must be a .npz data policy, 'builtin:NAME' or 'module:function', got {ref!r}")
    if ref.endswith(".npz"):
        return "data"
    if ref.startswith(SHIPPED_PREFIX):
        return "shipped"
    if ref.endswith(".zip"):
        return "code"
    mod, sep, attr = ref.rpartition(":")
    if not sep or not mod or not attr:
        raise ConfigError(f"policy {ref!r} must be a .npz data policy, 'builtin:NAME', 'package.module:function' "
                          "or 'file.py:function'")
    return "builtin" if mod in BUILTIN_MODULES else "code"


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
    except ValueError:
        return False
    return True


def resolve_policy_file(ref_path: str, base: Path | None) -> Path:
    """The file a policy reference names: relative paths are taken relative to ``base`` (the
    scenario's folder) when given, else the working directory."""
    p = Path(ref_path)
    if not p.is_absolute() and base is not None:
        p = base / p
    return p


def check_policy_reference(ref: str, base: Path | None = None, allow_code: bool = False,
                           trusted: bool = False) -> str:
    """Validate ``ref`` without running anything; returns its kind (see :func:`policy_kind`).

    * builtin and ``.npz`` data policies are always allowed (a .npz must exist and be readable);
    * code (``file.py:function``, ``module:function``, SB3 ``.zip``) needs ``allow_code``
      (``--allow-code``); from a scenario file (``trusted`` False) it must moreover be a file
      inside the scenario's folder ``base`` (after resolving ``..`` and symlinks): installed
      modules and files elsewhere are refused. A reference typed on the command line
      (``--policy``, ``trusted`` True) may name any module or file.
    """
    kind = policy_kind(ref)
    if kind == "builtin":
        name = ref.rpartition(":")[2]
        if name not in BUILTIN:
            raise ConfigError(f"policy {ref!r}: module surgsim_envs.scenarios.policies has no {name!r}; "
                              f"built-in policies: {sorted(BUILTIN)}")
        return kind
    if kind == "shipped":
        from surgsim_envs.envs.registry import shipped_policy_path

        shipped_policy_path(ref[len(SHIPPED_PREFIX):])     # ConfigError naming the shipped tasks
        return kind
    if kind == "data":
        path = resolve_policy_file(ref, base)
        if not path.is_file():
            raise ConfigError(f"policy file {ref!r} not found (looked for {path})")
        return kind
    if not allow_code:
        raise ConfigError(f"policy {ref!r} loads and runs Python code (a .py file, an installed module or a pickled "
                          "stable-baselines3 .zip); sharing a scenario must not share a program, so this is off by "
                          "default. Pass --allow-code (allow_code=True) if you trust it, or export it as a .npz data "
                          "policy (surgsim_envs.policies.npz_policy)")
    file_part = ref if ref.endswith(".zip") else ref.rpartition(":")[0]
    is_file = file_part.endswith((".py", ".zip"))
    if not is_file:
        if not trusted:
            raise ConfigError(f"policy {ref!r}: a scenario file may only load code from a .py file in its own folder "
                              f"({base}), not the installed module {file_part!r}; give the module on the command line "
                              "(--policy ... --allow-code) instead")
        return kind
    path = resolve_policy_file(file_part, base)
    if not trusted and (base is None or not _inside(path, base)):
        raise ConfigError(f"policy file {file_part!r} resolves to {path.resolve()}, outside the scenario's folder "
                          f"{base}; a scenario may only load code from its own folder")
    if not path.is_file():
        raise ConfigError(f"policy file {file_part!r} not found (looked for {path})")
    return kind


def load_policy(ref: str, base: Path | None = None, allow_code: bool = False, trusted: bool = False) -> Callable:
    """A policy callable from a reference (checked by :func:`check_policy_reference` first).

    ``.npz`` gives a :class:`~surgsim_envs.policies.npz_policy.NpzPolicy`; ``builtin:NAME`` a
    function of this module; a ``module:function`` / ``file.py:function`` object (a class is
    instantiated without arguments); an SB3 ``.zip`` becomes
    ``lambda obs: model.predict(obs, deterministic=True)[0]``.
    """
    kind = check_policy_reference(ref, base, allow_code, trusted)
    if kind == "builtin":
        return BUILTIN[ref.rpartition(":")[2]]
    if kind == "shipped":
        from surgsim_envs.envs.registry import load_shipped

        return load_shipped(ref[len(SHIPPED_PREFIX):])
    if kind == "data":
        from surgsim_envs.policies.npz_policy import NpzPolicy

        return NpzPolicy.load(resolve_policy_file(ref, base))
    if ref.endswith(".zip"):
        return _load_sb3(ref, resolve_policy_file(ref, base))
    mod_name, _, attr = ref.rpartition(":")
    try:
        if mod_name.endswith(".py"):
            path = resolve_policy_file(mod_name, base)
            spec = importlib.util.spec_from_file_location(path.stem, path)
            if spec is None:
                raise ConfigError(f"policy file {mod_name!r} cannot be imported")
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
        else:
            module = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ConfigError(f"policy {ref!r}: cannot import {mod_name!r} ({exc})") from None
    obj = getattr(module, attr, None)
    if obj is None:
        raise ConfigError(f"policy {ref!r}: module {mod_name!r} has no {attr!r}")
    if isinstance(obj, type):
        obj = obj()
    if not callable(obj):
        raise ConfigError(f"policy {ref!r} is not callable")
    return obj


def _load_sb3(ref: str, path: Path) -> Callable:
    try:
        import stable_baselines3 as sb3
    except ImportError:
        raise ConfigError(f"policy {ref!r} is a stable-baselines3 model, but stable-baselines3 is not installed; "
                          "pip install 'surgsim_envs[train]' or export it as a .npz data policy") from None
    for algo in ("PPO", "SAC", "TD3", "A2C", "DDPG"):
        try:
            model = getattr(sb3, algo).load(str(path))
            return lambda obs: model.predict(obs, deterministic=True)[0]
        except Exception:  # noqa: BLE001 - wrong algorithm class: try the next
            continue
    raise ConfigError(f"could not load {ref!r} with any stable-baselines3 algorithm")


def policy_for(sc, ref: str) -> Callable:
    """Load ``ref`` for scenario ``sc`` with its folder, ``allow_code`` and command-line trust."""
    trusted = bool(sc.trusted_policy) and ref == sc.trusted_policy
    return load_policy(ref, sc.folder, allow_code=sc.allow_code, trusted=trusted)
