"""Contact readings give the force the tissue integrated (surgsim_envs/contact/integrated_readings.py).

An implicit or quasi-static tissue step integrates the penalty linearised about the step's start,
not the penalty evaluated there. The tools get the reaction of the integrated force; the readings
(per geom: ``geom_normal_force``, ``geom_tangential_force``; per tool: the report's ``normal_force``
and ``tangential_force``; the grasper's ``jaw_forces``) must report that same force. Checked
against the tool's own reaction on a flat punch, whose normal is one direction, so that the normal
reading must equal the reaction along it to rounding; and in Grasp-v0 with the quasi-static
``fem_static`` during a closure, where the start-of-step penalty read 0.1-25 N per jaw while the
tissue integrated under 0.02 N.
"""

import gymnasium as gym
import numpy as np
import pytest

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.contact import BOX, ContactModel, ContactParams
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue import registry

ELASTIC = {"young": 3000.0, "poisson": 0.45, "relax_fraction": 0.0}


def _punch(model_name, subdivisions, steps=60, stiffness=2000.0, **options):
    """A flat box punch (half extents 7.5 x 7.5 x 5 mm, face down) lowered 1.5 mm into a 4 x 4 x 2 cm
    block (5 mm lattice, bottom held) over 40 steps of 1 ms, then held; frictionless. Yields per step
    (the start-of-step penalty's normal reading, the normal reading after the step, the tool's
    reaction along the face normal (z up), tangential reading, report normal, report tangential)."""
    vol = box_volume((0.04, 0.04, 0.02), 0.005, center=(0.0, 0.0, 0.01))
    model = registry.get(model_name)(vol, ELASTIC, fixed=np.isclose(vol.nodes[:, 2], 0.0), **options)
    top = np.flatnonzero(np.isclose(model.rest_positions[:, 2], 0.02))
    surface = dict(surface=model.surface, surface_subdivisions=subdivisions) if subdivisions > 1 else {}
    cm = ContactModel(model.n_nodes, top, [0.0], ContactParams(stiffness=stiffness, damping=0.0), **surface)
    kind, tool, size = np.array([BOX]), np.array([0]), np.array([[0.0075, 0.0075, 0.005]])
    vel = np.zeros((1, 6))
    for i in range(steps):
        vel[0, 5] = -0.0375 if i < 40 else 0.0
        z = 0.0201 + 0.005 - 0.0016 * min(1.0, i / 40)
        res = cm.compute(model.positions, model.velocities, kind, tool, size, [[0.0, 0.0, z]], np.eye(3).reshape(1, 9),
                         vel, np.zeros((1, 3)), 1e-3)
        before = float(res.geom_normal_force[0])
        model.step(1e-3, res.forces, res.stiffness)
        cm.attribute_increment(model.integrated_external_forces)
        r = cm.result
        yield (before, float(r.geom_normal_force[0]), float(r.tool_force[0, 2]), float(r.geom_tangential_force[0]),
               float(cm.report.normal_force[0]), float(cm.report.tangential_force[0]))


@pytest.mark.parametrize("subdivisions", [1, 2])
def test_quasi_static_punch_reads_the_reaction_the_tool_gets(subdivisions):
    """fem_static under a moving flat punch: the normal reading after the step equals the tool's
    reaction along the face normal to 1e-12 relative at every step in contact (nodes only, and with
    surface samples splitting each node's increment among its points), the report agrees with the
    geom; and the start-of-step penalty, which the readings gave before, differs from it by more
    than 30 % while the punch moves (so the check can fail)."""
    rows = np.array(list(_punch("fem_static", subdivisions)))
    contact = rows[:, 2] > 1e-6
    assert contact.sum() > 30
    np.testing.assert_allclose(rows[contact, 1], rows[contact, 2], rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(rows[:, 4], rows[:, 1])          # one geom, one tool: the same sum
    np.testing.assert_array_equal(rows[:, 5], rows[:, 3])
    moving = contact.copy()
    moving[40:] = False
    assert np.max(np.abs(rows[moving, 0] / rows[moving, 2] - 1.0)) > 0.3
    assert rows[-1, 2] > 0.05                                       # pressed: tens of mN on the punch


def test_explicit_step_readings_unchanged():
    """An explicit step integrates the contact force itself: the readings after attribute_increment
    are the start-of-step penalty's, bit for bit (the mass-spring network, symplectic Euler)."""
    rows = np.array(list(_punch("mass_spring", 1, steps=45, stiffness=20.0, integrator="symplectic")))
    assert np.any(rows[:, 0] > 0)
    np.testing.assert_array_equal(rows[:, 0], rows[:, 1])


def test_grasp_closure_jaw_readings_follow_the_integrated_force():
    """Grasp-v0 with fem_static (the table's closest model), frictionless, the jaws closing through
    first contact at 5 mm/s: at every control step the three jaw normal readings sum to no more than
    the magnitudes of the forces the tissue integrated (equal when each node meets one flat face),
    and the report's normal force for the grasper equals the jaws' sum when only the jaws touch."""
    env = gym.make("SurgSim/Grasp-v0", model="fem_static", disable_env_checker=True).unwrapped
    env.reset(seed=0, options={"mu": (0.0, 0.0), "young_scale": (1.0, 1.0)})
    sim = env.sim
    tissue = sim.tissue()
    touched = 0
    for i in range(34):
        close = -0.45 + 0.25 * max(0, i - 12) / 21
        env.step(np.array([0.0, 0.0, 0.0, close], dtype=np.float32))
        jaws = sim.jaw_forces(env.tool_name)["normal"]
        integrated = float(np.linalg.norm(tissue.integrated_external_forces, axis=1).sum())
        assert jaws.sum() <= integrated * (1 + 1e-9) + 1e-12, (i, jaws, integrated)
        assert np.all(jaws >= -1e-12)
        touched += jaws.sum() > 1e-3
        report = sim.tool_contact_report(env.tool_name)["normal_force"]
        assert report >= jaws.sum() - 1e-12 * max(1.0, report)
    assert touched >= 10
    env.close()
