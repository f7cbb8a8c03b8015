"""The batched backend's grasp readouts (surgsim_envs/batch/simulation.py) against the CPU Simulation.

Grasp-v0's scene, the jaws closing on the organ tip from the task's reset state (friction and
stiffness drawn by the task, seed 0): per-jaw normal and tangential force (``jaw_forces``), the
contact report (``tool_contact_report``), the contacted nodes (``contact_nodes``) and the jaw
opening of world 0 follow the CPU ``Simulation`` through first contact (physics step ~890), the
closure and the grasp (~1050) up to step 1100, before any wrist motion (the stick/slip chaos window
of docs/batch.md opens when the grasped organ is pulled).

Bounds: MuJoCo Warp's float32 tool pose differs from C MuJoCo's by ~5e-9 m (measured 1e-9 to
5e-9 m here), which moves each contact node's penetration and stick anchor by as much; so each
per-jaw force agrees within 1e-4 of the grip (sum of the jaw normal forces) plus k_n x 1e-8 m per
contact node (k_n = 200 N/m: 2e-6 N a node); counts and contacted nodes are equal; the opening
(float32 qpos) within 1e-6 m. World 1 has no friction (mu = 0): its friction forces are zero and
its contact points slide, while world 0 grips with friction.
"""

import numpy as np
import pytest

from surgsim_envs.batch.backend import available

#: the single env the batched worlds are (the model and lattice the batched kernels step)
BATCHED = {"model": "mass_spring", "spacing": 0.01}

pytestmark = pytest.mark.skipif(not available(), reason="needs the [batch] extra (warp-lang, mujoco-warp)")

STEPS = 1100
REL, PER_NODE = 1e-4, 200.0 * 1e-8       # of the grip; N per contact node (k_n x 1e-8 m)


def _cpu_contact_nodes(sim):
    from surgsim_envs.envs.grasp.terms import contact_nodes

    return contact_nodes(sim)


@pytest.mark.slow
def test_grasp_readouts_follow_the_cpu_simulation_through_a_closure():
    import gymnasium as gym

    from surgsim_envs.batch.simulation import BatchSimulation

    env = gym.make("SurgSim/Grasp-v0").unwrapped
    env.reset(seed=0)
    sim = env.sim
    batch = BatchSimulation(sim, 2, device="cpu")
    mu = env.mu
    batch.set_tool_friction([mu, 0.0], [env.config.static_friction_ratio * mu, 0.0])
    kinetic, static = batch.tool_friction()
    assert kinetic.shape == (2, len(batch.bodies)) and np.all(kinetic[0] == mu) and np.all(static[1] == 0.0)
    tool = sim.tool("grasper")
    g = tool.config
    sim.set_jaw_opening("grasper", g.min_radius)
    batch.set_actuator_goals([tool.jaw_actuator_id], [g.open_radius - g.min_radius])
    first, grip_peak, slipped, frictionless_slid = None, 0.0, 0, 0
    for k in range(2, STEPS + 1, 2):
        sim.physics_step(2)
        batch.step(2)
        jc, jb = sim.jaw_forces("grasper"), batch.jaw_forces("grasper")
        rc, rb = sim.tool_contact_report("grasper"), batch.tool_contact_report("grasper")
        grip = float(np.sum(jc["normal"]))
        bound = REL * grip + PER_NODE * rc["contacts"]
        for key in ("normal", "tangential"):
            err = np.abs(jb[key][0] - jc[key]).max()
            assert err <= bound, (k, key, err, bound)
        for key in ("normal_force", "tangential_force"):
            assert abs(rb[key][0] - rc[key]) <= 3 * bound, (k, key, rb[key][0], rc[key])
        assert (rb["contacts"][0], rb["slipping"][0]) == (rc["contacts"], rc["slipping"]), k
        np.testing.assert_array_equal(batch.contact_nodes(0), _cpu_contact_nodes(sim), err_msg=f"step {k}")
        assert abs(batch.jaw_openings("grasper")[0] - sim.jaw_opening("grasper")) < 1e-6, k
        # world 1: no friction, so no friction force and every loaded point slides
        assert np.all(jb["tangential"][1] == 0.0) and rb["tangential_force"][1] == 0.0, k
        if first is None and rc["contacts"]:
            first = k
        grip_peak = max(grip_peak, grip)
        slipped = max(slipped, rc["slipping"])
        frictionless_slid = max(frictionless_slid, int(rb["slipping"][1]))
    assert first is not None and first < 1000, f"the jaws must reach the tissue (first contact at step {first})"
    assert grip_peak > 0.05, f"the jaws must grip (peak grip {grip_peak:.3g} N)"
    assert slipped > 0 and frictionless_slid > 0, "the script must exercise the slipping count"
    assert np.sum(jb["tangential"][0]) > 1e-3, "world 0 grips with friction"
    # a reset world reads zero until its next step; the other keeps its readouts
    before = batch.jaw_forces("grasper")["normal"][0].copy()
    batch.reset_worlds([1])
    after = batch.jaw_forces("grasper")
    np.testing.assert_array_equal(after["normal"][1], 0.0)
    np.testing.assert_array_equal(after["normal"][0], before)
    assert batch.tool_contact_report("grasper")["contacts"][1] == 0 and not len(batch.contact_nodes(1))


def test_bad_friction_and_readout_requests_raise_clear_errors():
    import gymnasium as gym

    from surgsim_envs.batch.simulation import BatchSimulation
    from surgsim_envs.errors import ConfigError

    env = gym.make("SurgSim/Palpation-v0", **BATCHED).unwrapped
    env.reset(seed=0)
    batch = BatchSimulation(env.sim, 2, device="cpu")
    with pytest.raises(ConfigError, match=r"mu must be finite numbers >= 0, one per listed world \(2,\)"):
        batch.set_tool_friction([0.5, -1.0])
    with pytest.raises(ConfigError, match="mu_static must be >= mu"):
        batch.set_tool_friction([0.5, 0.5], [0.4, 0.6])
    with pytest.raises(ConfigError, match="tool 'probe' has no jaws"):
        batch.jaw_forces("probe")
    with pytest.raises(ConfigError, match="unknown tool 'grasper'"):
        batch.tool_contact_report("grasper")
