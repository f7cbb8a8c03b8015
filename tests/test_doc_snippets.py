"""The ```python blocks of README.md and docs/*.md run as written.

Each block runs in a fresh interpreter (this tree first on ``PYTHONPATH``) from an empty temporary
directory, with a timeout. A block's first line may carry one marker comment:

- ``# doc-test: skip (REASON)``: never run here (needs an optional extra, a display, or is an
  illustration with names the reader supplies); the reason is required;
- ``# doc-test: slow (REASON)``: runs only with ``-m slow`` (a long computation);
- ``# doc-test: continues``: a fragment that continues the previous block of the same file; it runs
  after that block, in the same interpreter.
"""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
FILES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "models").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
MARKER = re.compile(r"#\s*doc-test:\s*(\w+)(?:\s*\((.*)\))?\s*$")
TIMEOUT_S = 240


def _blocks():
    """(file, index, code to run, marker, reason) for every block; continuations are joined."""
    out = []
    for path in FILES:
        prev = None
        for i, code in enumerate(BLOCK.findall(path.read_text())):
            first = code.splitlines()[0] if code.strip() else ""
            m = MARKER.match(first.strip())
            kind, reason = (m.group(1), (m.group(2) or "").strip()) if m else (None, "")
            if kind == "continues":
                if prev is None:
                    raise AssertionError(f"{path.name} block {i}: '# doc-test: continues' has no block before it")
                code = prev[2] + "\n" + code
                kind, reason = prev[3], prev[4]
            entry = (path, i, code, kind, reason)
            out.append(entry)
            prev = entry
    return out


BLOCKS = _blocks()


def _param(entry):
    path, i, _, kind, reason = entry
    marks = [pytest.mark.slow] if kind == "slow" else []
    return pytest.param(entry, id=f"{path.relative_to(ROOT)}#{i}", marks=marks)


def test_markers_are_known_and_skips_say_why():
    for path, i, _, kind, reason in BLOCKS:
        where = f"{path.relative_to(ROOT)} block {i}"
        assert kind in (None, "skip", "slow"), f"{where}: unknown doc-test marker {kind!r} (skip, slow, continues)"
        if kind in ("skip", "slow"):
            assert reason, f"{where}: '# doc-test: {kind}' needs a reason in brackets"


def test_the_readme_has_a_block_that_runs():
    assert any(p.name == "README.md" and kind is None for p, _, _, kind, _ in BLOCKS)


@pytest.mark.parametrize("entry", [_param(e) for e in BLOCKS])
def test_block_runs_as_written(entry, tmp_path):
    path, i, code, kind, reason = entry
    if kind == "skip":
        pytest.skip(reason)
    script = tmp_path / "snippet.py"
    script.write_text(code)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))
    env.setdefault("MUJOCO_GL", "egl")
    try:
        proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{path.relative_to(ROOT)} block {i} ran longer than {TIMEOUT_S} s (mark it '# doc-test: slow (...)')")
    assert proc.returncode == 0, (f"{path.relative_to(ROOT)} block {i} failed as written:\n{code}\n"
                                  f"--- stderr ---\n{proc.stderr[-4000:]}")
