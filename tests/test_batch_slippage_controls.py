"""The batched backend's pieces for Slippage-v0 (surgsim_envs/batch/simulation.py) against the CPU Simulation.

Slippage-v0's scene (its along-axis wrist drive a force motor, the template's MuJoCo model carried
into MuJoCo Warp), two worlds on Warp's CPU device:

* the reset's approach restored from a snapshot (``ApproachSnapshot`` recorded on the CPU scene,
  ``BatchSimulation.set_rigid_states`` into world 1 only): world 1 then closes its jaws for the rest
  of the settle with the task's control schedule (``step_with_controls``, per world) and follows the
  CPU scene that restored the same snapshot; world 0, not restored, runs the approach from its reset;
* then the pull: the task's schedule (ramp plus sinusoid) on the force motor for four control steps;
  the pull force (``actuator_forces``), the schedule's controls (``controls``) and the wrist
  displacement along the pull (``tool_displacements``) follow the CPU scene.

Bounds (causes as in docs/batch.md): MuJoCo Warp integrates the tools in float32, so the wrist and
opening agree within 1e-6 m (measured 6e-8 m through the settle, 5e-7 m by the fourth pull step);
per-jaw forces within 1e-4 of the grip plus k_n x 1e-8 m per contact node through the settle (before
the pull: once the grasped organ is pulled, the stick/slip grasp is chaotic at float32 rounding,
measured 1 % of the grip by the third pull step); the pull force is the control rounded to float32
(2^-24 relative, bound 1e-7 relative); the controls are the float64 schedule itself (equal).
"""

import mujoco
import numpy as np
import pytest

from surgsim_envs.batch.backend import available

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

REL, PER_NODE = 1e-4, 200.0 * 1e-8       # of the grip; N per contact node (k_n x 1e-8 m)
POS = 1e-6                               # m, float32 tool pose
PULL_STEPS = 4                           # control steps of pull (before the chaos window widens)


