"""The contact kernel zeroes only the node rows it wrote last call and writes the contact states
only of the points that were in contact, instead of every touched row and every rejected point
(cheaper per substep). The outputs must be
those of zeroing everything every call, bit for bit: checked here call by call against the same
kernel told that every row and every point was written (which makes it zero all of them), and
through the compiled and the generic substep loops after a contact ends."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import surgsim_envs  # noqa: F401  (registers the tasks)
from surgsim_envs.contact import CAPSULE, SPHERE, ContactModel, ContactParams
from surgsim_envs.contact.model import _row_lists

#: Palpation-v0 on the explicit mass-spring network (its default model is the quasi-static FEM, which has no
#: compiled substep loop)
MASS_SPRING = {"model": "mass_spring", "spacing": 0.01}



def _grid(n=7, h=0.01):
    """An n x n node sheet at z = 0 (spacing h) and its triangles."""
    ij = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2)
    pos = np.c_[ij * h, np.zeros(len(ij))]
    tris = []
    for a in range(n - 1):
        for b in range(n - 1):
            p = a * n + b
            tris += [[p, p + n, p + 1], [p + 1, p + n, p + n + 1]]
    return pos, np.array(tris, dtype=np.int64)


def _outputs(cm):
    r = cm.result
    return [r.forces, r.stiffness, cm.node_tool_stiffness, r.tool_force, r.tool_torque, r.geom_normal_force,
            r.geom_tangential_force, cm._anchor_on, cm._anchor_local, cm.report.contacts, cm.report.slipping,
            cm.report.penetration, cm.report.normal_force, cm.report.tangential_force]


def _everything_listed(cm):
    """Tell the kernel that every touched row was written and every point is in contact: its next
    call then zeroes all of them, as the kernel did before this pass."""
    w0, a0 = _row_lists(len(cm.candidate_nodes), cm.n_samples)
    rows = cm._rows
    rows[0], rows[1] = len(cm._touched), cm.n_points
    rows[w0:w0 + len(cm._touched)] = cm._touched
    rows[a0:a0 + cm.n_points] = np.arange(cm.n_points)


def test_lazy_zeroing_matches_zeroing_everything_call_by_call():
    pos, tris = _grid()
    n = len(pos)
    cand = np.arange(0, n, 2)           # some nodes are touched only through the surface samples
    models = [ContactModel(n, cand, [0.4, 0.9], ContactParams(stiffness=300.0, damping=0.2),
                           surface=tris, surface_subdivisions=2) for _ in range(2)]
    kind, tool = np.array([SPHERE, CAPSULE]), np.array([0, 1])
    size = np.array([[0.012, 0, 0], [0.004, 0.01, 0]])
    gmat = np.tile(np.eye(3).reshape(1, 9), (2, 1))
    com = np.zeros((2, 3))
    rng = np.random.default_rng(0)
    vel = rng.normal(0, 0.01, (n, 3))
    # the tools come down, press and slide (stick and slip), leave, come back elsewhere, leave for good
    path = np.r_[np.linspace(0.03, -0.004, 15), np.full(10, -0.004), np.linspace(-0.004, 0.05, 8),
                 np.linspace(0.05, -0.003, 10), np.linspace(-0.003, 1.0, 5), np.full(3, 1.0)]
    seen_contact = False
    for k, z in enumerate(path):
        x = pos + rng.normal(0, 1e-4, pos.shape)
        gpos = np.array([[0.02 + 0.0005 * k, 0.03, z + 0.012], [0.045 - 0.001 * (k > 30), 0.02, z + 0.004]])
        gvel = rng.normal(0, 0.01, (2, 6))
        _everything_listed(models[1])
        res = [m.compute(x, vel, kind, tool, size, gpos, gmat, gvel, com, 1e-3) for m in models]
        for u, v in zip(_outputs(models[0]), _outputs(models[1])):
            np.testing.assert_array_equal(u, v)
        seen_contact |= bool(res[0].stiffness.any())
    assert seen_contact
    cm = models[0]
    # the tools are 1 m away: every row and every state is exactly zero again (positive zero)
    assert not cm._anchor_on.any() and cm._rows[0] == 0 and cm._rows[1] == 0
    for arr in (cm.result.forces, cm.result.stiffness, cm.node_tool_stiffness):
        assert np.all(arr == 0.0) and not np.signbit(arr).any()


def test_contact_outputs_zero_after_the_probe_leaves_in_both_loops():
    envs = [gym.make("SurgSim/Palpation-v0", **MASS_SPRING) for _ in range(2)]
    for e in envs:
        e.reset(seed=3)
    envs[1].unwrapped.sim.compiled_substeps = False
    sims = [e.unwrapped.sim for e in envs]
    assert sims[0].compiled_runner() is not None and sims[1].compiled_runner() is None
    a = np.zeros(envs[0].action_space.shape, dtype=np.float32)
    a[-1] = -1.0
    touched = 0
    for z in [*np.linspace(-1.0, 0.8, 20), *[-1.0] * 40]:
        a[2] = z
        outs = [e.step(a) for e in envs]
        np.testing.assert_array_equal(outs[0][0], outs[1][0])
        touched += int(next(iter(sims[0].contacts.values())).report.contacts.sum())
    assert touched > 0, "no contact in the run: the check would be vacuous"
    cms = [next(iter(s.contacts.values())) for s in sims]
    for cm in cms:
        assert not cm._anchor_on.any(), "the probe should have left the tissue"
        for arr in (cm.result.forces, cm.result.stiffness, cm.node_tool_stiffness, cm.result.tool_force):
            assert np.all(arr == 0.0) and not np.signbit(arr).any()
    np.testing.assert_array_equal(sims[0].tissue().positions, sims[1].tissue().positions)
