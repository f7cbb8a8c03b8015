"""A lean multi-process Gymnasium vector env for the SurgSim tasks: what
``gym.make_vec("SurgSim/Grasp-v0", num_envs=4)`` returns (each task's ``vector_entry_point``).

>>> import gymnasium as gym, surgsim_envs
>>> vec = gym.make_vec("SurgSim/Grasp-v0", num_envs=4)               # doctest: +SKIP
>>> obs, info = vec.reset(seed=0)                                     # doctest: +SKIP
>>> obs, rew, term, trunc, info = vec.step(vec.action_space.sample())  # doctest: +SKIP
>>> vec.close()                                                       # doctest: +SKIP

``workers`` processes (default ``min(num_envs, os.cpu_count())``), each hosting a contiguous block
of envs and stepping them one after another. Actions, observations, rewards, terminations,
truncations and the numeric info entries live in one shared-memory block
(:mod:`~surgsim_envs.vector.ipc`); a step is one byte down each worker's command pipe and
one byte back. Gymnasium's AsyncVectorEnv instead pickles each env's action, observation and
info dict through a ``multiprocessing.Pipe`` and merges the infos key by key in the main process
(~0.4-0.6 ms per vector step here: CHANGELOG.md "Vector env: shared memory instead of pickled steps").

Semantics are Gymnasium 1.x's (:class:`gymnasium.vector.SyncVectorEnv` gives the same numbers for
the same seeds; tests/test_vector_env.py): ``autoreset_mode`` NEXT_STEP (default), SAME_STEP
(``info["final_obs"]``/``info["final_info"]``) or DISABLED; ``reset(seed=int | list, options=...)``
with ``options["reset_mask"]``; ``single_observation_space``/``single_action_space``; ``call``,
``get_attr``, ``set_attr``, ``render``. Returned arrays are fresh copies every step. Actions are
cast to the action space's dtype (float32) on their way to the workers.

**Infos** (``info_keys=``): by default only the numeric entries (``bool``/``int``/``float``/numpy
scalars, also inside nested dicts such as ``reward_terms``), through shared memory with
Gymnasium's ``_key`` masks (:mod:`~surgsim_envs.vector.info`); strings, lists and None
(``organ``, ``inclusion_centre_m``, ``estimate_xy_m`` ...) are left out, since pickling them every
step costs as much as the step's pipe round trip. ``info_keys="all"`` adds them back (pickled,
only for steps that have them); a tuple of key names keeps just those (``()``: no infos at all).

**in_main=True**: the main process steps block 0 itself while the workers step the others
(``workers`` then counts the main process: ``num_envs=2, workers=2`` is one worker process).
One sleep/wake-up less per step for the main process; a crash (not an exception) in a block-0
env then takes the main process with it.

**spin_us** (default 0): once fewer workers than cores are still busy (the others replied, or
with ``in_main`` the main process finished its own block), the main process polls for the
remaining replies without sleeping for up to this many microseconds before it blocks. It saves
the main process a wake-up per step when a core is free; when the cores are shared with other
work it takes CPU from them (CHANGELOG.md "Vector env: accounting, info write plans, bounded spin").
**worker_spin_us** (default 0): the same on the workers' side: after each reply a worker polls its
command pipe for up to this long (yielding the core between polls) before it sleeps, so that the
next step's command is read without a wake-up. For a machine with a core per process (``in_main``
on 2 cores); otherwise the polling workers compete with the main process.

**Failures**: an exception inside an env is re-raised in the main process with a note naming
the env index and the worker's traceback (the vector env stays usable after a ``reset``). A
worker that dies or does not answer within ``timeout_s`` raises
:class:`~surgsim_envs.errors.VectorEnvWorkerError` naming its envs, instead of hanging; the
vector env is then unusable. ``close()`` never hangs: workers that do not exit within
``close_timeout_s`` are terminated, then killed.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import select
import time

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from surgsim_envs import validate
from surgsim_envs.vector import ipc
from surgsim_envs.vector.info import InfoMerger
from surgsim_envs.vector.worker import _Worker, worker_main
from surgsim_envs.errors import ConfigError, VectorEnvWorkerError

#: us the main process polls for replies without sleeping once fewer workers than cores are busy
#: (``spin_us=``; CHANGELOG.md "Vector env: accounting, info write plans, bounded spin")
DEFAULT_SPIN_US = 0.0
#: us a worker polls for its next command without sleeping after each reply (``worker_spin_us=``)
DEFAULT_WORKER_SPIN_US = 0.0

#: bytes of shared memory one rollout() record may take (observations, actions, rewards, flags)
MAX_ROLLOUT_BYTES = 1 << 30

#: spaces whose samples are fixed-shape arrays (what the shared memory holds)
_ARRAY_SPACES = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)


#: s, the longest a vector env waits for its workers (a day: "wait forever" is a hang, not a timeout)
MAX_TIMEOUT_S = 86_400.0
#: s, the shortest: a worker cannot even answer a command in less
MIN_TIMEOUT_S = 1e-3
#: numeric info entries per env the shared memory may hold (a task has a few dozen)
MAX_INFO_KEYS = 4096
#: envs one vector env may hold: each task env takes tens of MB, so 1024 of them fill a large machine
MAX_ENVS = 1024


def _spin_microseconds(name, value) -> float:
    """A polling time option (us) in [0, 100000]: ConfigError naming it otherwise (NaN included)."""
    return validate.real(value, name, lo=0.0, hi=1e5, unit="us",
                         fix="0 sleeps at once; a few tens of us save a wake-up where a core is free")


def _info_mode(info_keys):
    """``(keys or None, keep_other)`` from the ``info_keys`` option."""
    if info_keys is None:
        return None, False
    if isinstance(info_keys, str):
        if info_keys == "all":
            return None, True
        raise ConfigError(f"info_keys must be None (numeric entries), 'all' or a sequence of key names, "
                          f"got {info_keys!r}")
    if not isinstance(info_keys, (list, tuple, set, frozenset)):
        raise ConfigError(f"info_keys must be None (numeric entries), 'all' or a sequence of key names, got "
                          f"{info_keys!r} of type {type(info_keys).__name__}")
    keys = tuple(info_keys)
    if not all(isinstance(k, str) for k in keys):
        raise ConfigError(f"info_keys must be None, 'all' or a sequence of key names (str), got {info_keys!r}")
    return keys, True


class SurgSimVectorEnv(VectorEnv):
    """``num_envs`` copies of task ``env_id`` (made with ``gym.make(env_id, **env_kwargs)``) in
    ``workers`` processes. ``env_id`` may also be a picklable callable returning one env
    (``env_id(**env_kwargs)``), e.g. a function that wraps the task. See the module docstring for
    the options and semantics."""

    def __init__(self, env_id: str, num_envs: int = 1, *, workers: int | None = None, info_keys=None,
                 autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP, max_info_keys: int = 64,
                 context: str | None = None, timeout_s: float = 300.0, start_timeout_s: float = 600.0,
                 close_timeout_s: float = 5.0, in_main: bool = False, spin_us: float = DEFAULT_SPIN_US,
                 worker_spin_us: float = DEFAULT_WORKER_SPIN_US, **env_kwargs):
        self._workers: dict = {}                 # block number -> (process, command pipe, reply pipe)
        self._local = None                       # with in_main: block 0, stepped by this process
        self._shm = None
        self.closed = False
        self._broken: str | None = None
        self._waiting = False
        self.num_envs = validate.integer(num_envs, "SurgSimVectorEnv num_envs", lo=1, hi=MAX_ENVS,
                                         fix=f"at most {MAX_ENVS} envs in one vector env (each takes tens of MB)")
        n_workers = min(self.num_envs, os.cpu_count() or 1) if workers is None else workers
        n_workers = validate.integer(n_workers, "SurgSimVectorEnv workers", lo=1, hi=self.num_envs,
                                     fix=f"at most one worker per env ({self.num_envs} envs)")
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ConfigError(f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, "
                              f"got {autoreset_mode!r}") from None
        keys, keep_other = _info_mode(info_keys)
        self.info_keys = info_keys
        max_info_keys = validate.integer(max_info_keys, "SurgSimVectorEnv max_info_keys", lo=1, hi=MAX_INFO_KEYS,
                                         fix="the number of numeric info entries shared per env, e.g. 64")
        for name, t in (("timeout_s", timeout_s), ("start_timeout_s", start_timeout_s),
                        ("close_timeout_s", close_timeout_s)):
            validate.real(t, name, lo=MIN_TIMEOUT_S, hi=MAX_TIMEOUT_S, unit="s",
                          fix="a worker that does not answer within it is reported; waiting forever is a hang")
        self.timeout_s, self.close_timeout_s = float(timeout_s), float(close_timeout_s)
        self.spin_us = _spin_microseconds("spin_us", spin_us)
        self.worker_spin_us = _spin_microseconds("worker_spin_us", worker_spin_us)
        self._spin_s = self.spin_us * 1e-6
        self._cpus = os.cpu_count() or 1
        if not (isinstance(env_id, str) or callable(env_id)):
            raise ConfigError(f"env_id must be a registered task id (str) or a callable returning an env, got {env_id!r}")
        self.env_id = env_id if isinstance(env_id, str) else getattr(env_id, "__name__", repr(env_id))

        if context is not None:
            validate.choice(context, "SurgSimVectorEnv context", mp.get_all_start_methods(),
                            fix="a multiprocessing start method, or None for the platform default")
        ctx = mp.get_context(context)
        if ctx.get_start_method() == "fork":
            # one resource tracker for all processes: a worker that attaches the shared memory must
            # not start its own tracker, which would unlink the block when the worker exits
            from multiprocessing import resource_tracker
            resource_tracker.ensure_running()
        bounds = np.linspace(0, self.num_envs, n_workers + 1).round().astype(int)
        self._ranges = [(int(bounds[w]), int(bounds[w + 1])) for w in range(n_workers)]
        self._poller = select.poll()
        if not isinstance(in_main, bool):
            raise ConfigError(f"in_main must be True or False, got {in_main!r}")
        self.in_main = in_main
        try:
            for w, (lo, hi) in enumerate(self._ranges):
                if in_main and w == 0:
                    continue
                cmd_r, cmd_w = ctx.Pipe(duplex=False)
                rep_r, rep_w = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=worker_main, name=f"SurgSimVectorEnv-{w}", daemon=True,
                                   args=(env_id, env_kwargs, lo, hi, cmd_r, rep_w, self.autoreset_mode.value,
                                         keys, keep_other, max_info_keys, self.worker_spin_us, os.getpid()))
                proc.start()
                cmd_r.close()
                rep_w.close()
                self._workers[w] = (proc, cmd_w, rep_r)
                self._poller.register(rep_r.fileno(), select.POLLIN)
            if in_main:
                lo, hi = self._ranges[0]
                try:
                    self._local = _Worker(env_id, env_kwargs, lo, hi, self.autoreset_mode.value, keys, keep_other,
                                          max_info_keys)
                except BaseException as exc:
                    exc.add_note(f"raised while making {self._envs_of(0)} of {self.env_id} in the main process")
                    raise
            described = self._gather(ipc.OK, "start-up", timeout=start_timeout_s)
            if in_main:
                described[0] = self._local.description()
            self._setup(described, max_info_keys)
            self._command(ipc.ATTACH, lambda w: (self._shm.name, self._layout))
            self._gather(ipc.OK, "attach")
            if in_main:
                self._local.use_views(self._v, self._layout.same_step)
        except BaseException:
            self.close(terminate=True)
            raise

    # --- set-up ---------------------------------------------------------------------------
    def _setup(self, described: dict, max_info_keys: int) -> None:
        from multiprocessing import shared_memory

        first = described[0]
        self.single_observation_space = first["observation_space"]
        self.single_action_space = first["action_space"]
        for what in ("observation_space", "action_space"):
            space = first[what]
            if not isinstance(space, _ARRAY_SPACES):
                raise ConfigError(
                    f"SurgSimVectorEnv shares {what.split('_')[0]}s as arrays and needs a Box, Discrete, "
                    f"MultiDiscrete or MultiBinary space, got {space}; use "
                    "gym.make_vec(..., vectorization_mode='async') for other spaces")
            for w, d in described.items():
                if d[what] != space:
                    raise ConfigError(f"the envs of worker {w} have {what} {d[what]}, worker 0's {space}: "
                                      "every env of a vector env needs the same spaces")
        self.metadata = dict(first["metadata"])
        self.metadata["autoreset_mode"] = self.autoreset_mode
        self.render_mode = first["render_mode"]
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        obs, act = self.single_observation_space, self.single_action_space
        self._layout = ipc.Layout(self.num_envs, obs.shape, obs.dtype, act.shape, act.dtype, max_info_keys,
                                  same_step=self.autoreset_mode == AutoresetMode.SAME_STEP)
        self._shm = shared_memory.SharedMemory(create=True, size=self._layout.nbytes)
        self._v = self._layout.views(self._shm.buf)
        self._merger = InfoMerger(self.num_envs, self._ranges)
        self._cmd_fds = {w: c.fileno() for w, (_, c, _) in self._workers.items()}

    # --- messaging --------------------------------------------------------------------------
    def _envs_of(self, w: int) -> str:
        lo, hi = self._ranges[w]
        return f"env {lo}" if hi - lo == 1 else f"envs {lo}..{hi - 1}"

    def _check_usable(self) -> None:
        if self.closed:
            raise VectorEnvWorkerError("this SurgSimVectorEnv is closed; make a new one")
        if self._broken:
            raise VectorEnvWorkerError(f"this SurgSimVectorEnv is unusable: {self._broken}; close() it and make a "
                                       "new one")
        if self._waiting:
            raise ConfigError("step_async was called without step_wait: call step_wait() first")

    def _command(self, op: int, payload_of=None) -> None:
        for w, (_, cmd, _) in self._workers.items():
            try:
                ipc.send(cmd.fileno(), op, None if payload_of is None else payload_of(w))
            except OSError:
                self._died(w, "a command")

    def _died(self, w: int, what: str):
        proc = self._workers[w][0]
        proc.join(0.5)
        code = proc.exitcode
        how = ("is still running but closed its pipe" if code is None else
               f"was killed by signal {-code}" if code < 0 else f"exited with code {code}")
        self._broken = f"worker {w} (pid {proc.pid}, {self._envs_of(w)}) {how} during {what}"
        raise VectorEnvWorkerError(
            f"SurgSimVectorEnv worker {w} (pid {proc.pid}), hosting {self._envs_of(w)} of {self.env_id}, {how} "
            f"during {what}: close() this vector env and make a new one (look for an out-of-memory kill or "
            "a crash in the env)")

    def _gather(self, expect: int, what: str, timeout: float | None = None) -> dict:
        """Wait for one reply from every worker; return ``{worker: payload}``; raise the first error."""
        pending = {rep.fileno(): w for w, (_, _, rep) in self._workers.items()}
        timeout = self.timeout_s if timeout is None else timeout
        deadline = time.monotonic() + timeout
        replies: dict = {}
        try:
            while pending:
                events = None
                if self._spin_s and len(pending) < self._cpus:
                    # a core is free (fewer busy workers than cores): poll without sleeping for a
                    # while, which spares this process a wake-up when the reply comes soon
                    end = time.perf_counter() + self._spin_s
                    events = self._poller.poll(0)
                    while not events and time.perf_counter() < end:
                        events = self._poller.poll(0)
                if not events:
                    events = self._poller.poll(max(0.0, deadline - time.monotonic()) * 1e3)
                if not events:
                    late = ", ".join(f"worker {w} ({self._envs_of(w)})" for w in pending.values())
                    self._broken = f"{late} did not answer {what} within {timeout:g} s"
                    raise VectorEnvWorkerError(
                        f"SurgSimVectorEnv ({self.env_id}): {late} did not answer {what} within "
                        f"timeout_s={timeout:g} s; close() it (the workers are terminated) and pass a larger "
                        "timeout_s= if the envs are just slow")
                for fd, _ in events:
                    w = pending.pop(fd, None)
                    if w is None:
                        continue
                    try:
                        replies[w] = ipc.receive(fd)
                    except (ipc.WorkerGone, OSError):
                        self._died(w, what)
        except KeyboardInterrupt:
            self._broken = f"interrupted while waiting for {what}"
            raise
        out = {}
        for w in sorted(replies):
            op, payload = replies[w]
            if op == ipc.ERROR:
                self._raise_worker_error(w, payload, what)
            out[w] = payload
        return out

    def _broadcast(self, op: int, payload_of, what: str, timeout: float | None = None) -> dict:
        """Send ``op`` to every worker, run it on the main process's own block (``in_main``) in the
        meantime, and return ``{block: reply payload}`` (``timeout``: s, default ``timeout_s``)."""
        self._command(op, payload_of)
        local = self._run_local(op, None if payload_of is None else payload_of(0), what)
        replies = self._gather(ipc.OK, what, timeout=timeout)
        if self._local is not None:
            replies[0] = local
        return replies

    def _run_local(self, op: int, payload, what: str):
        """``op`` on the in-main block (None without one). An error waits for the workers' replies
        (so that the pipes stay in step) before it is raised."""
        if self._local is None:
            return None
        try:
            if op == ipc.STEP:
                return self._local.step()
            if op == ipc.RESET:
                return self._local.reset(*payload)
            if op == ipc.ROLLOUT:
                return self._local.rollout(*payload)
            if op == ipc.CALL:
                return self._local.call(*payload)
            return self._local.set_attr(*payload)
        except BaseException as exc:
            env = self._local.current
            try:
                self._gather(ipc.OK, what)
            except Exception:  # noqa: BLE001 - the env's own error is the one to report
                pass
            exc.add_note(f"raised in env {env} of SurgSimVectorEnv({self.env_id}, num_envs={self.num_envs}) "
                         f"(in the main process) during {what}")
            raise

    def _raise_worker_error(self, w: int, p: dict, what: str):
        exc = p["exception"]
        if not isinstance(exc, BaseException):
            exc = VectorEnvWorkerError(f"{p['type']}: {p['message']}")
        env = p["env"]
        exc.add_note(f"raised in env {env} of SurgSimVectorEnv({self.env_id}, num_envs={self.num_envs}) "
                     f"(worker {w}, pid {self._workers[w][0].pid}) during {what}; worker traceback:\n"
                     f"{p['traceback']}")
        raise exc

    def _absorb(self, replies: dict):
        other, final_other = {}, {}
        for w, payload in replies.items():
            if payload:
                if payload["new_keys"]:
                    self._merger.announce(w, payload["new_keys"])
                other.update(payload["other"] or {})
                final_other.update(payload["final_other"] or {})
        return other, final_other

    def _infos(self, other: dict, final_other: dict) -> dict:
        v = self._v
        infos = self._merger.merge(v["info_values"], v["info_present"])
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            final = v["final"].copy()
            if final.any():
                final_obs = np.full(self.num_envs, None, dtype=object)
                for i in np.flatnonzero(final):
                    final_obs[i] = v["final_obs"][i].copy()
                final_info = self._merger.merge(v["final_info_values"], v["final_info_present"], rows=final)
                for i, d in sorted(final_other.items()):
                    final_info = self._add_info(final_info, d, i)
                infos["final_obs"], infos["_final_obs"] = final_obs, final
                infos["final_info"], infos["_final_info"] = final_info, final.copy()
        for i, d in sorted(other.items()):
            infos = self._add_info(infos, d, i)
        return infos

    # --- Gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        """Reset every env (or those in ``options["reset_mask"]``); ``seed``: None, an int (env i
        gets ``seed + i``) or one seed per env."""
        self._check_usable()
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ConfigError(f"reset(seed=...) needs one seed per env ({n}), got {len(seeds)}: {seed!r}")
        mask = None
        if options is not None and "reset_mask" in options:
            options = dict(options)
            mask = options.pop("reset_mask")
            if not (isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.shape == (n,)):
                raise ConfigError(f"options['reset_mask'] must be a numpy bool array of shape ({n},), got {mask!r}")
            if not mask.any():
                raise ConfigError("options['reset_mask'] must have at least one True entry, got all False")
        replies = self._broadcast(ipc.RESET, lambda w: (
            seeds[slice(*self._ranges[w])], options, None if mask is None else mask[slice(*self._ranges[w])].tolist()),
            "reset")
        other, _ = self._absorb(replies)
        return self._v["obs"].copy(), self._infos(other, {})

    def step_async(self, actions) -> None:
        """Send ``actions`` (shape ``action_space.shape``) to the workers; :meth:`step_wait` collects."""
        self._check_usable()
        acts = self._v["actions"]
        a = np.asarray(actions)
        if a.dtype.kind not in "iuf":
            raise ConfigError(f"actions must be real numbers (float or int) of shape {acts.shape}, got dtype "
                              f"{a.dtype} (bool, complex, string and object actions are refused)")
        if a.shape != acts.shape:
            raise ConfigError(f"actions must have shape {acts.shape} (num_envs x action shape), got {a.shape}")
        acts[...] = a
        for w, fd in self._cmd_fds.items():
            try:
                ipc.send_step(fd)
            except OSError:
                self._died(w, "step")
        self._waiting = True

    def step_wait(self):
        """The results of the step :meth:`step_async` started."""
        if not self._waiting:
            raise ConfigError("step_wait() without step_async(actions)")
        self._waiting = False
        local = self._run_local(ipc.STEP, None, "step")
        replies = self._gather(ipc.OK, "step")
        if self._local is not None:
            replies[0] = local
        other, final_other = self._absorb(replies)
        v = self._v
        return (v["obs"].copy(), v["rewards"].copy(), v["terminations"].copy(), v["truncations"].copy(),
                self._infos(other, final_other))

    def step(self, actions):
        self.step_async(actions)
        return self.step_wait()

    def rollout(self, policy, steps: int, seed: int | None = None) -> dict:
        """``steps`` vector steps with actions from ``policy``, each worker stepping its own block
        without a round trip per step: one command per worker for the whole rollout.

        ``policy``: a picklable callable (it is sent to every worker), called on a block's
        observations ``(k, *single observation shape)`` and returning ``(k, *single action shape)``
        actions, e.g. ``NpzPolicy.load(path).batched`` (:class:`~surgsim_envs.policies.npz_policy.
        BatchedPolicy`) or a module-level function; it must act on each row alone (blocks differ between
        worker layouts).
        Every step is what :meth:`step` does with those actions (autoreset, the same rewards and
        flags: SyncVectorEnv stepping the same policy gives the same arrays), and the vector env
        goes on from where the rollout ended. Infos are not recorded.

        Each worker gets its own (pickled) copy of ``policy``, random state included, so a stochastic
        policy would draw the same noise in every block; with ``seed`` (an int) and a policy that has
        ``reset(seed)`` (e.g. ``NpzPolicy.batched``), each block's copy is reset with ``seed`` + its first env
        index before it acts: distinct, reproducible streams per block.

        Returns ``{"observations": (steps + 1, n, ...), "actions": (steps, n, ...), "rewards",
        "terminations", "truncations": (steps, n)}``: ``observations[t]`` is what ``actions[t]`` was
        chosen from (row 0: the observations of the last reset or step). The record must fit in
        :data:`MAX_ROLLOUT_BYTES` (a ConfigError says how many steps do: call rollout in chunks), and a
        worker may take ``timeout_s`` per step before it counts as hung."""
        from multiprocessing import shared_memory

        self._check_usable()
        if self.autoreset_mode == AutoresetMode.DISABLED:
            raise ConfigError("rollout() needs autoreset (autoreset_mode NEXT_STEP or SAME_STEP): with DISABLED an "
                              "env that ends mid-rollout could not go on")
        steps = validate.integer(steps, "rollout steps", lo=1, fix="give the number of vector steps to run")
        if not callable(policy):
            raise ConfigError(f"rollout policy must be a callable (observations -> actions), got {policy!r}")
        if seed is not None:
            if not (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool)):
                raise ConfigError(f"rollout seed must be an int or None, got {seed!r}")
            if not callable(getattr(policy, "reset", None)):
                raise ConfigError(f"rollout(seed={seed}) reseeds the policy with its reset(seed) method, and "
                                  f"{type(policy).__name__} has none: drop seed= or give the policy a reset(seed)")
            seed = int(seed)
        obs, act = self.single_observation_space, self.single_action_space
        layout = ipc.RolloutLayout(steps, self.num_envs, obs.shape, obs.dtype, act.shape, act.dtype)
        if layout.nbytes > MAX_ROLLOUT_BYTES:
            per_step = ipc.RolloutLayout(1, self.num_envs, obs.shape, obs.dtype, act.shape, act.dtype).nbytes
            raise ConfigError(f"rollout of {steps} steps x {self.num_envs} envs needs {layout.nbytes / 2**30:.1f} GiB of "
                              f"shared memory, above MAX_ROLLOUT_BYTES ({MAX_ROLLOUT_BYTES / 2**30:.0f} GiB): call "
                              f"rollout in chunks of at most {MAX_ROLLOUT_BYTES // per_step} steps")
        shm = shared_memory.SharedMemory(create=True, size=layout.nbytes)
        try:
            replies = self._broadcast(ipc.ROLLOUT, lambda w: (policy, steps, shm.name, layout, seed), "rollout",
                                      timeout=self.timeout_s * steps)
            self._absorb(replies)
            return {k: a.copy() for k, a in layout.views(shm.buf).items()}
        finally:
            shm.close()
            shm.unlink()

    def call(self, name: str, *args, **kwargs) -> tuple:
        """``name(*args, **kwargs)`` on every env (or the attribute's value if not callable)."""
        return self.call_envs(None, name, *args, **kwargs)

    def call_envs(self, indices, name: str, *args, **kwargs) -> tuple:
        """:meth:`call` on the envs ``indices`` only (None: all), results in that order."""
        self._check_usable()
        which = self._which(indices)
        replies = self._broadcast(ipc.CALL, lambda w: (name, args, kwargs, which[w]), f"call({name!r})")
        results = tuple(x for w in range(len(self._ranges)) for x in replies[w])
        if indices is None:
            return results
        order = [lo + j for (lo, _), local in zip(self._ranges, which) for j in local]
        by_env = dict(zip(order, results))
        return tuple(by_env[i] for i in self._indices(indices))

    def get_attr(self, name: str) -> tuple:
        return self.call(name)

    def set_attr(self, name: str, values, indices=None) -> None:
        """Set attribute ``name`` of every env (or of ``indices``): one value for all, or a
        list/tuple of one per env."""
        self._check_usable()
        targets = list(range(self.num_envs)) if indices is None else self._indices(indices)
        if not isinstance(values, (list, tuple)):
            values = [values] * len(targets)
        if len(values) != len(targets):
            raise ConfigError(f"set_attr({name!r}) needs one value per env ({len(targets)}), got {len(values)}")
        value_of = dict(zip(targets, values))
        which = [[i - lo for i in sorted(value_of) if lo <= i < hi] for lo, hi in self._ranges]
        self._broadcast(ipc.SET_ATTR, lambda w: (name, [value_of[self._ranges[w][0] + j] for j in which[w]], which[w]),
                        f"set_attr({name!r})")

    def _which(self, indices) -> list:
        """Per worker: its local env numbers among ``indices`` (None: all -> None per worker)."""
        if indices is None:
            return [None] * len(self._ranges)
        idx = sorted(set(self._indices(indices)))
        return [[i - lo for i in idx if lo <= i < hi] for lo, hi in self._ranges]

    def _indices(self, indices) -> list:
        idx = [int(i) for i in ([indices] if isinstance(indices, (int, np.integer)) else indices)]
        bad = [i for i in idx if not 0 <= i < self.num_envs]
        if bad:
            raise ConfigError(f"env indices {bad} out of range for {self.num_envs} envs")
        return idx

    def render(self):
        return self.call("render")

    @property
    def worker_pids(self) -> list:
        """Process ids of the worker processes, in block order (with ``in_main`` block 0 is this
        process and not listed)."""
        return [p.pid for p, _, _ in self._workers.values()]

    @property
    def worker_envs(self) -> list:
        """``(first, last + 1)`` env indices of each block (block 0 in this process with ``in_main``)."""
        return list(self._ranges)

    def close_extras(self, terminate: bool = False, **kwargs) -> None:
        """Ask the workers to close their envs and exit; terminate (then kill) those still running
        after ``close_timeout_s``. Never waits longer than about ``close_timeout_s + 2`` s."""
        deadline = time.monotonic() + (0.0 if terminate else self.close_timeout_s)
        for proc, cmd, _ in self._workers.values():
            if proc.is_alive() and not terminate:
                try:
                    ipc.send(cmd.fileno(), ipc.CLOSE)
                except OSError:
                    pass
        if self._local is not None:
            self._local.close()
            self._local = None
        for proc, _, _ in self._workers.values():
            proc.join(max(0.0, deadline - time.monotonic()))
        for proc, _, _ in self._workers.values():
            if proc.is_alive():
                proc.terminate()
                proc.join(1.0)
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
        for proc, cmd, rep in self._workers.values():
            cmd.close()
            rep.close()
            try:
                proc.close()
            except ValueError:      # still running after kill (should not happen): leave it to the OS
                pass
        self._workers = {}
        if self._shm is not None:
            self._v = None
            try:
                self._shm.close()
            except BufferError:     # an array view still exported: unlinking alone frees the name
                pass
            self._shm.unlink()
            self._shm = None

    def close(self, **kwargs) -> None:
        if self.closed:
            return
        try:
            self.close_extras(**kwargs)
        finally:
            self.closed = True

    def __del__(self):
        try:
            if not getattr(self, "closed", True):
                self.close(terminate=False)
        except Exception:  # noqa: BLE001 - nothing to report to during garbage collection
            pass
