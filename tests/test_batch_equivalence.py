"""The batched Warp backend (surgsim_envs/batch) against the CPU Simulation of the same scene.

One world on Warp's CPU device steps the Palpation-v0 scene through a scripted press (descend,
then slide) next to the CPU ``Simulation`` built by the task. Bound (the issue's target):
tool and tissue positions within 1e-6 m, probe contact force within 1e-4 of its magnitude.
MuJoCo Warp computes in float32, so the tool pose differs from C MuJoCo's float64 by float32
rounding (~1e-9 m at these positions); the tissue and contact kernels run in float64 and differ
from the CPU kernels only in summation order. Measured on this host: tool 3e-9 m, tissue 5e-9 m,
force 2e-5 relative over 200 steps.
"""

import math

import numpy as np
import pytest

from surgsim_envs.batch.backend import available, cuda_available

#: the single env the batched worlds are (the model and lattice the batched kernels step)
BATCHED = {"model": "mass_spring", "spacing": 0.01}

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

POSITION_BOUND = 1e-6      # m
FORCE_BOUND = 1e-4         # relative to the force's magnitude
FORCE_FLOOR = 1e-3         # N: below this the probe is (nearly) out of contact; compared absolutely


def _palpation_sim(seed=0, **options):
    import gymnasium as gym

    env = gym.make("SurgSim/Palpation-v0", **BATCHED).unwrapped
    env.reset(seed=seed, options=options)
    env.sim.reset()
    return env


@pytest.fixture(scope="module")
def pair():
    from surgsim_envs.batch.simulation import BatchSimulation

    env = _palpation_sim(young_scale=(1.0, 1.0), stiffness_contrast=(1.0, 1.0))
    batch = BatchSimulation(env.sim, 1, device="cpu")
    env.sim.reset()
    return env.sim, batch


def _press(sim, batch, steps, slide=(0.005, 0.0)):
    """Scripted press: the probe target 10 mm down (its tip 8 mm below the rest surface, the task's
    deepest press) at the 0.2 m/s rate limit, then a slide in x/y after half the steps. Returns the
    worst (tool m, tissue m, force relative) and the largest force on the probe (N)."""
    sim.reset()
    batch.reset_worlds()
    home = np.array(sim.tool("probe").home)
    worst, peak = np.zeros(3), 0.0
    for k in range(steps):
        if k in (0, steps // 2):
            target = home + np.array([0.0, 0.0, -0.01])
            if k:
                target[:2] += slide
            sim.set_tool_target("probe", target, speed=0.2)
            batch.set_tool_targets("probe", target[None], speed=0.2)
        sim.physics_step(1)
        batch.step(1)
        tool = np.abs(batch.tool_positions("probe")[0] - sim.tool_position("probe")).max()
        tissue = np.abs(batch.tissue_positions()[0] - sim.tissue().positions).max()
        fc, fb = sim.tool_force("probe"), batch.tool_forces("probe")[0]
        scale = np.linalg.norm(fc)
        force = np.linalg.norm(fb - fc) / scale if scale > FORCE_FLOOR else np.linalg.norm(fb - fc) / FORCE_FLOOR
        worst = np.maximum(worst, [tool, tissue, force])
        peak = max(peak, float(scale))
    return worst, peak


def test_one_world_matches_the_cpu_simulation_over_a_press(pair):
    sim, batch = pair
    worst, peak = _press(sim, batch, 200)
    assert peak > 0.1, f"the press must load the probe (peak {peak:.3g} N)"
    assert worst[0] < POSITION_BOUND, f"tool position differs by {worst[0]:.3g} m"
    assert worst[1] < POSITION_BOUND, f"tissue positions differ by {worst[1]:.3g} m"
    assert worst[2] < FORCE_BOUND, f"probe force differs by {worst[2]:.3g} of its magnitude"


@pytest.mark.slow
def test_one_world_matches_the_cpu_simulation_over_1000_steps(pair):
    sim, batch = pair
    worst, peak = _press(sim, batch, 1000, slide=(0.01, -0.005))
    assert peak > 0.1
    assert worst[0] < POSITION_BOUND and worst[1] < POSITION_BOUND, worst
    assert worst[2] < FORCE_BOUND, worst


def test_worlds_step_independently():
    """Three worlds: 0 and 2 get the same command, 1 another; 0 and 2 stay identical bit for bit
    and 1 differs (no world reads another's arrays)."""
    from surgsim_envs.batch.simulation import BatchSimulation

    env = _palpation_sim()
    batch = BatchSimulation(env.sim, 3, device="cpu")
    home = np.array(env.sim.tool("probe").home)
    targets = home + np.array([[0.0, 0.0, -0.02], [0.004, 0.0, -0.02], [0.0, 0.0, -0.02]])
    batch.set_tool_targets("probe", targets, speed=0.2)
    batch.step(40)
    x = batch.tissue_positions()
    f = batch.tool_forces("probe")
    assert f[0, 2] > 0.01
    np.testing.assert_array_equal(x[0], x[2])
    np.testing.assert_array_equal(f[0], f[2])
    assert np.abs(x[1] - x[0]).max() > 1e-4
    # a reset world is back at rest while the others keep their state and their tool readouts (MuJoCo's
    # forward runs in every world: the others' poses are put back)
    tool = batch.tool_positions("probe").copy()
    batch.reset_worlds([2])
    x2 = batch.tissue_positions()
    np.testing.assert_array_equal(x2[2], batch.topology.rest)
    np.testing.assert_array_equal(x2[0], x[0])
    np.testing.assert_array_equal(batch.tool_positions("probe")[:2], tool[:2])
    batch.set_tool_targets("probe", targets[2:], speed=0.2, worlds=[2])
    batch.step(40)
    x3 = batch.tissue_positions()
    np.testing.assert_array_equal(x3[2], x[0])      # replayed from rest: the same 40 steps, the same state
    # per-world material written for one listed world only
    k1 = batch.fields.K1.numpy().copy()
    batch.set_young_factors(np.full((1, batch.topology.n_tets), 2.0), worlds=[1])
    k1_new = batch.fields.K1.numpy()
    np.testing.assert_allclose(k1_new[1], 2.0 * k1[1], rtol=1e-14)
    np.testing.assert_array_equal(k1_new[[0, 2]], k1[[0, 2]])


def test_young_factors_match_the_cpu_models_rederivation(pair):
    """A stiffer inclusion in one world: the batched springs, branches and volume term equal the CPU
    model's own after scale_material (which rebuilds them from the per-tet fields)."""
    from surgsim_envs.envs.tissue_setup import sphere_mask
    from surgsim_envs.tissue.registry import get as model_class

    sim, batch = pair
    template = sim.tissue()
    cpu = model_class("mass_spring")(template.volume, template.material, integrator="symplectic",
                                     **dict(model_class("mass_spring").point_load_options))
    mask = sphere_mask(cpu.element_centroids(), (0.012, -0.008, 0.012), 0.009)
    factors = np.where(mask, 0.9 * 4.0, 0.9)
    cpu.scale_material("young", 0.9)
    cpu.scale_material("young", 0.9 * 4.0, mask=mask)
    np.testing.assert_allclose(cpu.K1, template.K1 * 0.0 + cpu.K1)   # same topology
    saved = {k: getattr(batch.fields, k).numpy().copy() for k in ("K1", "K2", "kM", "kMg", "kv")}
    try:
        batch.set_young_factors(factors[None])
        kMg = cpu.symplectic_kernel_state(batch.dt)[13]
        for name, ref in (("K1", cpu.K1), ("K2", cpu.K2), ("kM", cpu.kM), ("kMg", kMg), ("kv", cpu.volume_kv)):
            got = getattr(batch.fields, name).numpy()[0]
            np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0, err_msg=name)
        assert cpu.K1.max() > 3.0 * template.K1.max()     # the inclusion is stiffer
    finally:
        for k, v in saved.items():
            getattr(batch.fields, k).assign(v)


