"""``surgsim bench soak --workers/--out/--resume``: the split, the seeds, the merge,
checkpoints and resuming. Tiny step counts: the long soak is a benchmark, not a test."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from surgsim_envs.bench.soak import soak
from surgsim_envs.bench.soak_parallel import (
    load_state,
    markdown_table,
    merge_rows,
    run_parallel,
    segment_seed,
    split_steps,
    write_json,
)
from surgsim_envs.errors import ConfigError

from test_soak import _Faulty

PALPATION = "SurgSim/Palpation-v0"


def _faulty_counts(n: int) -> dict:
    """What _Faulty does in n steps of one fresh env (see test_soak)."""
    ks = np.arange(1, n + 1)
    raised, unstable = ks % 7 == 0, (ks % 13 == 0) & (ks % 7 != 0)
    ok = ~raised & ~unstable
    return {"exceptions": int(raised.sum()), "unstable": int(unstable.sum()), "nan": int((ok & (ks % 5 == 0)).sum()),
            "force_out_of_bounds": int((ok & (ks % 11 == 0)).sum())}


def test_split_steps_sums_and_balances():
    for total, workers in ((1_000_000, 3), (10, 4), (3, 5), (7, 1), (0, 2)):
        sizes = split_steps(total, workers)
        assert sum(sizes) == total and all(s > 0 for s in sizes)
        assert len(sizes) == min(total, workers)
        assert not sizes or max(sizes) - min(sizes) <= 1
    for bad in ((10, 0), (10, 2.0), (-1, 2), (True, 2)):
        with pytest.raises(ConfigError, match="must be an integer"):
            split_steps(*bad)


def test_segment_seeds_are_distinct_and_reproducible():
    seeds = [segment_seed(14, k) for k in range(2000)]
    assert len(set(seeds)) == len(seeds)
    assert segment_seed(14, 3) == seeds[3] and segment_seed(15, 3) != seeds[3]


def test_merge_sums_the_counts_of_real_segments_exactly():
    if "SurgSimTest/Faulty-v0" not in gym.registry:
        gym.register("SurgSimTest/Faulty-v0", entry_point=_Faulty, disable_env_checker=True)
    sizes = [301, 157, 90]
    rows = [soak("SurgSimTest/Faulty-v0", n, seed=segment_seed(0, k), sample_every=50) for k, n in enumerate(sizes)]
    total = merge_rows("SurgSimTest/Faulty-v0", rows, steps_requested=600)
    expect = [_faulty_counts(n) for n in sizes]
    assert total["steps"] == sum(sizes) and total["segments"] == 3 and not total["complete"]
    for key in ("exceptions", "unstable", "nan", "force_out_of_bounds"):
        assert total[key] == sum(e[key] for e in expect), key
    assert total["exception_types"] == {"step:ValueError": sum(e["exceptions"] for e in expect)}
    assert total["failures"] == sum(total[k] for k in ("nan", "exceptions", "unstable", "obs_out_of_space",
                                                        "force_out_of_bounds"))
    assert total["max_peak_force_N"] == 0.5  # the 1 kN steps are out of bounds, not a peak
    assert total["rss_growth_mb_max"] == max(r["rss_growth_mb"] for r in rows)
    assert len(total["rss_end_mb"]) == 3


def test_docs_table_from_an_out_file(tmp_path):
    if "SurgSimTest/Faulty-v0" not in gym.registry:
        gym.register("SurgSimTest/Faulty-v0", entry_point=_Faulty, disable_env_checker=True)
    rows = [soak("SurgSimTest/Faulty-v0", n, seed=segment_seed(0, k)) for k, n in enumerate((60, 40))]
    out = tmp_path / "soak.json"
    write_json(out, {"tasks": {"SurgSimTest/Faulty-v0": {"segments": rows}}})
    table = markdown_table(load_state(out))
    expect = [_faulty_counts(60), _faulty_counts(40)]
    row = table.splitlines()[2].split(" | ")
    assert row[0] == "| SurgSimTest/Faulty-v0" and row[1] == "100" and row[2] == "2"
    assert row[4] == str(sum(e["nan"] for e in expect)) and row[5] == str(sum(e["exceptions"] for e in expect))
    assert row[8] == str(sum(e["force_out_of_bounds"] for e in expect))


def test_checkpoints_report_the_counts_so_far():
    if "SurgSimTest/Faulty-v0" not in gym.registry:
        gym.register("SurgSimTest/Faulty-v0", entry_point=_Faulty, disable_env_checker=True)
    seen = []
    row = soak("SurgSimTest/Faulty-v0", 100, seed=1, checkpoint=seen.append, checkpoint_every=40)
    assert [r["steps"] for r in seen] == [40, 80]
    assert seen[0]["nan"] == _faulty_counts(40)["nan"] and seen[1]["exceptions"] == _faulty_counts(80)["exceptions"]
    assert row["steps"] == 100


@pytest.mark.slow  # four spawned workers each import MuJoCo and the tissue models: ~40 s on 2 loaded cores
def test_parallel_soak_splits_merges_and_resumes(tmp_path):
    out = tmp_path / "soak.json"
    rows = run_parallel([PALPATION], 30, seed=3, workers=2, out=out, checkpoint_every=5, progress=False)
    state = json.loads(out.read_text())
    segs = state["tasks"][PALPATION]["segments"]
    assert sorted(s["steps"] for s in segs) == [15, 15]
    assert {s["seed"] for s in segs} == {segment_seed(3, 0), segment_seed(3, 1)}
    assert rows[0]["steps"] == 30 and rows[0]["complete"] and rows[0]["failures"] == 0
    assert not (tmp_path / "soak.json.parts").exists()
    with pytest.raises(ConfigError, match="--resume"):
        run_parallel([PALPATION], 30, seed=3, workers=2, out=out, progress=False)
    # a killed run left a part file (a third segment's checkpoint): resume counts it, then runs
    # only what is missing, with a seed no segment used
    parts = tmp_path / "soak.json.parts"
    parts.mkdir()
    extra = dict(segs[0], seed=segment_seed(3, 2), steps=7, steps_requested=20)
    (parts / "x.json").write_text(json.dumps(extra))
    assert sum(s["steps"] for s in load_state(out)["tasks"][PALPATION]["segments"]) == 37
    rows = run_parallel([PALPATION], 45, seed=3, workers=2, out=out, resume=True, progress=False)
    segs = json.loads(out.read_text())["tasks"][PALPATION]["segments"]
    assert rows[0]["steps"] == 45 and rows[0]["complete"]
    assert sorted(s["steps"] for s in segs) == [4, 4, 7, 15, 15]  # 45 - 37 = 8 over two workers
    assert len({s["seed"] for s in segs}) == 5


def test_resume_rejects_a_file_that_is_not_a_soak(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text("[1, 2]")
    with pytest.raises(ConfigError, match="no 'tasks' table"):
        run_parallel([PALPATION], 10, out=bad, resume=True, progress=False)
    with pytest.raises(ConfigError, match="does not exist"):
        run_parallel([PALPATION], 10, out=tmp_path / "nope" / "x.json", progress=False)