@pytest.fixture(scope="module")
def scene():
    import gymnasium as gym

    from surgsim_envs.batch.simulation import BatchSimulation
    from surgsim_envs.envs.slippage.terms import control_schedule
    from surgsim_envs.envs.terms.action import jaw_closure

    env = gym.make("SurgSim/Slippage-v0").unwrapped
    env.reset(seed=0)                     # draws friction and stiffness into the scene; the batch copies them
    sim = env.sim
    batch = BatchSimulation(sim, 2, device="cpu")          # resets the CPU scene
    c, tool = env.config, sim.tool("grasper")
    g = tool.config
    n = sim.tissue_subcycles
    dt = sim.dt * n

    def schedule(steps, jaw, t, goal, pull=None, t0=0.0):
        """(steps MuJoCo steps, 2) jaw and pull controls of the task's schedule (Slippage-v0's _run)."""
        v = np.zeros((steps, 2))          # no pull: column 1 stays 0 (control_schedule leaves it unwritten)
        args = (True, *pull, t0, float(c.max_pull)) if pull else (False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        control_schedule(v, jaw, goal, c.closing_speed * dt, t, dt, *args)
        return v

    return {"env": env, "sim": sim, "batch": batch, "c": c, "g": g, "n": n, "dt": dt, "schedule": schedule,
            "acts": [int(tool.jaw_actuator_id), int(tool.actuator_ids[2])],
            "goal": jaw_closure(c.initial_closure, g.open_radius, g.min_radius),
            "pull_dir": -np.asarray(g.axis, dtype=float) / np.linalg.norm(g.axis)}


def test_approach_restore_settle_and_pull_follow_the_cpu_simulation(scene):
    from surgsim_envs.scene.approach_snapshot import ApproachSnapshot

    sim, batch, c, schedule, acts = scene["sim"], scene["batch"], scene["c"], scene["schedule"], scene["acts"]
    jaw_act, pull_act = acts
    n, goal = scene["n"], scene["goal"]
    settle = int(round(c.settle_time / sim.dt))

    def run(k):
        sim.step_with_controls(acts, schedule(k // n, float(sim.data.ctrl[jaw_act]), sim.time, goal))

    snap = ApproachSnapshot()
    key = ("settle", goal, settle)
    done = snap.skip(sim, key, run, settle)
    state = snap.state(sim, key)
    assert 0 < done < settle and state is not None, "the approach must keep a contact-free part"
    qpos0 = batch.tools.data.qpos.numpy()[0].copy()
    batch.set_rigid_states(state, worlds=[1])
    d = batch.tools.data
    assert abs(float(d.time.numpy()[1]) - sim.time) < 1e-7 and float(d.time.numpy()[0]) == 0.0
    np.testing.assert_allclose(d.qpos.numpy()[1], sim.data.qpos, atol=1e-7)     # float32 of the state
    np.testing.assert_array_equal(d.qpos.numpy()[0], qpos0)                       # world 0 untouched
    assert batch.controls([jaw_act])[1, 0] == sim.data.ctrl[jaw_act] != 0.0

    # the rest of the settle: world 1 from the snapshot (as the CPU), world 0 from its reset
    K = (settle - done) // n
    v1 = schedule(K, float(sim.data.ctrl[jaw_act]), sim.time, goal)
    v0 = schedule(K, 0.0, 0.0, goal)
    grip_peak = 0.0
    for k in range(0, K, 10):
        sim.step_with_controls(acts, v1[k:k + 10])
        batch.step_with_controls(acts, np.stack([v0[k:k + 10], v1[k:k + 10]], axis=1))
        assert np.abs(batch.tool_positions("grasper")[1] - sim.tool_position("grasper")).max() < POS, k
        assert abs(batch.jaw_openings("grasper")[1] - sim.jaw_opening("grasper")) < POS, k
        jc, jb = sim.jaw_forces("grasper"), batch.jaw_forces("grasper")
        rc, rb = sim.tool_contact_report("grasper"), batch.tool_contact_report("grasper")
        grip = float(np.sum(jc["normal"]))
        bound = REL * grip + PER_NODE * rc["contacts"]
        for key_ in ("normal", "tangential"):
            assert np.abs(jb[key_][1] - jc[key_]).max() <= bound, (k, key_)
        assert (rb["contacts"][1], rb["slipping"][1]) == (rc["contacts"], rc["slipping"]), k
        grip_peak = max(grip_peak, grip)
    assert grip_peak > 0.2, f"the settle must grip (peak grip {grip_peak:.3g} N)"
    t_w0 = K * scene["dt"]          # float32 time summed K times: at most K roundings of 2^-24 of it
    assert abs(float(d.time.numpy()[0]) - t_w0) <= K * 2.0 ** -24 * t_w0, "world 0 ran K MuJoCo steps from its reset"

    # the pull: the task's schedule on the force motor (rate, amplitude, frequency, phase)
    pull = (0.5, 0.03, 1.0, 0.3)
    t0 = sim.time
    pos0_cpu = sim.tool_position("grasper").copy()
    pos0 = batch.tool_positions("grasper")
    for step in range(PULL_STEPS):
        v = schedule(scene["env"].substeps // n, float(sim.data.ctrl[jaw_act]), sim.time, goal, pull, t0)
        sim.step_with_controls(acts, v)
        batch.step_with_controls(acts, np.repeat(v[:, None, :], 2, axis=1))
        f_cpu = float(sim.data.actuator_force[pull_act])
        assert f_cpu == v[-1, 1] > 0.0, step                   # a force motor: its control, in N
        f = batch.actuator_forces([pull_act])
        assert abs(f[1, 0] - f_cpu) <= 1e-7 * f_cpu, step
        np.testing.assert_array_equal(batch.controls(acts)[1], v[-1])
        disp_cpu = float((sim.tool_position("grasper") - pos0_cpu) @ scene["pull_dir"])
        disp = batch.tool_displacements("grasper", pos0, scene["pull_dir"])
        assert abs(disp[1] - disp_cpu) < POS, (step, disp[1], disp_cpu)
    assert abs(disp_cpu) > 1e-4, f"the pull must move the wrist (moved {disp_cpu:.3g} m)"


def test_slippage_pieces_refuse_bad_input_with_the_fix(scene):
    from surgsim_envs.errors import ConfigError

    batch, acts = scene["batch"], scene["acts"]
    with pytest.raises(ConfigError, match=r"values must have shape \(steps, 2, 2\)"):
        batch.step_with_controls(acts, np.zeros((3, 2)))
    with pytest.raises(ConfigError, match="NaN/inf"):
        batch.step_with_controls(acts, np.full((1, 2, 2), np.nan))
    with pytest.raises(ConfigError, match=r"actuators must be ids in \[0, "):
        batch.controls([99])
    size = mujoco.mj_stateSize(scene["sim"].model, mujoco.mjtState.mjSTATE_INTEGRATION)
    with pytest.raises(ConfigError, match=f"mjSTATE_INTEGRATION vector of {size} numbers"):
        batch.set_rigid_states(np.zeros(size + 1))
    with pytest.raises(ConfigError, match=r"worlds must be indices in \[0, 2\)"):
        batch.set_rigid_states(np.zeros(size), worlds=[2])
    with pytest.raises(ConfigError, match="unit 3-vector"):
        batch.tool_displacements("grasper", np.zeros((2, 3)), [0.0, 0.0, 2.0])
    with pytest.raises(ConfigError, match=r"origins must be finite \(2, 3\)"):
        batch.tool_displacements("grasper", np.zeros(3), [0.0, 0.0, 1.0])


def test_held_worlds_get_their_state_back(scene):
    """``held``: the steps inside move every world; on leaving, the held world's tissue, contact,
    controls and MuJoCo state are what they were (bit for bit), the other world keeps its steps."""
    from surgsim_envs.errors import ConfigError

    batch, acts = scene["batch"], scene["acts"]
    d = batch.tools.data
    before = (batch.tissue_positions(), d.qpos.numpy().copy(), d.time.numpy().copy(), batch.controls(acts),
              batch.contact.f_ext.numpy().copy(), batch.tool_positions("grasper"))
    v = np.zeros((20, 2, 2))
    v[:, :, 0] = before[3][:, 0] + 1e-3          # the jaws close 1 mm further in both worlds
    with batch.held([0]):
        batch.step_with_controls(acts, v)
        assert not np.array_equal(batch.tissue_positions()[0], before[0][0]), "world 0 steps inside"
    after = (batch.tissue_positions(), d.qpos.numpy(), d.time.numpy(), batch.controls(acts), batch.contact.f_ext.numpy(),
             batch.tool_positions("grasper"))     # the pose: forward recomputed from the restored state
    for b, a in zip(before, after):
        np.testing.assert_array_equal(a[0], b[0])
    assert after[2][1] > before[2][1] and not np.array_equal(after[0][1], before[0][1]), "world 1 kept its steps"
    with pytest.raises(ConfigError, match=r"worlds must be indices in \[0, 2\)"):
        with batch.held([5]):
            pass


def test_resetting_one_world_leaves_the_others_readouts(scene):
    """``reset_worlds`` runs MuJoCo Warp's ``forward`` in every world; the other worlds' poses and
    actuator forces (their wrist and pull readouts between steps) stay bit for bit (without the
    put-back, a moving wrist's pose jumps to the next step's: 4e-7 m in Grasp-v0 at a 0.5 action)."""
    batch, acts = scene["batch"], scene["acts"]
    v = np.zeros((10, 2, 2))
    v[:, :, 1] = 0.05                            # a pull in both worlds: the wrist moves
    batch.step_with_controls(acts, v)
    pos, force = batch.tool_positions("grasper"), batch.actuator_forces(acts)
    batch.reset_worlds([1])
    np.testing.assert_array_equal(batch.tool_positions("grasper")[0], pos[0])
    np.testing.assert_array_equal(batch.actuator_forces(acts)[0], force[0])
    assert not np.array_equal(batch.tool_positions("grasper")[1], pos[1]), "world 1 is back at its reset pose"
