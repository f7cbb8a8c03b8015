"""choose(): cheapest model meeting error and cost, clear error otherwise; resolve_resolution()."""

import pytest

from surgsim_envs.tissue.resolution import choose, resolve_resolution
from surgsim_envs.errors import ConfigError

ROWS = [
    {"scene": "indent", "model": "a", "integrator": "x", "spacing": 0.003, "nodes": 100, "error": 0.30, "us_per_ms": 10.0, "dt": 1e-3},
    {"scene": "indent", "model": "a", "integrator": "x", "spacing": 0.001, "nodes": 900, "error": 0.05, "us_per_ms": 400.0, "dt": 1e-3},
    {"scene": "indent", "model": "b", "integrator": "y", "spacing": 0.002, "nodes": 300, "error": 0.08, "us_per_ms": 150.0, "dt": 1e-3},
    {"scene": "indent", "model": "c", "integrator": "z", "spacing": 0.002, "nodes": 300, "error": 0.01, "us_per_ms": 5.0, "baseline": True},
]


def test_picks_cheapest_that_meets_both():
    assert choose(0.1, 1000.0, table=ROWS).model == "b"
    assert choose(0.06, 1000.0, table=ROWS).spacing == 0.001
    assert choose(0.5, 50.0, table=ROWS).model == "a"


def test_none_meets_names_closest():
    with pytest.raises(ConfigError, match="closest: b/y"):
        choose(0.07, 160.0, table=ROWS)


def test_bad_input():
    with pytest.raises(ConfigError):
        choose(-1, 100, table=ROWS)
    with pytest.raises(ConfigError):
        choose(0.1, 100, scene="nope", table=ROWS)


def test_shipped_table_and_resolve_resolution():
    pick = choose(1.0, 1e9)
    assert pick.spacing > 0 and pick.us_per_ms > 0
    model, spacing = resolve_resolution("auto", error_tolerance=1.0, step_budget_us=1e9)
    assert (model, spacing) == (pick.model, pick.spacing)
    assert resolve_resolution(0.004, model="fem") == ("fem", 0.004)
    assert resolve_resolution(None, model="fem") == ("fem", None)
    with pytest.raises(ConfigError):
        resolve_resolution("fine")


# ---------------------------------------------------------------------------------------------
# resolution="auto" in scenes (TissueConfig) — synthetic table so the rule, not the shipped
# numbers, is under test
import json  # noqa: E402

from surgsim_envs.scene import SceneConfig, TissueConfig, build_scene  # noqa: E402

TABLE = {"rows": [
    {"scene": "indent", "model": "mass_spring", "integrator": "symplectic", "spacing": 0.01, "nodes": 50,
     "error": 0.30, "us_per_ms": 50.0, "dt": 1e-3},
    {"scene": "indent", "model": "mass_spring", "integrator": "symplectic", "spacing": 0.005, "nodes": 300,
     "error": 0.10, "us_per_ms": 400.0, "dt": 5e-4},
    {"scene": "indent", "model": "fem", "integrator": "implicit", "spacing": 0.005, "nodes": 300,
     "error": 0.05, "us_per_ms": 3000.0, "dt": 1e-3},
]}


@pytest.fixture
def table(tmp_path):
    path = tmp_path / "accuracy.json"
    path.write_text(json.dumps(TABLE))
    return str(path)


def _scene(table, **kw):
    t = TissueConfig(name="slab", organ="slab", volume_options={"size": (0.04, 0.04, 0.01)}, position=(0, 0, 0.005),
                     options={"integrator": "symplectic"}, accuracy_table=table, **kw)
    return build_scene(SceneConfig(tissues=[t], cameras=[], floor=False))


def test_auto_resolution_tight_budget_is_coarser(table):
    coarse = _scene(table, resolution="auto", error_tolerance=0.5, step_budget_us=100.0)
    fine = _scene(table, resolution="auto", error_tolerance=0.15, step_budget_us=10_000.0)
    assert coarse.config.tissues[0].spacing == 0.01 and fine.config.tissues[0].spacing == 0.005
    assert coarse.resolutions["slab"].us_per_ms <= 100.0
    # the chosen spacing is the one the tissue is built with: the node count follows it
    n_coarse, n_fine = len(coarse.tissues["slab"].positions), len(fine.tissues["slab"].positions)
    assert n_fine > 4 * n_coarse


