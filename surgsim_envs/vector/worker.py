"""The worker process of :class:`~surgsim_envs.vector.SurgSimVectorEnv`: hosts envs
``lo..hi-1`` of the vector, reads their actions from shared memory, steps them, writes
observations, rewards, terminations, truncations and numeric infos back, and answers each
command with one byte (or a short pickled message: new info keys, non-numeric infos, call
results, an error). Protocol and layout: :mod:`surgsim_envs.vector.ipc`."""

from __future__ import annotations

import os
import pickle
import select
import signal
import time
import traceback

import numpy as np

from surgsim_envs.vector import ipc
from surgsim_envs.vector.info import InfoWriter
from surgsim_envs.vector.parent import PARENT_POLL_S, follow_parent, parent_alive

NEXT_STEP, SAME_STEP, DISABLED = "NextStep", "SameStep", "Disabled"


class _Worker:
    """Envs ``lo..hi-1`` and what a worker does with them (also used in the main process for the
    ``in_main`` block)."""

    def __init__(self, env_id, env_kwargs, lo, hi, autoreset, info_keys, keep_other, max_info_keys):
        import gymnasium as gym   # the package root registers the SurgSim tasks once it loads

        self.lo, self.hi, self.autoreset = lo, hi, autoreset
        make = (lambda: gym.make(env_id, **env_kwargs)) if isinstance(env_id, str) else (lambda: env_id(**env_kwargs))
        self.envs = [make() for _ in range(hi - lo)]
        self.writer = InfoWriter(max_info_keys, info_keys, keep_other)
        self.ended = [False] * (hi - lo)
        self.shm = self.v = None
        self.current = f"{lo}..{hi - 1}"       # the env an error is reported against

    def description(self) -> dict:
        e = self.envs[0]
        return {"observation_space": e.observation_space, "action_space": e.action_space,
                "metadata": dict(e.metadata), "render_mode": e.render_mode, "pid": os.getpid()}

    def attach(self, name, layout):
        from multiprocessing import shared_memory

        self.shm = shared_memory.SharedMemory(name=name)
        self.v = layout.views(self.shm.buf)
        self.same_step = layout.same_step

    def use_views(self, views, same_step):
        """Work on the main process's own views (a block stepped in the main process)."""
        self.v, self.same_step = views, same_step

    def _reply(self, other, final_other=None):
        new = self.writer.take_new()
        if new or other or final_other:
            return {"new_keys": new, "other": other, "final_other": final_other}
        return None

    def step(self):
        """Step every env of the block in one loop (one reply for all): actions copied out of the
        shared memory once, rewards and flags written once at the end."""
        v, lo, hi, writer = self.v, self.lo, self.hi, self.writer
        acts = v["actions"][lo:hi].copy()       # the envs may keep their action: not a view of shared memory
        obs_buf, vals, pres = v["obs"], v["info_values"], v["info_present"]
        ended, autoreset, same_step = self.ended, self.autoreset, self.same_step
        rews, terms, truncs = [0.0] * (hi - lo), [False] * (hi - lo), [False] * (hi - lo)
        other = final_other = None
        for j, env in enumerate(self.envs):
            i = self.current = lo + j
            if ended[j] and autoreset == NEXT_STEP:
                obs, info = env.reset()
                ended[j] = False
            else:
                if ended[j] and autoreset == DISABLED:
                    raise RuntimeError(
                        f"env {i} was stepped after its episode ended, with autoreset_mode=DISABLED: reset it "
                        f"first (reset(options={{'reset_mask': mask}}) with mask[{i}] True)")
                obs, r, te, tr, info = env.step(acts[j])
                rews[j] = r
                if te or tr:
                    terms[j], truncs[j] = bool(te), bool(tr)
                    if same_step:
                        v["final"][i] = True
                        v["final_obs"][i] = obs
                        o = writer.write(v["final_info_values"][i], v["final_info_present"][i], info)
                        if o:
                            final_other = final_other or {}
                            final_other[i] = o
                        obs, info = env.reset()
                    else:
                        ended[j] = True
                if same_step and not (te or tr):
                    v["final"][i] = False
                    v["final_info_present"][i] = False
                    v["final_info_values"][i] = 0.0
            obs_buf[i] = obs
            o = writer.write(vals[i], pres[i], info)
            if o:
                other = other or {}
                other[i] = o
        v["rewards"][lo:hi] = rews
        v["terminations"][lo:hi] = terms
        v["truncations"][lo:hi] = truncs
        return self._reply(other, final_other)

    def rollout(self, policy, steps, name, layout, seed=None):
        """``steps`` steps of the block with actions from ``policy`` (called on the block's observations,
        ``(envs, *obs shape)`` -> ``(envs, *action shape)``), each exactly as :meth:`step` (autoreset,
        infos), recorded into the rollout's shared memory ``name`` (:class:`~surgsim_envs.vector.ipc.
        RolloutLayout`). ``seed``: the policy (this worker's copy) is first ``reset(seed + lo)``.
        Returns the reply of :meth:`step` with every info key first seen meanwhile."""
        from multiprocessing import shared_memory

        v, lo, hi = self.v, self.lo, self.hi
        if seed is not None:
            policy.reset(seed + lo)
        shm = shared_memory.SharedMemory(name=name)
        try:
            rec = layout.views(shm.buf)
            obs, acts = v["obs"], v["actions"]
            rec["observations"][0, lo:hi] = obs[lo:hi]
            new = []
            for t in range(steps):
                self.current = f"{lo}..{hi - 1}"
                a = np.asarray(policy(obs[lo:hi].copy()))
                if a.shape != acts[lo:hi].shape:
                    raise ValueError(f"the rollout policy returned actions of shape {a.shape} for {hi - lo} "
                                     f"observations; expected {acts[lo:hi].shape}")
                acts[lo:hi] = a
                rec["actions"][t, lo:hi] = acts[lo:hi]
                reply = self.step()
                if reply and reply["new_keys"]:
                    new.extend(reply["new_keys"])
                rec["observations"][t + 1, lo:hi] = obs[lo:hi]
                rec["rewards"][t, lo:hi] = v["rewards"][lo:hi]
                rec["terminations"][t, lo:hi] = v["terminations"][lo:hi]
                rec["truncations"][t, lo:hi] = v["truncations"][lo:hi]
            rec = None                          # no view may outlive the mapping
        finally:
            shm.close()
        return {"new_keys": new, "other": None, "final_other": None} if new else None

    def reset(self, seeds, options, mask):
        v, other = self.v, None
        for j, env in enumerate(self.envs):
            i = self.current = self.lo + j
            v["info_present"][i] = False
            v["info_values"][i] = 0.0
            if self.same_step:
                v["final"][i] = False
                v["final_info_present"][i] = False
                v["final_info_values"][i] = 0.0
            if mask is not None and not mask[j]:
                continue
            obs, info = env.reset(seed=seeds[j], options=options)
            v["obs"][i] = obs
            v["terminations"][i] = v["truncations"][i] = False
            v["rewards"][i] = 0.0
            self.ended[j] = False
            o = self.writer.write(v["info_values"][i], v["info_present"][i], info)
            if o:
                other = other or {}
                other[i] = o
        return self._reply(other)

    def call(self, name, args, kwargs, which=None):
        """``name(*args, **kwargs)`` (or the attribute) of each env, or of the local envs ``which``."""
        out = []
        for j in range(len(self.envs)) if which is None else which:
            self.current = self.lo + j
            f = self.envs[j].get_wrapper_attr(name)
            out.append(f(*args, **kwargs) if callable(f) else f)
        return out

    def set_attr(self, name, values, which=None):
        for j, value in zip(range(len(self.envs)) if which is None else which, values):
            self.current = self.lo + j
            self.envs[j].set_wrapper_attr(name, value)

    def close(self):
        for env in self.envs:
            try:
                env.close()
            except Exception:  # noqa: BLE001 - closing must not fail the shutdown
                pass
        if self.shm is not None:
            self.v = None
            self.shm.close()


