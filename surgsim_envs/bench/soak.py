"""Long runs of a task with random actions, random seeds and resets (``surgsim bench soak``,
:mod:`surgsim_envs.cli.bench_soak`; several processes: :mod:`surgsim_envs.bench.soak_parallel`).

Every control step takes a uniformly random action from the action space; every episode end
(termination or truncation) resets with a fresh random seed drawn from ``--seed``. Counted:

* ``nan``: steps whose observation or reward holds NaN/inf;
* ``exceptions``: exceptions raised by ``reset``/``step`` (by type, first message kept); the env
  is reset (or rebuilt if reset fails) and the run goes on. A tissue divergence is counted
  separately as ``unstable`` (``TissueUnstableError`` or ``info["unstable"]``);
* ``obs_out_of_space``: observations outside the declared observation space;
* ``force_out_of_bounds``: steps whose tool force (``info["peak_force_N"]``, the episode's peak, or
  ``info["force_N"]`` where a task reports the press force instead: :data:`FORCE_KEYS`) is
  non-finite, negative or above ``--force-bound`` N (default 50 N: tools pressing on soft tissue
  stay within a few N);
* memory: resident set size (RSS, from ``/proc/self/statm``) after the first episode and at the
  end; ``rss_growth_mb`` is their difference, ``rss_slope_mb_per_100k`` the least-squares slope
  of RSS samples taken every ``--sample-every`` steps.

Zero of each is the target (no input may crash, diverge or leak). The JSON also records steps/s and the machine load.
Timings depend on the machine and its load; tests only run a short soak and check the counts.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError, TissueUnstableError

FORCE_BOUND_N = 50.0

#: info keys of a step's tool force, first present wins: the episode peak (physics-rate tasks) or the
#: force of the press (quasi-static LayeredPalpation-v0)
FORCE_KEYS = ("peak_force_N", "force_N")


def rss_mb() -> float:
    """Current resident set size of this process in MB (Linux ``/proc``; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        return math.nan


def _finite(x) -> bool:
    if isinstance(x, dict):
        return all(_finite(v) for v in x.values())
    try:
        return bool(np.all(np.isfinite(np.asarray(x, dtype=float))))
    except (TypeError, ValueError):
        return False


class _Counts:
    def __init__(self):
        self.steps = self.episodes = self.nan = self.unstable = self.obs_out_of_space = 0
        self.force_out_of_bounds = 0
        self.exceptions: dict[str, int] = {}
        self.first_messages: dict[str, str] = {}
        self.max_peak_force = 0.0

    def exception(self, exc: BaseException, where: str) -> None:
        key = f"{where}:{type(exc).__name__}"
        self.exceptions[key] = self.exceptions.get(key, 0) + 1
        self.first_messages.setdefault(key, str(exc)[:300])


def soak(task: str, steps: int, seed: int = 0, force_bound: float = FORCE_BOUND_N, max_seconds: float = math.inf,
         sample_every: int = 1000, progress: bool = False, env_kwargs: dict | None = None,
         checkpoint=None, checkpoint_every: int = 10_000, counter=None) -> dict:
    """Run ``steps`` random-action steps of ``task``; returns the JSON row (module docstring).

    ``checkpoint(row)`` (optional) is called with the row so far every ``checkpoint_every``
    steps (an interrupted run keeps what it counted, see :mod:`.soak_parallel`); ``counter``
    (optional, a shared ``multiprocessing.Value``) is advanced by the steps run, every 100."""
    import gymnasium as gym

    import surgsim_envs.envs  # noqa: F401  (registers the SurgSim tasks)

    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise ConfigError(f"--steps must be an integer >= 1, got {steps!r}")
    validate.positive(force_bound, "--force-bound", unit="N", fix="the peak force counted as out of bounds, e.g. 50")
    if not max_seconds > 0:
        raise ConfigError(f"--max-seconds must be > 0, got {max_seconds!r}")
    if task not in gym.registry:
        ours = sorted(k for k in gym.registry if k.startswith("SurgSim/"))
        raise ConfigError(f"unknown task {task!r}; choose one of {ours} or 'all'")
    rng = np.random.default_rng(seed)
    kwargs = dict(env_kwargs or {})

    def make():
        env = gym.make(task, **kwargs)
        env.action_space.seed(int(rng.integers(2**31)))
        return env

    env = make()
    c = _Counts()
    samples: list[tuple[int, float]] = []
    rss0 = math.nan
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=steps, unit="step", mininterval=1.0, desc=task, file=sys.stderr)
    wall0 = time.perf_counter()
    need_reset = True
    reported = 0
    try:
        while c.steps < steps and time.perf_counter() - wall0 < max_seconds:
            if need_reset:
                try:
                    obs, _ = env.reset(seed=int(rng.integers(2**31)))
                    need_reset = False
                    c.episodes += 1
                    if c.episodes == 2 and math.isnan(rss0):  # after one whole episode: caches warm
                        rss0 = rss_mb()
                        samples.append((c.steps, rss0))
                except Exception as exc:  # noqa: BLE001 - counted, then the env is rebuilt
                    c.exception(exc, "reset")
                    env.close()
                    env = make()
                    continue
            action = env.action_space.sample()
            try:
                obs, reward, terminated, truncated, info = env.step(action)
            except TissueUnstableError:
                c.unstable += 1
                c.steps += 1
                need_reset = True
                continue
            except Exception as exc:  # noqa: BLE001 - counted; the episode restarts
                c.exception(exc, "step")
                c.steps += 1
                need_reset = True
                continue
            c.steps += 1
            if bar is not None:
                bar.update(1)
            if not (_finite(obs) and _finite(reward)):
                c.nan += 1
            elif not env.observation_space.contains(obs):
                c.obs_out_of_space += 1
            peak = next((info[k] for k in FORCE_KEYS if info.get(k) is not None), None)
            if peak is not None:
                if not (math.isfinite(peak) and 0.0 <= peak <= force_bound):
                    c.force_out_of_bounds += 1
                elif peak > c.max_peak_force:
                    c.max_peak_force = float(peak)
            if info.get("unstable"):
                c.unstable += 1
            if c.steps % sample_every == 0 and not math.isnan(rss0):
                samples.append((c.steps, rss_mb()))
            if counter is not None and c.steps % 100 == 0:
                with counter.get_lock():
                    counter.value += c.steps - reported
                reported = c.steps
            if checkpoint is not None and c.steps % checkpoint_every == 0:
                checkpoint(_row(task, steps, seed, force_bound, c, samples, rss0, time.perf_counter() - wall0))
            need_reset = bool(terminated or truncated)
    finally:
        if bar is not None:
            bar.close()
        env.close()
    if counter is not None:
        with counter.get_lock():
            counter.value += c.steps - reported
    return _row(task, steps, seed, force_bound, c, samples, rss0, time.perf_counter() - wall0)


