"""LayeredPalpation-v0 with its wall as a continuum (``model="fem_static"``): the task builds it, the
contact is unilateral and frictionless (complementarity holds node by node), the force rises with
depth, does not depend on the probe's path, and a stiff nodule raises the force above it."""

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs.envs  # noqa: F401
from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.anatomy import ABDOMINAL_WALL_THICKNESS

#: a small patch keeps each env build well under a second
SMALL = dict(model="fem_static", size=(0.04, 0.04), spacing=0.005)


def _env(**kw):
    return gym.make("SurgSim/LayeredPalpation-v0", disable_env_checker=True, **{**SMALL, **kw}).unwrapped


def _press(env, xy, depth):
    half = 0.5 * np.asarray(env.config.size)
    a = np.array([xy[0] / half[0], xy[1] / half[1], 2 * depth / env.config.max_depth - 1, -1], np.float32)
    return env.step(a)[4]["force_N"]


def test_the_task_builds_a_layer_conforming_continuum_wall():
    env = _env()
    nodes = env.tissue.rest_positions
    levels = np.unique(np.round(nodes[:, 2], 12))
    assert env.tissue.name == "fem_static"
    assert levels[-1] == pytest.approx(sum(ABDOMINAL_WALL_THICKNESS.values()), abs=1e-12)
    for plane in (0.002, 0.012, 0.027):         # a node level on every interface
        assert np.min(np.abs(levels - plane)) < 1e-12
    skin = levels[levels >= 0.027 - 1e-12]
    assert len(skin) - 1 >= 2                   # the skin in at least two cells (not one locking tet)


def test_contact_is_unilateral_and_complementary_node_by_node():
    env = _env()
    env.reset(seed=0, options={"nodule_position": (0.01, 0.0)})
    force = _press(env, (0.0, 0.0), 0.004)
    probe, tissue = env.probe, env.tissue
    assert force > 0 and np.all(probe.lam >= 0)
    centre = env._centre
    r = env.config.probe_radius
    cand = env.top[np.hypot(*(tissue.rest_positions[env.top, :2] - centre[:2]).T) < r]
    h = centre[2] - np.sqrt(r ** 2 - np.sum((tissue.rest_positions[cand, :2] - centre[:2]) ** 2, axis=1))
    z = tissue.positions[cand, 2]
    on = np.isin(cand, probe.nodes)
    assert on.any() and (~on).any() or on.all()
    np.testing.assert_allclose(z[on], h[on], atol=1e-9 * r)     # contact nodes on the sphere
    assert np.all(z[~on] <= h[~on] + 1e-9 * r)                  # the others not inside it
    # frictionless along the press axis: the probe pushes its nodes straight down only
    f = tissue.integrated_external_forces[probe.nodes]
    assert np.all(f[:, :2] == 0) and np.all(f[:, 2] < 0)
    assert force == pytest.approx(-f[:, 2].sum(), rel=1e-12)
    # the condensed equilibrium is the full one: a full solve under the same forces gives the same body
    condensed = tissue.positions.copy()
    loads = np.zeros_like(condensed)
    loads[probe.nodes] = f
    np.testing.assert_allclose(tissue.static_solve(loads), condensed, atol=1e-12)


def test_force_rises_with_depth_and_a_probe_above_the_skin_reads_zero():
    env = _env()
    env.reset(seed=0, options={"nodule_position": (0.01, 0.01)})
    forces = [_press(env, (-0.005, 0.0), d) for d in (0.0, 0.001, 0.002, 0.003, 0.005)]
    assert forces[0] < 1e-12 * forces[-1]      # touching the skin: round-off only
    assert all(b > a for a, b in zip(forces, forces[1:]))


def test_the_force_depends_on_the_pose_only():
    env = _env()
    env.reset(seed=0, options={"nodule_position": (0.01, 0.01)})
    fresh = _press(env, (0.0, 0.0), 0.003)
    _press(env, (0.005, -0.005), 0.006)
    _press(env, (0.0, 0.0), 0.006)
    assert _press(env, (0.0, 0.0), 0.003) == pytest.approx(fresh, rel=1e-9)