def test_bad_arguments_raise_clear_errors(pair):
    from surgsim_envs.batch.simulation import BatchSimulation
    from surgsim_envs.errors import ConfigError

    sim, batch = pair
    with pytest.raises(ConfigError, match=r"worlds=0 must be an integer in \[1, "):
        BatchSimulation(sim, 0)
    with pytest.raises(ConfigError, match=r"device='tpu' must be 'cpu', 'cuda' or 'cuda:<index>'"):
        BatchSimulation(sim, 1, device="tpu")
    with pytest.raises(ConfigError, match=r"positions must be finite \(1, 3\) m"):
        batch.set_tool_targets("probe", [[math.nan, 0.0, 0.0]])
    with pytest.raises(ConfigError, match="outside its reach"):
        batch.set_tool_targets("probe", [[5.0, 0.0, 0.0]])
    with pytest.raises(ConfigError, match=r"factors must be positive finite \(1, "):
        batch.set_young_factors(np.zeros((1, 3)))
    with pytest.raises(ConfigError, match=r"step\(n\): n must be a whole number"):
        batch.step(-1)


def test_actuator_goals_are_written_for_the_listed_worlds_and_actuators_only():
    """set_actuator_goals writes on the device: the listed worlds' listed actuators get their goals (and
    their rates when a speed is given), those worlds move; every other entry is untouched."""
    from surgsim_envs.batch.simulation import BatchSimulation
    from surgsim_envs.errors import ConfigError

    env = _palpation_sim(young_scale=(1.0, 1.0), stiffness_contrast=(1.0, 1.0))
    batch = BatchSimulation(env.sim, 3, device="cpu")
    t = batch.tools
    goal0, rate0 = t.goal.numpy().copy(), t.rate.numpy().copy()
    t.moving.zero_()
    batch.set_actuator_goals([0, 2], [[0.001, -0.002]], worlds=[1])
    goal, rate, moving = t.goal.numpy(), t.rate.numpy(), t.moving.numpy()
    expect = goal0.copy()
    expect[1, [0, 2]] = [0.001, -0.002]
    assert np.array_equal(goal, expect) and np.array_equal(rate, rate0)
    assert moving.tolist() == [0, 1, 0]
    batch.set_actuator_goals([1], [0.003], speed=0.05, worlds=[0, 2])
    rate_expect = rate0.copy()
    rate_expect[[0, 2], 1] = 0.05
    assert np.array_equal(t.rate.numpy(), rate_expect) and t.moving.numpy().tolist() == [1, 1, 1]
    assert np.array_equal(t.goal.numpy()[[0, 2], 1], [0.003, 0.003])
    with pytest.raises(ConfigError, match="speed must be a positive number"):
        batch.set_actuator_goals([1], [0.004], speed=-1.0, worlds=[0])
    assert np.array_equal(t.goal.numpy()[0, 1], 0.003), "a refused command writes nothing"


