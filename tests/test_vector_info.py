"""InfoWriter (surgsim_envs/vector/info.py), the worker side of the vector env's numeric
infos: a layout seen before is written by a plan (one gather, one numpy assignment); whatever
the previous write of the same row left (a key the new layout lacks) must read absent and 0.
The end-to-end comparison with SyncVectorEnv is in tests/test_vector_env.py."""

from __future__ import annotations

import numpy as np

from surgsim_envs.vector.info import InfoWriter


def _numeric_leaves(info, slots, path=()):
    out = {}
    for k, v in info.items():
        if isinstance(v, dict):
            out.update(_numeric_leaves(v, slots[k], path + (k,)))
        elif isinstance(v, (bool, int, float, np.number)):
            out[slots[k]] = float(v)
    return out


def test_writer_plans_clear_what_the_previous_layout_left():
    """Layouts whose slots are 0..n-1 (a prefix) and ones with gaps, nested dicts, non-numeric
    entries and a value whose type changes, in an order that makes each follow each: after every
    write the row holds exactly the info's numbers at their slots, the rest 0 and absent."""
    layouts = [
        lambda k: {"a": k, "b": 0.5 * k, "c": k % 2 == 0, "d": np.float32(k / 4), "s": "text"},
        lambda k: {"a": k, "b": 0.5 * k, "c": True, "s": "text"},                 # a prefix of slots
        lambda k: {"a": k, "c": False, "d": np.float32(k), "s": None},             # gaps, other type
        lambda k: {"b": -1.0 * k, "n": {"x": 1.5 * k, "y": k}, "a": k},            # nested, new order
        lambda k: {"a": k, "b": 0.5 * k, "c": True, "s": [k]},
    ]
    order = [0, 1, 0, 2, 0, 3, 1, 2, 3, 0, 1, 4, 2, 4, 3, 3, 1, 0, 2, 2, 0]
    writer = InfoWriter(8, keep_other=True)
    values, present = np.full(8, 7.0), np.ones(8, dtype=bool)
    for k, which in enumerate(order, start=1):
        info = layouts[which](k)
        other = writer.write(values, present, info)
        want = _numeric_leaves(info, writer.slots)
        assert set(np.flatnonzero(present)) == set(want), (k, which)
        for s, x in want.items():
            assert values[s] == x, (k, which, s)
        assert not values[~present].any(), (k, which)
        assert other == ({"s": info["s"]} if "s" in info else None), (k, which)
    assert len(writer._plans) >= 3, "the layouts were never written by a plan"


def test_a_value_whose_type_alternates_is_written_by_two_plans_not_rebuilt(monkeypatch):
    """Palpation's ``stiffness_estimate_N_per_m`` was a Python float on some steps and a numpy
    float64 on others: a plan per (keys, value types) keeps both layouts on the fast path (no plan
    made after the first two writes) and the row still holds exactly the info's numbers."""
    from surgsim_envs.vector import info as vector_info

    made = []
    real_make = vector_info._WritePlan.make.__func__
    monkeypatch.setattr(vector_info._WritePlan, "make",
                        classmethod(lambda cls, *a, **k: made.append(1) or real_make(cls, *a, **k)))
    writer = InfoWriter(4)
    values, present = np.zeros(4), np.zeros(4, dtype=bool)
    for k in range(10):
        x = 0.25 * k
        info = {"k": x if k % 2 else np.float64(x), "f": 1.0 + k, "terms": {"t": -x}}
        writer.write(values, present, info)
        assert values[:3].tolist() == [x, 1.0 + k, -x] and present[:3].all() and not present[3:].any()
    assert len(made) == 2, f"{len(made)} plans made for two layouts"
