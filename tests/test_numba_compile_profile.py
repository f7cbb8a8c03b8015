"""scripts/numba_compile_profile.py: the summary attributes nested compiles to their callers."""

import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "numba_compile_profile.py"


def _load():
    spec = importlib.util.spec_from_file_location("numba_compile_profile", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_exclusive_seconds_leave_out_the_callees_and_count_specialisations():
    # recorded as compiles finish: callees before their caller
    records = [
        {"fn": "pkg.inner", "sig": "(float64,)", "secs": 2.0, "depth": 2, "test": "t1"},
        {"fn": "pkg.middle", "sig": "(float64,)", "secs": 3.0, "depth": 1, "test": "t1"},
        {"fn": "pkg.helper", "sig": "(int64,)", "secs": 0.5, "depth": 1, "test": "t1"},
        {"fn": "pkg.outer", "sig": "(float64,)", "secs": 5.0, "depth": 0, "test": "t1"},
        {"fn": "pkg.middle", "sig": "(Literal[bool](True),)", "secs": 1.0, "depth": 0, "test": "t2"},
    ]
    text = _load().summarise(records)
    lines = text.splitlines()
    assert lines[0].startswith("6.0 s in 2 top-level compiles (5 with the nested ones)")
    rows = {line.split()[-1]: (float(line.split()[0]), int(line.split()[1])) for line in lines[2:]}
    assert rows["pkg.outer"] == (1.5, 1)          # 5 - (3 + 0.5): the grandchild is the middle's
    assert rows["pkg.middle"] == (2.0, 2)         # (3 - 2) + 1, two specialisations
    assert rows["pkg.inner"] == (2.0, 1)
    assert rows["pkg.helper"] == (0.5, 1)
