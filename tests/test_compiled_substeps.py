"""The compiled substeps (scene/step/compiled.py, one numba call per control step) give exactly what the generic
per-substep loop gives: the same tissue state, contact forces, tool wrenches and MuJoCo state after
many substeps, bit for bit; and the same errors with the same messages when the guard or the input
check fails. Models, integrators or guards without a registered loop keep the generic loop."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.errors import ConfigError, NonFiniteInputError, TissueUnstableError
from surgsim_envs.scene.step.compiled import key_of, registered
from surgsim_envs.tissue.guard import StabilityGuard
from surgsim_envs.tissue.mass_spring import MassSpringModel

#: Palpation-v0 on the explicit mass-spring network (its default model is the quasi-static FEM, which has no
#: compiled substep loop)
MASS_SPRING = {"model": "mass_spring", "spacing": 0.01}



def _pair(task, **config):
    """Two envs of ``task`` in the same state: the first steps compiled, the second generically."""
    envs = [gym.make(task, **config), gym.make(task, **config)]
    for e in envs:
        e.reset(seed=3)
    envs[1].unwrapped.sim.compiled_substeps = False
    return envs


def _actions(env, n, seed=0):
    a = np.random.default_rng(seed).uniform(-1, 1, (n, *env.action_space.shape)).astype(np.float32)
    if "Palpation" in env.spec.id:
        a[:, 2] = np.linspace(-1, 0.8, n)     # press progressively deeper: contact is certain
        a[:, -1] = -1.0                       # never report: the episode keeps going
    return a


def _assert_same(s0, s1):
    t0, t1 = s0.tissue(), s1.tissue()
    c0, c1 = next(iter(s0.contacts.values())).result, next(iter(s1.contacts.values())).result
    pairs = [(t0.positions, t1.positions), (t0.velocities, t1.velocities),
             (t0.integrated_external_forces, t1.integrated_external_forces), (c0.forces, c1.forces),
             (c0.stiffness, c1.stiffness), (c0.tool_force, c1.tool_force), (c0.tool_torque, c1.tool_torque),
             (c0.geom_normal_force, c1.geom_normal_force), (c0.geom_tangential_force, c1.geom_tangential_force),
             (c0.report.normal_force, c1.report.normal_force),
             (c0.report.tangential_force, c1.report.tangential_force),
             (s0.data.qpos, s1.data.qpos), (s0.data.qvel, s1.data.qvel), (s0.data.ctrl, s1.data.ctrl),
             (s0.data.xfrc_applied, s1.data.xfrc_applied)]
    for x, y in pairs:
        np.testing.assert_array_equal(x, y)
    assert (t0.time, t0.steps, s0.steps, s0.time) == (t1.time, t1.steps, s1.steps, s1.time)
    (e0, pos0, vel0, time0), (e1, pos1, vel1, time1) = t0.guard.state(), t1.guard.state()
    np.testing.assert_array_equal(pos0, pos1)
    np.testing.assert_array_equal(vel0, vel1)
    assert time0 == time1
    # the energy reference is summed in another order in the kernel: equal to rounding
    assert e0 == pytest.approx(e1, rel=1e-12, abs=0.0)


@pytest.mark.parametrize("task", ["SurgSim/Palpation-v0",
                                  pytest.param("SurgSim/Slippage-v0", marks=pytest.mark.slow)])
def test_compiled_substeps_match_the_generic_loop_bit_for_bit(task):
    envs = _pair(task, **(MASS_SPRING if "Palpation" in task else {}))
    s0, s1 = (e.unwrapped.sim for e in envs)
    assert s0.compiled_runner() is not None, "the task's default tissue should have a compiled loop"
    assert s1.compiled_runner() is None
    touched = 0
    for a in _actions(envs[0], 25):
        outs = [e.step(a) for e in envs]
        np.testing.assert_array_equal(outs[0][0], outs[1][0])
        assert outs[0][1] == outs[1][1]
        _assert_same(s0, s1)
        touched += int(next(iter(s0.contacts.values())).report.contacts.sum())
    assert touched > 0, "no contact in the run: the comparison would be vacuous"


def _assert_close(s0, s1, rtol=1e-12):
    t0, t1 = s0.tissue(), s1.tissue()
    scale = float(np.abs(t1.positions).max())
    np.testing.assert_allclose(t0.positions, t1.positions, rtol=0, atol=rtol * scale)
    np.testing.assert_allclose(s0.data.qpos, s1.data.qpos, rtol=0, atol=rtol * max(1.0, np.abs(s1.data.qpos).max()))
    assert (t0.time, t0.steps, s0.steps) == (t1.time, t1.steps, s1.steps)


def test_calibrated_mass_spring_runs_compiled():
    """mass_spring_calibrated (nodal volume term in its own step), symplectic as Palpation-v0 builds
    it: the compiled loop gives the generic loop's result. Bit for bit when numba compiles the
    kernels in the process; with kernels loaded from numba's cache the fastmath nodal-volume kernel
    may round the last bit differently (measured 1e-15 relative), hence 1e-12 here
    (CHANGELOG.md "Env step: address table, pluggable tissue step"). "auto" (sub-cycles, implicit steps):
    tests/test_compiled_calibrated.py."""
    envs = _pair("SurgSim/Palpation-v0", model="mass_spring_calibrated", spacing=0.01, dt=2.5e-4)
    s0, s1 = (e.unwrapped.sim for e in envs)
    assert type(s0.tissue()).__name__ == "CalibratedMassSpringModel" and s0.tissue().integrator == "symplectic"
    assert s0.compiled_runner() is not None and s1.compiled_runner() is None
    for a in _actions(envs[0], 30, seed=1):
        outs = [e.step(a) for e in envs]
        np.testing.assert_allclose(outs[0][0], outs[1][0], rtol=1e-5, atol=1e-6)    # float32 observations
        _assert_close(s0, s1)


def test_mass_spring_implicit_steps_give_the_tools_the_integrated_reaction():
    """MassSpringModel under "auto" with a step above its explicit limit: every step is implicit,
    the integrated force differs from the contact force, and the compiled loop attributes the
    increment to the tools exactly as ContactModel.attribute_increment does (same wrenches, same
    tool motion, the same readings of the integrated force), bit for bit."""
    a, b = _free_scene(1, True, integrator="auto", dt=5e-3), _free_scene(1, False, integrator="auto", dt=5e-3)
    assert a.compiled_runner() is not None and b.compiled_runner() is None
    p0 = a.momentum()
    differs = implicit = 0
    for _ in range(40):
        a.step_with_controls([], np.zeros((1, 0)))
        b.step_with_controls([], np.zeros((1, 0)))
        ca, cb = next(iter(a.contacts.values())), next(iter(b.contacts.values()))
        for x, y in ((a.tissue().positions, b.tissue().positions), (a.data.qvel, b.data.qvel),
                     (a.tissue().integrated_external_forces, b.tissue().integrated_external_forces),
                     (ca.result.geom_normal_force, cb.result.geom_normal_force),
                     (ca.result.geom_tangential_force, cb.result.geom_tangential_force),
                     (ca.report.normal_force, cb.report.normal_force),
                     (ca.report.tangential_force, cb.report.tangential_force)):
            np.testing.assert_array_equal(x, y)
        assert a.tissue()._active == b.tissue()._active
        implicit += a.tissue()._active == "implicit"
        c = next(iter(a.contacts.values())).result
        differs += not np.array_equal(a.tissue().integrated_external_forces, c.forces)
    assert implicit > 5 and differs > 5, "the implicit increment never acted: the comparison would be vacuous"
    # the tools got the reaction of what the tissue integrated: momentum is conserved (to the CG
    # tolerance of the implicit solve, 1e-6 relative; without the increment it leaks 11-14 %)
    np.testing.assert_allclose(a.momentum(), p0, rtol=0, atol=1e-5 * np.abs(p0).max())


def test_the_guard_raises_the_same_error_in_both_loops():
    """Runaway speed (cheap check, every step) and kinetic-energy blow-up (costly check, every
    check_every steps, run inside the kernel) give the generic loop's error and message."""
    for setting in ({"max_speed": 1e-4}, {"energy_factor": 1e-9, "energy_floor": 1e-9}):
        envs = _pair("SurgSim/Palpation-v0", **MASS_SPRING)
        msgs = []
        for e in envs:
            tissue = e.unwrapped.sim.tissue()
            for k, v in setting.items():
                setattr(tissue.guard, k, v)
            with pytest.raises(TissueUnstableError) as info:
                for a in _actions(e, 30):
                    e.step(a)
            msgs.append(str(info.value))
        assert msgs[0] == msgs[1]
        _assert_same(*(e.unwrapped.sim for e in envs))


