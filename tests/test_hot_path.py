"""The scene's hot path (prepared contact, pre-validated tissue step) gives exactly what the checked public calls give:
ContactModel.compute_prepared == compute, TissueModel.step_prevalidated == step, and NaN input
is still refused with the same error and an untouched state."""

from __future__ import annotations

import numpy as np
import pytest

from surgsim_envs.contact import BOX, SPHERE, ContactModel, ContactParams
from surgsim_envs.errors import ConfigError, NonFiniteInputError
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue.registry import make

DT = 1e-3


def _tissue():
    vol = box_volume(size=(0.04, 0.04, 0.02), spacing=0.01)
    return make("mass_spring", vol, "liver", fixed=np.flatnonzero(vol.nodes[:, 2] < -0.009))


def _scene(tissue):
    top = tissue.rest_positions[:, 2].max()
    kind = np.array([SPHERE, BOX], dtype=np.int64)
    tool = np.array([0, 1], dtype=np.int64)
    size = np.array([[0.006, 0, 0], [0.004, 0.004, 0.002]])
    pos = np.array([[0.0, 0.0, top + 0.004], [0.012, 0.0, top + 0.0015]])
    mat = np.tile(np.eye(3).reshape(-1), (2, 1))
    vel = np.zeros((2, 6))
    vel[:, 5] = -0.05
    vel[1, 3] = 0.02
    com = pos.copy()
    return kind, tool, size, pos, mat, vel, com


def _contact(tissue):
    return ContactModel(tissue.n_nodes, tissue.surface_nodes, [0.3, 0.5], ContactParams(stiffness=300.0),
                        node_masses=tissue.masses)


def test_prepared_contact_and_tissue_step_match_the_checked_calls_bit_for_bit():
    a, b = _tissue(), _tissue()
    ca, cb = _contact(a), _contact(b)
    kind, tool, size, pos, mat, vel, com = _scene(a)
    cb.prepare(kind, tool, size, DT)
    touched = 0
    for k in range(60):
        pos[:, 2] -= 0.05 * DT          # the tools press in and slide
        pos[1, 0] += 0.02 * DT
        ra = ca.compute(a.positions, a.velocities, kind, tool, size, pos, mat, vel, com, DT)
        a.step(DT, ra.forces, ra.stiffness)
        ca.attribute_increment(a.integrated_external_forces)
        rb = cb.compute_prepared(b.positions, b.velocities, pos, mat, vel, com)
        b.step_prevalidated(DT, rb.forces, rb.stiffness)
        cb.attribute_increment_prepared(b.integrated_external_forces)
        touched += int(ra.report.contacts.sum())
        for x, y in ((ra.forces, rb.forces), (ra.stiffness, rb.stiffness), (ra.tool_force, rb.tool_force),
                     (ra.tool_torque, rb.tool_torque), (a.positions, b.positions), (a.velocities, b.velocities)):
            np.testing.assert_array_equal(x, y)
    assert touched > 0, "the tools never touched the tissue: the comparison would be vacuous"


def test_step_prevalidated_refuses_nan_forces_like_step_and_keeps_the_state():
    t = _tissue()
    f = np.zeros_like(t.positions)
    f[5, 1] = np.nan
    before = t.positions.copy()
    with pytest.raises(NonFiniteInputError, match="node 5"):
        t.step_prevalidated(DT, f, None)
    k = np.zeros(t.n_nodes)
    k[7] = np.inf
    with pytest.raises(NonFiniteInputError, match="contact stiffness.*node 7"):
        t.step_prevalidated(DT, np.zeros_like(t.positions), k)
    np.testing.assert_array_equal(t.positions, before)
    assert t.steps == 0


def test_compute_prepared_needs_prepare_and_reports_bad_shapes():
    t = _tissue()
    c = _contact(t)
    kind, tool, size, pos, mat, vel, com = _scene(t)
    with pytest.raises(ConfigError, match="prepare"):
        c.compute_prepared(t.positions, t.velocities, pos, mat, vel, com)
    with pytest.raises(ConfigError, match="shape_tool"):
        c.prepare(kind, tool[:1], size, DT)
    bad = size.copy()
    bad[0, 0] = -1.0
    c.prepare(kind, tool, bad, DT)
    with pytest.raises(ConfigError, match=r"shape_size\[0\]"):
        c.compute_prepared(t.positions, t.velocities, pos, mat, vel, com)