def test_auto_resolution_can_choose_model_and_integrator(table):
    t = TissueConfig(name="slab", organ="slab", model="auto", resolution="auto", error_tolerance=0.06,
                     step_budget_us=1e4, volume_options={"size": (0.02, 0.02, 0.01)}, accuracy_table=table)
    scene = build_scene(SceneConfig(tissues=[t], cameras=[], floor=False))
    resolved = scene.config.tissues[0]
    assert (resolved.model, resolved.spacing, resolved.options["integrator"]) == ("fem", 0.005, "implicit")
    assert type(scene.tissues["slab"]).__name__ == "TetFEMModel"
    # a fixed integrator restricts the candidates: no symplectic FEM row in the table
    with pytest.raises(ConfigError, match="closest: mass_spring/symplectic"):
        _scene(table, model="auto", resolution="auto", error_tolerance=0.06, step_budget_us=1e4)


def test_auto_resolution_impossible_names_closest(table):
    with pytest.raises(ConfigError, match=r"tissue 'slab'.*closest: mass_spring/symplectic at spacing 10 mm"):
        _scene(table, resolution="auto", error_tolerance=0.2, step_budget_us=40.0)


def test_numeric_resolution_and_bad_values(table):
    a = _scene(table, resolution=0.02)
    b = _scene(table, resolution=0.01)
    assert a.config.tissues[0].spacing == 0.02 and len(a.tissues["slab"].positions) < len(b.tissues["slab"].positions)
    with pytest.raises(ConfigError, match="resolution"):
        _scene(table, resolution="fine")
    with pytest.raises(ConfigError, match="resolution"):
        _scene(table, resolution=-0.01)
    with pytest.raises(ConfigError, match="model='auto'"):
        _scene(table, model="auto")
    with pytest.raises(ConfigError, match="error_tolerance"):
        _scene(table, resolution="auto", error_tolerance=0.0)


def test_auto_resolution_with_shipped_table():
    pick = choose(1.0, 1e9, models=["mass_spring"], integrators=["symplectic"])
    t = TissueConfig(name="slab", organ="slab", resolution="auto", error_tolerance=1.0, step_budget_us=1e9,
                     volume_options={"size": (0.02, 0.02, 0.006)}, options={"integrator": "symplectic"})
    scene = build_scene(SceneConfig(tissues=[t], cameras=[], floor=False))
    assert scene.config.tissues[0].spacing == pick.spacing
    assert scene.resolutions["slab"] == pick


def test_shipped_table_has_fem_static_and_a_tight_tolerance_picks_it():
    """The shipped table (``surgsim bench accuracy --quick``, docs/benchmarks.md) has fem_static rows
    for its three spacings, with fem's force errors (same element, same exact contact). Below the
    error of every cheaper row (layered reaches 3.2 % at 1.3 mm) the cheapest qualifying row is
    fem_static, and ``resolution="auto"`` with ``model="auto"`` builds the quasi-static model."""
    from surgsim_envs.tissue.resolution import load_table

    rows = {(r["model"], r["spacing"]): r for r in load_table()}
    for s in (0.003, 0.002, 0.0013):
        static, fem = rows[("fem_static", s)], rows[("fem", s)]
        assert static["integrator"] == "quasi_static" and static["error"] == pytest.approx(fem["error"], rel=1e-6)
    pick = choose(0.03, 1000.0)
    assert (pick.model, pick.integrator) == ("fem_static", "quasi_static") and pick.error <= 0.03
    assert pick.us_per_ms <= min(r["us_per_ms"] for r in rows.values() if r["error"] <= 0.03 and not r.get("baseline"))
    assert resolve_resolution("auto", error_tolerance=0.03, step_budget_us=1000.0) == ("fem_static", pick.spacing)
    # restricted to the FEM element, fem_static wins at the 5 % target too (fem symplectic costs more)
    assert choose(0.05, 1e6, models=["fem", "fem_static"]).model == "fem_static"
    t = TissueConfig(name="slab", organ="slab", model="auto", resolution="auto", error_tolerance=0.03,
                     step_budget_us=1000.0, volume_options={"size": (0.016, 0.016, 0.005)}, position=(0, 0, 0.0025),
                     anchors=("bottom",))
    scene = build_scene(SceneConfig(tissues=[t], cameras=[], floor=False))
    assert scene.config.tissues[0].spacing == pick.spacing and scene.tissues["slab"].name == "fem_static"