def test_non_finite_contact_input_is_refused_with_the_same_message():
    envs = _pair("SurgSim/Palpation-v0", **MASS_SPRING)
    msgs = []
    for e in envs:
        sim = e.unwrapped.sim
        next(iter(sim.contacts.values())).tool_friction[:] = np.nan   # friction NaN -> contact force NaN
        with pytest.raises(NonFiniteInputError) as info:
            for a in _actions(e, 30):
                e.step(a)
        msgs.append(str(info.value))
    assert msgs[0] == msgs[1] and "node" in msgs[0]
    _assert_same(*(e.unwrapped.sim for e in envs))


def test_models_without_a_registered_loop_keep_the_generic_loop():
    assert ("ContactModel", "MassSpringModel", "symplectic") in registered()
    assert ("ContactModel", "CalibratedMassSpringModel", "symplectic") in registered()
    env = gym.make("SurgSim/Palpation-v0", **MASS_SPRING)
    env.reset(seed=0)
    sim = env.unwrapped.sim
    tissue = sim.tissue()
    assert key_of(sim) is not None and sim.compiled_runner() is not None

    class StricterGuard(StabilityGuard):
        pass

    tissue.guard = StricterGuard()
    assert key_of(sim) is None and sim.compiled_runner() is None
    tissue.guard = StabilityGuard()
    tissue.integrator = "implicit"
    assert sim.compiled_runner() is None
    tissue.integrator = "symplectic"

    class Calibrated(MassSpringModel):
        pass

    tissue.__class__ = Calibrated
    assert sim.compiled_runner() is None
    tissue.__class__ = MassSpringModel
    assert sim.compiled_runner() is not None


