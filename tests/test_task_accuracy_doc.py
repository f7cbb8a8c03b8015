"""The published task-accuracy tables (docs/task_accuracy.md) are the shipped table's, block by block."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.bench.task_accuracy_doc import BEGIN, END, task_block
from surgsim_envs.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "task_accuracy.md"
TABLE = ROOT / "surgsim_envs" / "tissue" / "data" / "task_accuracy_table.json"


@pytest.fixture(scope="module")
def table() -> dict:
    return json.loads(TABLE.read_text())


def _block(text: str, task: str) -> str:
    start = text.index(BEGIN.format(task=task))
    return text[start:text.index(END, start)]


def _row(block: str, model: str, spacing_mm: str) -> list[str]:
    for line in block.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[:2] == [model, spacing_mm]:
            return cells
    raise AssertionError(f"no row {model} {spacing_mm} mm in the block")


def test_the_published_tables_are_the_shipped_tables(table):
    """Every task of the shipped table has its block in docs/task_accuracy.md, and each block reads
    exactly what the table renders to: regenerate with ``surgsim bench task-accuracy --render
    surgsim_envs/tissue/data/task_accuracy_table.json --doc docs/task_accuracy.md``."""
    text = DOC.read_text()
    assert ta.update_doc(text, table) == text


def test_each_block_holds_only_its_own_tasks_rows(table):
    """Two tasks measured at the same model and spacing keep their own rows: fem_static at 5 mm reads
    the shipped Palpation-v0 error in Palpation-v0's block and LayeredPalpation-v0's in its own."""
    text = ta.update_doc(DOC.read_text(), table)
    for task in ("SurgSim/Palpation-v0", "SurgSim/LayeredPalpation-v0"):
        row = next(r for r in table["rows"] if r["task"] == task and r["model"] == "fem_static" and r["spacing"] == 0.005)
        cells = _row(_block(text, task), "fem_static", "5")
        assert cells[2] == str(row["nodes"])
        assert cells[4] == f"{100 * row['error_p95']:.1f}"
    palpation = _row(_block(text, "SurgSim/Palpation-v0"), "fem_static", "5")
    layered = _row(_block(text, "SurgSim/LayeredPalpation-v0"), "fem_static", "5")
    assert palpation[4] != layered[4]


def test_grasp_and_pull_blocks_carry_their_own_columns(table):
    """Closures and pulls are not presses: their blocks name their readings' columns, not a press's."""
    grasp = task_block(table, "SurgSim/Grasp-v0")
    pull = task_block(table, "SurgSim/Slippage-v0")
    assert "sum N rises with closure" in grasp and "contrast (ref)" not in grasp
    assert "motor held / (mu sum N)" in pull and "rises with depth" not in pull
    row = next(r for r in table["rows"] if r["task"] == "SurgSim/Slippage-v0" and r["model"] == "fem_static"
               and r["spacing"] == 0.011)
    cells = _row(pull, "fem_static", "11")
    assert cells[5] == ", ".join(f"{v['held_ratio']:.2f}" for v in row["held_ratio"].values())


def test_a_page_without_a_tasks_markers_is_refused_with_the_lines_to_add(table):
    with pytest.raises(ConfigError, match=r"no block for SurgSim/Grasp-v0.*task-accuracy table: SurgSim/Grasp-v0"):
        ta.update_doc("# a page\n", {**table, "references": {"SurgSim/Grasp-v0": table["references"]["SurgSim/Grasp-v0"]}})


def test_the_cli_refuses_a_page_without_markers_before_it_runs(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# no markers here\n")
    args = SimpleNamespace(tasks="SurgSim/Grasp-v0", models=None, quick=False, spacings=None, out=str(tmp_path / "out"),
                           json=False, rescore=None, render=None, doc=str(page))
    with pytest.raises(ConfigError, match="no block for SurgSim/Grasp-v0"):
        ta.run(args)
    assert not (tmp_path / "out").exists()


def test_render_rewrites_the_blocks_of_a_stored_table_without_running(tmp_path, table):
    page = tmp_path / "page.md"
    stale = "\n".join(f"{BEGIN.format(task=t)}\nstale\n{END}" for t in table["references"]) + "\n"
    page.write_text("# page\n\n" + stale)
    args = SimpleNamespace(tasks=",".join(table["references"]), models=None, quick=False, spacings=None,
                           out=str(tmp_path / "out"), json=False, rescore=None, render=str(TABLE), doc=str(page))
    assert ta.run(args) == 0
    text = page.read_text()
    assert "stale" not in text and ta.update_doc(text, table) == text
    assert (tmp_path / "out" / "task_accuracy.png").stat().st_size > 0


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", '{"rows": []}'])
def test_render_refuses_a_file_that_is_not_a_table(tmp_path, text):
    bad = tmp_path / "table.json"
    bad.write_text(text)
    args = SimpleNamespace(tasks="SurgSim/Grasp-v0", models=None, quick=False, spacings=None, out=str(tmp_path / "out"),
                           json=False, rescore=None, render=str(bad), doc=None)
    with pytest.raises(ConfigError, match=r"--render=.*table\.json.*give a task_accuracy\.json this command wrote"):
        ta.run(args)