def _error_payload(exc: BaseException, env_index) -> dict:
    try:
        pickle.dumps(exc)
        picklable = exc
    except Exception:  # noqa: BLE001 - an unpicklable exception is sent as text
        picklable = None
    return {"exception": picklable, "type": type(exc).__name__, "message": str(exc),
            "traceback": traceback.format_exc(), "env": env_index}


def wait_for_command(poller, spin_s: float) -> None:
    """Poll the command pipe (registered in ``poller``) without sleeping for up to ``spin_s`` s,
    yielding the core between polls, so that a command that comes soon is read without a wake-up
    (and the main process's write finds no sleeper to wake). Returns when a command is there or
    the time is up (the caller's blocking read follows)."""
    if poller.poll(0):
        return
    end = time.perf_counter() + spin_s
    while time.perf_counter() < end:
        os.sched_yield()
        if poller.poll(0):
            return


def _orphaned(worker) -> None:
    """The main process died: unlink the shared memory (nobody else will) and exit now."""
    shm = getattr(worker, "shm", None) if worker is not None else None
    if shm is not None:
        try:
            shm.unlink()
        except (FileNotFoundError, OSError):      # another worker unlinked it first
            pass
    os._exit(0)


def worker_main(env_id, env_kwargs, lo, hi, cmd, rep, autoreset, info_keys, keep_other, max_info_keys,
                spin_us: float = 0.0, parent_pid: int | None = None):
    """Process entry point. ``cmd``/``rep``: the worker's ends (``multiprocessing.Connection``,
    used as raw file descriptors) of the command and reply pipes. ``spin_us``: after each reply the
    worker polls for the next command this long before it sleeps (:func:`wait_for_command`).
    ``parent_pid``: the main process; the worker exits when it dies (:mod:`surgsim_envs.vector.parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # Ctrl-C goes to the main process, which closes us
    cfd, rfd = cmd.fileno(), rep.fileno()
    spin_s = float(spin_us) * 1e-6
    poller = select.poll()
    poller.register(cfd, select.POLLIN)
    holder: list = [None]
    signalled = True if parent_pid is None else follow_parent(parent_pid, lambda: _orphaned(holder[0]))
    try:
        worker = holder[0] = _Worker(env_id, env_kwargs, lo, hi, autoreset, info_keys, keep_other, max_info_keys)
        ipc.send(rfd, ipc.OK, worker.description())
    except BaseException as exc:  # noqa: BLE001 - reported to the main process
        ipc.send(rfd, ipc.ERROR, _error_payload(exc, f"{lo}..{hi - 1}"))
        return
    while True:
        try:
            if spin_s:
                wait_for_command(poller, spin_s)
            if not signalled:
                while not poller.poll(PARENT_POLL_S * 1e3):
                    if not parent_alive(parent_pid):
                        _orphaned(worker)
            op, payload = ipc.receive(cfd)
        except (ipc.WorkerGone, OSError):     # the main process is gone
            break
        if op == ipc.CLOSE:
            worker.close()
            try:
                ipc.send_ok(rfd)
            except OSError:
                pass
            break
        worker.current = f"{lo}..{hi - 1}"
        try:
            if op == ipc.STEP:
                out = worker.step()
            elif op == ipc.RESET:
                out = worker.reset(*payload)
            elif op == ipc.ROLLOUT:
                out = worker.rollout(*payload)
            elif op == ipc.CALL:
                out = worker.call(*payload)
            elif op == ipc.SET_ATTR:
                out = worker.set_attr(*payload)
            elif op == ipc.ATTACH:
                out = worker.attach(*payload)
            else:
                raise RuntimeError(f"unknown vector env command {op}")
        except BaseException as exc:  # noqa: BLE001 - reported to the main process
            try:
                ipc.send(rfd, ipc.ERROR, _error_payload(exc, worker.current))
            except OSError:
                break
            continue
        try:
            if out is None:
                ipc.send_ok(rfd)
            else:
                ipc.send(rfd, ipc.OK, out)
        except OSError:
            break
