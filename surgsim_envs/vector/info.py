"""Numeric info entries through shared memory, for :class:`~surgsim_envs.vector.SurgSimVectorEnv`.

A worker writes each env's numeric info entries (Python ``bool``/``int``/``float`` and numpy
scalars, also inside nested dicts such as ``reward_terms``) into its row of a
``(num_envs, max_info_keys)`` float64 table plus a presence mask (:class:`InfoWriter`). Slots are
numbered per worker in the order keys are first seen; a new key is announced once, in that
step's reply. An info dict whose keys and value types match one seen before is written by a
plan (:class:`_WritePlan`: one ``itemgetter`` per dict level, one numpy assignment). The main process (:class:`InfoMerger`) maps every worker's slots to one key list
and builds Gymnasium's info dict (``info[key]`` an array over envs, ``info["_key"]`` the mask of
envs that returned it, nested dicts likewise) with a few numpy operations per step, not a Python
merge per key and env. Values are stored as float64 and cast back to the type the key had when
first seen (float64, int64, bool, float32, ...): exact for floats, bools and integers below 2**53.

Other entries (strings, lists, None, arrays) are not in the table: with ``keep_other`` they are
pickled through the pipe and merged with Gymnasium's ``VectorEnv._add_info``, as
AsyncVectorEnv does for every entry.
"""

from __future__ import annotations

from operator import itemgetter
from typing import NamedTuple

import numpy as np

from surgsim_envs.errors import ConfigError

_SCALARS = frozenset({float, int, bool, np.float64, np.float32, np.int64, np.int32, np.bool_})
_NP_SCALARS = (np.number, np.bool_)


def is_numeric(v) -> bool:
    return type(v) in _SCALARS or isinstance(v, _NP_SCALARS)


class InfoWriter:
    """Worker side: writes info dicts into shared-memory rows; collects new slots and other entries.

    ``keys``: None = every entry; a tuple = only these top-level keys (``()``: none).
    ``keep_other``: also return the non-numeric entries (to be pickled)."""

    def __init__(self, max_keys: int, keys=None, keep_other: bool = False):
        self.max_keys = int(max_keys)
        self.keys = None if keys is None else tuple(keys)
        self.keep_other = bool(keep_other)
        self.slots: dict = {}
        self.count = 0
        self.new: list = []          # (slot, path, dtype str) not yet announced
        self._plans: dict = {}       # (top-level keys, their value types) -> _WritePlan (see write)

    def write(self, values, present, info: dict):
        """Fill one env's row (``values``/``present`` are 1-D views; entries not in ``info`` read 0
        and absent); return the other entries or None.

        An info dict with the same keys and value types as one seen before (every step of a task,
        as a rule) takes a plan made from that one: its numeric values gathered with one
        ``itemgetter`` per dict level and written with one numpy assignment. Anything else (a new
        key, a key missing, a value whose type changed) takes the general path, which assigns
        slots to new keys."""
        if self.keys is not None:
            if not self.keys:
                return None
            info = {k: info[k] for k in self.keys if k in info}
        layout = (tuple(info), tuple(map(type, info.values())))
        plan = self._plans.get(layout)
        if plan is not None:
            vals = plan.gather(info)
            if vals is not None:
                if plan.contiguous:
                    values[:plan.n] = vals
                    present[:plan.n] = True
                    if self.count > plan.n:
                        values[plan.n:self.count] = 0.0
                        present[plan.n:self.count] = False
                else:
                    values[:self.count] = 0.0
                    values[plan.slots] = vals
                    present[:self.count] = plan.mask[:self.count]
                return plan.other(info) if self.keep_other else None
        present[:] = False
        values[:] = 0.0
        other = self._write(values, present, info, self.slots, ())
        if len(self._plans) < _MAX_PLANS:
            plan = _WritePlan.make(info, self.slots, self.max_keys, self.keep_other)
            if plan is not None:
                self._plans[layout] = plan
        return other

    def _write(self, values, present, info, slots, path):
        other = None
        for key, v in info.items():
            if type(v) in _SCALARS or isinstance(v, _NP_SCALARS):
                s = slots.get(key)
                if s is None:
                    s = self._new_slot(slots, path + (key,), v)
                if type(s) is int:
                    values[s] = v
                    present[s] = True
                    continue
            elif type(v) is dict:
                sub = slots.get(key)
                if sub is None:
                    sub = slots[key] = {}
                if type(sub) is dict:
                    o = self._write(values, present, v, sub, path + (key,))
                    if o:
                        other = other or {}
                        other[key] = o
                    continue
            if self.keep_other:     # non-numeric, or a key whose kind changed between steps
                other = other or {}
                other[key] = v
        return other

    def _new_slot(self, slots, path, v) -> int:
        if self.count >= self.max_keys:
            raise ConfigError(
                f"info entry {'/'.join(map(str, path))!r} needs numeric info slot {self.count + 1}, but "
                f"max_info_keys={self.max_keys}: pass a larger max_info_keys= to make_vec, or info_keys=(...) "
                "naming the entries you need")
        s = slots[path[-1]] = self.count
        self.count += 1
        self.new.append((s, path, np.asarray(v).dtype.str))
        return s

    def take_new(self) -> list:
        new, self.new = self.new, []
        return new


