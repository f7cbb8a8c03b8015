"""fem_static's relaxation in the scene users meet: a Palpation-v0 press held still relaxes to the
force of the same press on the relaxed material (moduli x (1 - g)), the long-term equilibrium of the
standard linear solid, and starts near the force of the instantaneous material."""

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401

G, TAU = 0.5, 0.2            # s: a short relaxation time keeps the hold short (10 tau)
NO_LUMP = {"stiffness_contrast": (1.0, 1.0), "young_scale": (1.0, 1.0)}


def _press(material, depth=0.005, hold=10 * TAU):
    env = gym.make("SurgSim/Palpation-v0", model="fem_static", spacing=0.01, material=material,
                   disable_env_checker=True).unwrapped
    env.reset(seed=0, options=NO_LUMP)
    sim, c = env.sim, env.config
    top = env.surface_z + c.tip_radius
    forces = []

    def run(seconds):
        for _ in range(int(round(seconds / env.control_dt))):
            sim.step()
            forces.append(float(sim.tool_force("probe")[2]))

    sim.set_tool_target("probe", [0.0, 0.0, top + c.hover], speed=c.probe_speed)
    run(0.05)
    sim.set_tool_target("probe", [0.0, 0.0, top - depth], speed=c.probe_speed)
    run((c.hover + depth) / c.probe_speed + 0.01)
    arrived = len(forces)
    run(hold)
    env.close()
    return np.array(forces), arrived


def test_a_held_press_relaxes_to_the_relaxed_materials_force_frictionless():
    base = {"preset": "liver", "young": 4000.0, "friction": 0.0}
    visco, arrived = _press({**base, "relax_fraction": G, "relax_time": TAU})
    relaxed, _ = _press({**base, "young": 4000.0 * (1.0 - G), "relax_fraction": 0.0})
    instant, _ = _press({**base, "relax_fraction": 0.0})
    assert relaxed[-1] > 0.05                            # a real press (N)
    # after 10 tau the hereditary part is exp(-10) = 5e-5 of its start (the contact in series slows it
    # a little): the long-term equilibrium
    assert visco[-1] == pytest.approx(relaxed[-1], rel=2e-3)
    # on arrival it has relaxed only over the 35 ms ramp (g T / (2 tau) ~ 4 %)
    assert 0.85 * instant[arrived - 1] < visco[arrived - 1] < instant[arrived - 1]
    assert np.all(np.diff(visco[arrived + 1:]) <= 1e-12)  # held still, it only relaxes
