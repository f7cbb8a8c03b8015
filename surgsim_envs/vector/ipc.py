"""What the main process and the workers of :class:`~surgsim_envs.vector.SurgSimVectorEnv`
share: the shared-memory layout and the pipe protocol.

**Shared memory** (one ``multiprocessing.shared_memory.SharedMemory`` block, :class:`Layout`):
actions, observations, rewards, terminations, truncations and a table of numeric info entries,
one row per env (plus final observations and final infos for ``autoreset_mode=SAME_STEP``).
Each block starts on a 64-byte boundary.

**Pipes** (two ``os.pipe`` per worker: commands in, replies out). Every message is one opcode
byte; bit 7 set means a pickled payload follows, preceded by its length (4 bytes, little endian).
A plain ``step`` is therefore one byte each way: the data travels through shared memory. The
byte pair costs 15-33 us round trip on this 2-core VM against 17-44 us for a pair of
``multiprocessing.Semaphore`` and 48-124 us for ``multiprocessing.Connection.send_bytes``
(1 and 2 workers, CHANGELOG.md "Vector env: shared memory instead of pickled steps"); waiting blocks in
``poll``, so idle processes take no CPU.
"""

from __future__ import annotations

import os
import pickle

import numpy as np

# commands (main -> worker)
STEP, RESET, CALL, SET_ATTR, ATTACH, CLOSE, ROLLOUT = 1, 2, 3, 4, 5, 6, 8
# replies (worker -> main)
OK, ERROR = 0, 7
_PAYLOAD = 0x80
_STEP_BYTE = bytes([STEP])
_OK_BYTE = bytes([OK])

#: numeric info values are stored as float64 (exact for floats, bools and integers below 2**53)
INFO_DTYPE = np.float64
_ALIGN = 64


class WorkerGone(EOFError):
    """The other end of a pipe closed (the worker process exited or was killed)."""


def send(fd: int, op: int, payload=None) -> None:
    """Write one message: the opcode byte, and with a payload its length and pickle."""
    if payload is None:
        data = bytes([op])
    else:
        body = pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)
        data = bytes([op | _PAYLOAD]) + len(body).to_bytes(4, "little") + body
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def send_step(fd: int) -> None:
    os.write(fd, _STEP_BYTE)


def send_ok(fd: int) -> None:
    os.write(fd, _OK_BYTE)


def receive(fd: int):
    """Read one message (blocking): ``(op, payload or None)``. Raises :class:`WorkerGone` on EOF."""
    data = os.read(fd, 65536)
    if not data:
        raise WorkerGone(fd)
    op = data[0]
    if not op & _PAYLOAD:
        return op, None
    while len(data) < 5:
        more = os.read(fd, 5 - len(data))
        if not more:
            raise WorkerGone(fd)
        data += more
    need = 5 + int.from_bytes(data[1:5], "little")
    chunks, have = [data], len(data)
    while have < need:
        more = os.read(fd, min(need - have, 1 << 20))
        if not more:
            raise WorkerGone(fd)
        chunks.append(more)
        have += len(more)
    body = b"".join(chunks)[5:need]
    return op & ~_PAYLOAD, pickle.loads(body)


class _Fields:
    """Named arrays laid out one after another in a buffer, each on a 64-byte boundary; the object
    pickles, so both ends build the same views from it."""

    def _place(self, fields) -> None:
        """``fields``: ``(name, shape, numpy dtype)`` in buffer order."""
        self.fields, offset = [], 0
        for name, shape, dtype in fields:
            offset = -(-offset // _ALIGN) * _ALIGN
            self.fields.append((name, tuple(int(s) for s in shape), dtype.str, offset))
            offset += int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        self.nbytes = max(offset, 1)

    def views(self, buffer) -> dict:
        return {name: np.ndarray(shape, dtype=np.dtype(dtype), buffer=buffer, offset=offset)
                for name, shape, dtype, offset in self.fields}


class Layout(_Fields):
    """Byte offsets of the shared arrays for ``num_envs`` envs (see the module docstring).

    ``views(buffer)`` returns the numpy arrays over a buffer of ``nbytes`` bytes; main process and
    workers build the same views from the same constructor arguments (this object pickles)."""

    def __init__(self, num_envs: int, obs_shape, obs_dtype, act_shape, act_dtype, max_info_keys: int,
                 same_step: bool):
        self.num_envs, self.max_info_keys, self.same_step = int(num_envs), int(max_info_keys), bool(same_step)
        n, k = self.num_envs, self.max_info_keys
        fields = [("actions", (n, *act_shape), np.dtype(act_dtype)),
                  ("obs", (n, *obs_shape), np.dtype(obs_dtype)),
                  ("rewards", (n,), np.dtype(np.float64)),
                  ("terminations", (n,), np.dtype(np.bool_)),
                  ("truncations", (n,), np.dtype(np.bool_)),
                  ("info_values", (n, k), np.dtype(INFO_DTYPE)),
                  ("info_present", (n, k), np.dtype(np.bool_))]
        if same_step:
            fields += [("final", (n,), np.dtype(np.bool_)),
                       ("final_obs", (n, *obs_shape), np.dtype(obs_dtype)),
                       ("final_info_values", (n, k), np.dtype(INFO_DTYPE)),
                       ("final_info_present", (n, k), np.dtype(np.bool_))]
        self._place(fields)


class RolloutLayout(_Fields):
    """Byte offsets of a rollout's record (:meth:`SurgSimVectorEnv.rollout`): for ``steps`` steps of
    ``num_envs`` envs the observations before each step and after the last (``steps + 1`` rows), the
    actions, rewards, terminations and truncations. A shared-memory block of its own per rollout call."""

    def __init__(self, steps: int, num_envs: int, obs_shape, obs_dtype, act_shape, act_dtype):
        t, n = int(steps), int(num_envs)
        fields = [("observations", (t + 1, n, *obs_shape), np.dtype(obs_dtype)),
                  ("actions", (t, n, *act_shape), np.dtype(act_dtype)),
                  ("rewards", (t, n), np.dtype(np.float64)),
                  ("terminations", (t, n), np.dtype(np.bool_)),
                  ("truncations", (t, n), np.dtype(np.bool_))]
        self._place(fields)