#: info layouts a writer keeps a plan for (a task has one or two: its step's and its reset's)
_MAX_PLANS = 8


class _WritePlan:
    """How to write an info dict of one layout (keys and value types at every level) fast:
    ``gather(info)`` returns its numeric values in slot order, or None if ``info`` does not have
    this layout; ``other(info)`` its non-numeric entries (nested as in ``info``) or None."""

    __slots__ = ("keys", "types", "get", "nested", "other_keys", "slots", "n", "contiguous", "mask")

    @classmethod
    def make(cls, info: dict, slots: dict, max_keys: int, keep_other: bool):
        """The plan for ``info``'s layout, with the writer's ``slots``; None if some numeric entry
        has no slot (a key whose kind changed, sent as an other entry by the general path)."""
        plan = cls()
        order: list = []
        if not plan._build(info, slots, order, keep_other):
            return None
        plan.slots = np.asarray(order, dtype=np.intp)
        plan.n = len(order)
        plan.contiguous = order == list(range(len(order)))
        plan.mask = np.zeros(max_keys, dtype=bool)
        plan.mask[plan.slots] = True
        return plan

    def _build(self, info, slots, order, keep_other) -> bool:
        self.keys = tuple(info)
        self.types = tuple(map(type, info.values()))
        numeric, nested, self.nested, self.other_keys = [], [], [], []
        for key, v in info.items():
            s = slots.get(key)
            if is_numeric(v):
                if type(s) is not int:
                    return False
                numeric.append(key)
                order.append(s)
            elif type(v) is dict and type(s) is dict:
                nested.append((key, v, s))
            elif keep_other:
                self.other_keys.append(key)
        for key, v, s in nested:            # after this level's numbers: the order gather returns
            sub = _WritePlan()
            if not sub._build(v, s, order, keep_other):
                return False
            self.nested.append((key, sub))
        self.get = (lambda d: ()) if not numeric else (
            (lambda d, k=numeric[0]: (d[k],)) if len(numeric) == 1 else itemgetter(*numeric))
        return True

    def gather(self, info: dict):
        if tuple(info) != self.keys or tuple(map(type, info.values())) != self.types:
            return None
        vals = self.get(info)
        for key, sub in self.nested:
            more = sub.gather(info[key])
            if more is None:
                return None
            vals += more
        return vals

    def other(self, info: dict):
        out = {k: info[k] for k in self.other_keys}
        for key, sub in self.nested:
            o = sub.other(info[key])
            if o:
                out[key] = o
        return out or None