@pytest.mark.skipif(not cuda_available(), reason="no CUDA device on this host (Warp sees none)")
def test_one_world_on_cuda_matches_the_cpu_simulation():
    from surgsim_envs.batch.simulation import BatchSimulation

    env = _palpation_sim(young_scale=(1.0, 1.0), stiffness_contrast=(1.0, 1.0))
    batch = BatchSimulation(env.sim, 1, device="cuda")
    worst, _ = _press(env.sim, batch, 200)
    assert worst[0] < POSITION_BOUND and worst[1] < POSITION_BOUND and worst[2] < FORCE_BOUND, worst


def test_a_diverged_world_is_named(pair):
    """A non-finite tissue state in one world is detected on the device and reported by name;
    a reset clears it."""
    from surgsim_envs.errors import TissueUnstableError

    sim, batch = pair
    batch.reset_worlds()
    batch.check_stable()
    v = batch.tissue_state.v.numpy()
    v[0, int(np.flatnonzero(~sim.tissue().fixed)[0])] = np.inf
    batch.tissue_state.v.assign(v)
    batch.step(1)
    with pytest.raises(TissueUnstableError, match=r"non-finite node positions in 1 of 1 batched worlds \(first: \[0\]\)"):
        batch.check_stable()
    batch.reset_worlds()
    batch.check_stable()
    assert np.all(np.isfinite(batch.tissue_positions()))


@pytest.mark.slow
def test_grasp_scene_matches_until_the_grasp_then_tracks_the_cpus_own_sensitivity():
    """Grasp-v0's scene (box jaws, cylinder shaft, joint-coupled jaws, MuJoCo contacts, tissue
    sub-cycling 2): the jaws close for 500 steps, then the wrist lifts 10 mm and the jaws meet the
    tissue (first contact ~ step 506). Through step 540 the bounds of the press hold. Later the
    stick/slip grasp is itself chaotic at the scale of MuJoCo Warp's float32 rounding: a 1e-9 m
    perturbation of the CPU tissue at step 540 grows to ~2e-3 m by step 900 (measured), and the
    batched tissue departs from the CPU's by that order too; the wrist stays within 1e-6 m."""
    import gymnasium as gym

    from surgsim_envs.batch.simulation import BatchSimulation

    env = gym.make("SurgSim/Grasp-v0").unwrapped
    env.reset(seed=0, options={"young_scale": 1.0})
    sim = env.sim
    batch = BatchSimulation(sim, 1, device="cpu")
    assert batch.subcycles == 2
    sim.reset()
    tool = sim.tool("grasper")
    jaw, g = tool.jaw_actuator_id, tool.config
    sim.set_jaw_opening("grasper", g.min_radius)
    batch.set_actuator_goals([jaw], [g.open_radius - g.min_radius])
    early, wrist, peak = np.zeros(3), 0.0, 0.0
    for k in range(0, 1000, 2):
        if k == 500:
            target = np.array(tool.home) + np.array([0.0, 0.0, 0.01])
            sim.set_tool_target("grasper", target)
            batch.set_tool_targets("grasper", target[None])
        sim.physics_step(2)
        batch.step(2)
        wrist = max(wrist, np.abs(batch.tool_positions("grasper")[0] - sim.tool_position("grasper")).max())
        fc, fb = sim.tool_force("grasper"), batch.tool_forces("grasper")[0]
        peak = max(peak, float(np.linalg.norm(fc)))
        if k < 540:
            tissue = np.abs(batch.tissue_positions()[0] - sim.tissue().positions).max()
            force = np.linalg.norm(fb - fc) / max(np.linalg.norm(fc), FORCE_FLOOR)
            early = np.maximum(early, [wrist, tissue, force])
    assert peak > 0.02, f"the jaws must load the tissue (peak {peak:.3g} N)"
    assert early[0] < POSITION_BOUND and early[1] < POSITION_BOUND, early
    assert early[2] < FORCE_BOUND, early
    assert wrist < POSITION_BOUND, wrist
