"""Scenario runs that drive a registered Gymnasium task with a saved policy (``scenario.task``).

The policy reference (``[policy] file``) is loaded by :func:`~surgsim_envs.scenarios.policies.load_policy`
(trust model: data and built-in policies always, code only with ``--allow-code``).
A callable whose first parameter is named ``env`` is a *factory*: it is called with the
environment at the start of each episode and must return ``policy(obs) -> action``. Otherwise the
callable is the policy itself; a policy with ``reset(seed)`` (a stochastic ``.npz`` policy's
sampler) is reseeded with the episode's reset seed. Each control step records the tool's contact forces (N) and
position (m) from the task's simulation; the episode's ``info`` supplies the inclusion estimate
(``guess_xy_m``) and truth (``inclusion_centre_m``) when the task has them.
"""

from __future__ import annotations

import inspect
import time

import numpy as np

from surgsim_envs.errors import ConfigError, TissueUnstableError
from surgsim_envs.scenarios.recording import Recording, RunResult
from surgsim_envs.scenarios.schema import Scenario


def _as_policy(obj, env):
    try:
        params = list(inspect.signature(obj).parameters)
    except (TypeError, ValueError):
        params = []
    if params and params[0] == "env":
        return obj(env)
    return obj


def run_rollout(sc, progress: bool = False):
    """Run ``sc.policy.episodes`` episodes of ``sc.meta.task``; return one RunResult (all episodes
    concatenated in time; phases are the episodes)."""
    import gymnasium as gym

    import surgsim_envs  # noqa: F401  (registers the SurgSim tasks)
    from surgsim_envs.scenarios.policies import policy_for

    spec = sc.policy
    wall0 = time.perf_counter()
    try:
        env = gym.make(sc.meta.task, **dict(spec.env_kwargs))
    except gym.error.Error as exc:
        raise ConfigError(f"{sc.source or sc.name}: scenario.task {sc.meta.task!r} cannot be made: {exc}") from None
    ref = policy_for(sc, spec.file)
    rec = Recording()
    completed, error, infos = True, None, []
    t_offset = 0.0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=spec.episodes * spec.max_steps, unit="step", mininterval=0.5)
    try:
        for ep in range(spec.episodes):
            obs, info = env.reset(seed=sc.meta.seed + ep)
            policy = _as_policy(ref, env)
            if callable(getattr(policy, "reset", None)):     # a stochastic .npz policy: reproducible episodes
                policy.reset(sc.meta.seed + ep)
            sim = getattr(env.unwrapped, "sim", None)
            tool = next(iter(sim.tools)) if sim is not None and sim.tools else None
            start = t_offset
            done, steps = False, 0
            while not done and steps < spec.max_steps:
                action = policy(obs)
                obs, reward, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                steps += 1
                if tool is not None:
                    rep = sim.contact_report()[tool]
                    rec.add(t_offset + sim.time, ep, rep["normal_force"], rep["tangential_force"], 0.0,
                            rep["slipping"], rep["contacts"], rep["penetration"], sim.tool_position(tool), np.nan)
                else:
                    rec.add(t_offset + float(info.get("time_s", steps)), ep, float(info.get("force_N", 0.0)), 0.0, 0.0,
                            0, 0, 0.0, np.zeros(3), np.nan)
                if bar is not None:
                    bar.update(1)
            if not done:
                completed = False
                error = f"episode {ep} did not end within max_steps={spec.max_steps}"
            end = t_offset + (sim.time if sim is not None else steps)
            rec.phase_names.append(f"episode {ep}")
            rec.phase_spans.append({"index": ep, "type": "policy", "label": f"episode {ep}", "driver": "policy",
                                    "start": start, "end": end})
            infos.append({k: v for k, v in info.items() if isinstance(v, (int, float, str, bool, list))})
            t_offset = end
    except TissueUnstableError as exc:
        completed, error = False, str(exc)
    finally:
        if bar is not None:
            bar.close()
        env.close()
    rec.finish()
    return _evaluate_rollout(sc, rec, completed, error, infos, time.perf_counter() - wall0)


def _evaluate_rollout(sc: Scenario, rec: Recording, completed: bool, error, infos: list, wall: float) -> RunResult:
    """Score a Gymnasium rollout: forces from the recording, the inclusion error from ``info``
    (``localisation_error_m`` or ``guess_xy_m`` vs ``inclusion_centre_m``), averaged over episodes."""
    from surgsim_envs.scenarios.scoring import compute_metrics, default_criteria, safety_violations, score_criteria

    limit = sc.scoring.safety_limit
    metrics = compute_metrics(rec, limit, completed)
    errors = []
    for info in infos:
        if info.get("localisation_error_m") is not None:
            errors.append(float(info["localisation_error_m"]))
        elif info.get("guess_xy_m") is not None and info.get("inclusion_centre_m") is not None:
            errors.append(float(np.linalg.norm(np.subtract(info["guess_xy_m"], info["inclusion_centre_m"][:2]))))
    if errors:
        metrics["inclusion_error"] = float(np.mean(errors))
        metrics["inclusion_errors"] = errors
    metrics["episodes"] = infos
    criteria = sc.scoring.criteria or default_criteria(limit, bool(errors))
    score, results = score_criteria(metrics, criteria)
    violations = safety_violations(rec.t, rec.normal, limit)
    return RunResult(sc, {}, rec, completed, error, metrics, score, results, violations, wall,
                     {"task": sc.meta.task, "policy": sc.policy.file})