def _row(task: str, steps: int, seed: int, force_bound: float, c: _Counts, samples: list, rss0: float,
         wall: float) -> dict:
    """The JSON row of one soak (or of its part so far)."""
    rss1 = rss_mb()
    slope = math.nan
    if len(samples) >= 3:
        xs, ys = np.array(samples, dtype=float).T
        slope = float(np.polyfit(xs, ys, 1)[0] * 1e5)
    return {
        "task": task, "steps": c.steps, "steps_requested": steps, "episodes": c.episodes, "seed": seed,
        "stopped_by_time": c.steps < steps, "wall_s": wall, "steps_per_s": c.steps / wall if wall > 0 else math.nan,
        "nan": c.nan, "exceptions": sum(c.exceptions.values()), "exception_types": dict(c.exceptions),
        "exception_messages": dict(c.first_messages), "unstable": c.unstable, "obs_out_of_space": c.obs_out_of_space,
        "force_out_of_bounds": c.force_out_of_bounds, "force_bound_N": force_bound,
        "max_peak_force_N": c.max_peak_force, "rss_start_mb": rss0, "rss_end_mb": rss1,
        "rss_growth_mb": rss1 - rss0 if not math.isnan(rss0) else math.nan, "rss_slope_mb_per_100k": slope,
        "load_avg": list(os.getloadavg()), "cpus": os.cpu_count(),
    }