def test_a_stiff_nodule_raises_the_force_above_it():
    env = _env()
    site, other = (0.01, 0.005), (-0.01, -0.005)
    env.reset(seed=0, options={"nodule_position": site})
    over = _press(env, site, 0.004)
    env.reset(seed=0, options={"nodule_position": other})
    away = _press(env, site, 0.004)
    assert over > 1.5 * away


@pytest.mark.parametrize("model", ["layered", "fem_static"])
def test_a_reset_with_the_same_nodule_keeps_it(model):
    """The env rescales the material only when the nodule's tets change: a reset to the same nodule,
    and back to it after another, presses as the first episode did."""
    env = _env(model=model)
    site, other = (0.01, 0.005), (-0.01, -0.005)
    env.reset(seed=0, options={"nodule_position": site})
    first = _press(env, site, 0.004)
    env.reset(seed=0, options={"nodule_position": site})
    again = _press(env, site, 0.004)
    env.reset(seed=0, options={"nodule_position": other})
    away = _press(env, site, 0.004)
    env.reset(seed=0, options={"nodule_position": site})
    back = _press(env, site, 0.004)
    assert again == pytest.approx(first, rel=1e-12) and back == pytest.approx(first, rel=1e-9)
    assert first > 1.05 * away


def test_a_model_the_task_does_not_build_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"model='mass_spring'.*\['layered', 'fem_static', 'fem_hex'\]"):
        _env(model="mass_spring")


def test_the_node_limit_counts_the_continuum_lattice():
    with pytest.raises(ConfigError, match="lattice nodes"):
        _env(size=(0.3, 0.3), spacing=0.002)


@pytest.mark.slow
def test_the_continuum_wall_at_2_mm_meets_the_tasks_20_percent_against_the_shipped_reference():
    """The probe set's presses on the full patch at 2 mm against the shipped reference (fem_static
    on graded lattices, 0.71 mm at each site, penalty contact per area: an independent discretisation
    and contact); the task declares 20 % (the 2 mm wall reads at most 18.8 % off, at the mirror site). 30 s on an idle 2-core host (2 min loaded), 3.7 GB."""
    import json

    from surgsim_envs.bench.probe_sets import layered_palpation as lp
    from surgsim_envs.tissue.task_table import TASK_TABLE_PATH

    with open(TASK_TABLE_PATH) as fh:
        ref = json.load(fh)["references"][lp.TASK]["forces_N"]
    row = lp.measure(lp.TASK, "fem_static", 0.002, lp.FULL)
    err = {k: row["forces_N"][k] / ref[k] - 1 for k in ref}
    assert max(abs(e) for e in err.values()) <= 0.20, err
    over = [row["forces_N"][f"0/over/{d}mm"] / row["forces_N"][f"0/mirror/{d}mm"] for d in ("2.5", "3.5", "4.5")]
    assert min(over) > 4.0          # the reference reads 4.91-4.97 x over the nodule what it reads beside it
    assert row["path_difference"] < 1e-9 and row["max_tensile_N"] == 0.0


def test_a_reset_factorises_the_stiffness_once_for_its_nodule(monkeypatch):
    """Taking the probe off before a reset solves nothing: only the new nodule's stiffness is factorised
    (at the task's 2 mm lattice a factorisation costs tens of seconds), and a reset that keeps the
    nodule's tets keeps the factorisation."""
    from surgsim_envs.tissue import fem_static

    made = []
    real = fem_static.CondensedCompliance

    def counting(*args, **kwargs):
        made.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(fem_static, "CondensedCompliance", counting)
    env = _env()
    env.reset(options={"nodule_position": (0.01, 0.0)})
    assert len(made) == 1
    first = _press(env, (0.01, 0.0), 0.004)
    env.reset(options={"nodule_position": (-0.01, 0.0)})
    assert len(made) == 2
    env.reset(options={"nodule_position": (-0.01, 0.0)})
    assert len(made) == 2
    env.reset(options={"nodule_position": (0.01, 0.0)})
    assert len(made) == 3 and _press(env, (0.01, 0.0), 0.004) == first