class InfoMerger:
    """Main side: one key list over all workers; builds the vector info dict from the table."""

    def __init__(self, num_envs: int, ranges):
        self.num_envs = int(num_envs)
        self.ranges = list(ranges)                  # (lo, hi) env rows per worker
        self.paths: list = []                       # global slot -> key path
        self.dtypes: list = []
        self.index: dict = {}                       # key path -> global slot
        self.local = [[] for _ in self.ranges]      # per worker: local slot -> global slot
        self._plan = None

    def announce(self, worker: int, new) -> None:
        loc = self.local[worker]
        for slot, path, dtype in new:
            path = tuple(path)
            g = self.index.get(path)
            if g is None:
                g = self.index[path] = len(self.paths)
                self.paths.append(path)
                self.dtypes.append(np.dtype(dtype))
            while len(loc) <= slot:
                loc.append(-1)
            loc[slot] = g
        self._plan = None

    def _build_plan(self):
        self._identity = all(loc == list(range(len(loc))) for loc in self.local)
        self._gidx = [np.asarray(loc, dtype=np.intp) for loc in self.local]
        # global slots sorted by dtype: each dtype is one contiguous block of rows, cast at once
        order = sorted(range(len(self.paths)), key=lambda g: self.dtypes[g].str)
        self._order = np.asarray(order, dtype=np.intp)
        self._blocks, where, start = [], {}, 0
        for k, g in enumerate(order):
            where[g] = k
            if k + 1 == len(order) or self.dtypes[order[k + 1]] != self.dtypes[g]:
                dt = self.dtypes[g]
                self._blocks.append((start, k + 1, None if dt == np.float64 else dt))
                start = k + 1
        tree: dict = {}
        for g, path in enumerate(self.paths):
            node = tree
            for key in path[:-1]:
                node = node.setdefault(key, {})
                if not isinstance(node, dict):       # a leaf and a dict under one key: keep the leaf
                    break
            else:
                node.setdefault(path[-1], g)

        def plan(node):
            out = []
            for key, v in node.items():
                if isinstance(v, dict):
                    rows = np.asarray([where[g] for g in _leaves(v)], dtype=np.intp)
                    out.append((key, "_" + key, None, plan(v), rows))
                else:
                    out.append((key, "_" + key, where[v], None, None))
            leaves = [(key, mkey, k) for key, mkey, k, sub, _ in out if sub is None]
            ks = tuple(k for _, _, k in leaves)
            get = (lambda rows: ()) if not ks else (
                (lambda rows, k=ks[0]: (rows[k],)) if len(ks) == 1 else itemgetter(*ks))
            nested = [(key, mkey, sub, rows) for key, mkey, _, sub, rows in out if sub is not None]
            return _Level(out, tuple(key for key, _, _ in leaves), tuple(m for _, m, _ in leaves), get, nested)

        self._plan = plan(tree)

    def merge(self, values, present, rows=None) -> dict:
        """The info dict from the shared table ``values``/``present`` (``(num_envs, K)``; a worker
        zeroes the values of entries its env did not return). ``rows``: only these envs."""
        if not self.paths:
            return {}
        if self._plan is None:
            self._build_plan()
        n_keys = len(self.paths)
        if rows is None and self._identity and present[:, :n_keys].all():
            # every env returned every key (the usual step): no per-key masks to compute
            vals = values.T[self._order]             # (keys, envs), rows in dtype order, a copy
            value_rows = []
            for a, b, dt in self._blocks:
                value_rows.extend(vals[a:b] if dt is None else vals[a:b].astype(dt))
            return _fill_full(self._plan, value_rows, list(np.ones((n_keys, self.num_envs), dtype=bool)),
                              self.num_envs)
        if self._identity:
            vals = values.T[self._order]             # (keys, envs), rows in dtype order, a copy
            pres = present.T[self._order]
        else:
            vals = np.zeros((n_keys, self.num_envs))
            pres = np.zeros((n_keys, self.num_envs), dtype=bool)
            for (lo, hi), gidx in zip(self.ranges, self._gidx):
                if len(gidx):
                    vals[gidx, lo:hi] = values[lo:hi, :len(gidx)].T
                    pres[gidx, lo:hi] = present[lo:hi, :len(gidx)].T
            vals, pres = vals[self._order], pres[self._order]
        if rows is not None:
            pres[:, ~rows] = False
            vals[:, ~rows] = 0.0
        value_rows = []
        for a, b, dt in self._blocks:
            value_rows.extend(vals[a:b] if dt is None else vals[a:b].astype(dt))
        any_present = pres.any(axis=1)
        if any_present.all():       # every key returned by some env (the usual step): no per-key test
            return _fill_all(self._plan, value_rows, list(pres), pres)
        return _fill(self._plan, value_rows, list(pres), pres, any_present.tolist())


def _leaves(node) -> list:
    out = []
    for v in node.values():
        out.extend(_leaves(v) if isinstance(v, dict) else [v])
    return out


class _Level(NamedTuple):
    """One dict level of the info plan: ``entries`` ``(key, "_key", row, sub-level or None, leaf rows)``;
    its leaves' keys, mask keys and row getter; its nested dicts ``(key, "_key", level, leaf rows)``."""
    entries: list
    keys: tuple
    mask_keys: tuple
    get: object
    nested: list


def _fill_all(level, value_rows, mask_rows, pres) -> dict:
    out = dict(zip(level.keys, level.get(value_rows)))
    out.update(zip(level.mask_keys, level.get(mask_rows)))
    for key, mkey, sub, leaves in level.nested:
        out[key] = _fill_all(sub, value_rows, mask_rows, pres)
        out[mkey] = pres[leaves].any(axis=0)
    return out


def _fill_full(level, value_rows, mask_rows, n) -> dict:
    out = dict(zip(level.keys, level.get(value_rows)))
    out.update(zip(level.mask_keys, level.get(mask_rows)))
    for key, mkey, sub, _ in level.nested:
        out[key] = _fill_full(sub, value_rows, mask_rows, n)
        out[mkey] = np.ones(n, dtype=bool)
    return out


def _fill(level, value_rows, mask_rows, pres, any_present) -> dict:
    out = {}
    for key, mask_key, k, sub, leaves in level.entries:
        if sub is None:
            if any_present[k]:
                out[key] = value_rows[k]
                out[mask_key] = mask_rows[k]
        else:
            mask = pres[leaves].any(axis=0)
            if mask.any():
                out[key] = _fill(sub, value_rows, mask_rows, pres, any_present)
                out[mask_key] = mask
    return out
