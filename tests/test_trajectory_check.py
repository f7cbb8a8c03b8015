"""``surgsim bench trajectory``: a record compares equal to itself re-recorded in the same tree,
and a one-bit change is found at its path."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from surgsim_envs.bench.trajectory_check import compare, first_difference
from surgsim_envs.cli import main


def test_record_twice_is_bit_for_bit_and_a_flipped_bit_is_found(tmp_path, capsys):
    a, b = tmp_path / "a.pkl", tmp_path / "b.pkl"
    for path in (a, b):
        assert main(["bench", "trajectory", "--record", str(path), "--tasks", "SurgSim/Palpation-v0",
                     "--steps", "3"]) == 0
    assert main(["bench", "trajectory", "--compare", str(a), str(b)]) == 0
    assert "SurgSim/Palpation-v0: bit for bit identical" in capsys.readouterr().out
    rec = pickle.loads(b.read_bytes())
    pos = rec["SurgSim/Palpation-v0"][-1]
    pos[0, 0] = np.nextafter(pos[0, 0], np.inf)          # one ulp on one node
    b.write_bytes(pickle.dumps(rec))
    assert main(["bench", "trajectory", "--compare", str(a), str(b)]) == 1
    last = len(rec["SurgSim/Palpation-v0"]) - 1
    assert f"SurgSim/Palpation-v0: DIFFERENT, first at SurgSim/Palpation-v0[{last}]" in capsys.readouterr().out


def test_first_difference_names_the_path():
    x = {"t": [(np.zeros(2), 1.0, False, {"f": 0.5})]}
    y = {"t": [(np.zeros(2), 1.0, False, {"f": 0.25})]}
    assert first_difference(x, x) is None
    assert first_difference(x, y) == ".t[0][3].f: 0.5 vs 0.25"
    assert first_difference(np.zeros(2, np.float32), np.zeros(2)) is not None      # dtype counts
    assert first_difference(float("nan"), float("nan")) is None
    assert compare({"t": 1}, {"u": 1}) == {"t": "recorded in one file only", "u": "recorded in one file only"}


def test_compare_needs_exactly_one_mode(capsys):
    assert main(["bench", "trajectory"]) == 2
    assert "give exactly one of --record FILE or --compare A B" in capsys.readouterr().err


def test_unreadable_record_is_a_config_error(tmp_path, capsys):
    bad = tmp_path / "bad.pkl"
    bad.write_bytes(b"not a pickle")
    assert main(["bench", "trajectory", "--compare", str(bad), str(bad)]) == 2
    assert "cannot read trajectory record" in capsys.readouterr().err