def test_step_with_controls_checks_its_schedule():
    env = gym.make("SurgSim/Grasp-v0")
    env.reset(seed=0)
    sim = env.unwrapped.sim
    with pytest.raises(ConfigError, match="shape"):
        sim.step_with_controls([0, 1], np.zeros((3, 1)))
    with pytest.raises(ConfigError, match="actuator ids"):
        sim.step_with_controls([sim.model.nu], np.zeros((3, 1)))
    with pytest.raises(ConfigError, match="NaN"):
        sim.step_with_controls([0], np.full((3, 1), np.nan))
    steps = sim.steps
    sim.step_with_controls([0], np.full((4, 1), 0.001))
    assert sim.steps == steps + 4 * sim.tissue_subcycles and sim.data.ctrl[0] == 0.001   # 4 MuJoCo steps


# ---------------------------------------------------------------------------------------------
# tissue_subcycles: n tissue + contact steps per MuJoCo step
def _free_scene(subcycles, compiled, integrator="symplectic", dt=5e-4):
    from surgsim_envs.scene import ProbeConfig, SceneConfig, Simulation, TissueConfig, build_scene

    tissue = TissueConfig(name="blob", organ="block", model="mass_spring",
                          material={"preset": "liver", "damping": 0.0}, spacing=0.01, anchors=(),
                          position=(0.0, 0.0, 0.0), volume_options={"size": (0.04, 0.04, 0.02)},
                          options={"integrator": integrator})
    probe = ProbeConfig(name="probe", drive="free", tip_radius=0.008, position=(0.003, -0.002, 0.0185), mass=0.02)
    cfg = SceneConfig(name="momentum", tissues=[tissue], tools=[probe], dt=dt, gravity=(0.0, 0.0, 0.0),
                      floor=False, cameras=[])
    sim = Simulation(build_scene(cfg), tissue_subcycles=subcycles, compiled_substeps=compiled)
    sim.data.qvel[sim.tool("probe").dof_adr[2]] = -0.4      # moving down onto the tissue
    return sim


@pytest.mark.parametrize("compiled", [True, False])
def test_subcycled_steps_conserve_momentum_through_an_impact(compiled):
    """The tool gets the mean of the n reactions over the n-times longer MuJoCo step: the same
    impulse the tissue got, so tool + tissue momentum is conserved (no damping, gravity or anchors)."""
    sim = _free_scene(4, compiled)
    assert (sim.compiled_runner() is not None) == compiled
    assert sim.model.opt.timestep == pytest.approx(4 * sim.dt)
    p0 = sim.momentum()
    touched = 0
    for _ in range(100):
        sim.step_with_controls([], np.zeros((1, 0)))          # one MuJoCo step = 4 physics steps
        touched += sim.contact_report()["probe"]["contacts"] > 0
    assert sim.steps == 400 and sim.tissue().steps == 400
    assert touched > 5, "the tool never hit the tissue"
    assert abs(sim.tissue().momentum()[2]) > 0.2 * abs(p0[2]), "no momentum reached the tissue"
    np.testing.assert_allclose(sim.momentum(), p0, atol=1e-9 * max(1.0, np.abs(p0).max()) + 1e-12)


def test_subcycled_compiled_and_generic_loops_agree_bit_for_bit():
    a, b = _free_scene(4, True), _free_scene(4, False)
    for _ in range(30):
        a.run(4 * a.dt)
        b.run(4 * b.dt)
        np.testing.assert_array_equal(a.tissue().positions, b.tissue().positions)
        np.testing.assert_array_equal(a.data.qvel, b.data.qvel)
    assert a.steps == b.steps == 120
    with pytest.raises(ConfigError, match="multiple of 4"):
        a.physics_step()


def test_tissue_subcycles_is_checked():
    from surgsim_envs.envs.grasp import GraspSceneConfig

    with pytest.raises(ConfigError, match="tissue_subcycles"):
        _free_scene(0, True)
    with pytest.raises(ConfigError, match="tissue_subcycles=3"):
        GraspSceneConfig(tissue_subcycles=3).validate()      # 50 physics steps per control step
