"""The explicit state protocol between the objects a step touches and the compiled loop: a tissue
model bumps ``state_version`` (``notify_changed()``) where it replaces arrays and only there; the
guard hands its state out and takes it back (``state()`` / ``load_state()``); the contact model
counts its preparations (``prepared_version``)."""

import numpy as np
import pytest

from surgsim_envs.contact import SPHERE, ContactModel, ContactParams
from surgsim_envs.errors import TissueUnstableError
from surgsim_envs.geometry import box_volume
from surgsim_envs.tissue.compiled import compiled_step_class, compiled_step_of
from surgsim_envs.tissue.guard import StabilityGuard
from surgsim_envs.tissue.mass_spring import MassSpringModel


def _model():
    return MassSpringModel(box_volume((0.02, 0.02, 0.02), 0.01), "liver")


def test_state_version_moves_where_arrays_are_replaced_and_only_there():
    m = _model()
    m.step(1e-4)                          # first step allocates its work buffer (a replacement)
    v = m.state_version
    m.step(1e-4)
    m.time = 0.5
    m.positions[0, 0] += 1e-6             # in place
    assert m.state_version == v
    for change in (m.reset, lambda: m.set_fixed([0]), m.release, lambda: m.scale_material("young", 2.0)):
        before = m.state_version
        change()
        assert m.state_version > before, change


def test_a_subclass_does_not_inherit_its_parents_compiled_step():
    """A subclass may change the physics, so only the class that names ``compiled_step_module``
    itself has a compiled step (checked without loading the compiled modules: no compilation)."""

    class Softer(MassSpringModel):
        name = "softer_test_only"

    assert MassSpringModel.compiled_step_module == "surgsim_envs.tissue.mass_spring_compiled"
    assert Softer.compiled_step_module == MassSpringModel.compiled_step_module     # inherited attribute...
    assert compiled_step_class(Softer) is None                                       # ...but not used
    assert compiled_step_of(Softer(box_volume((0.02, 0.02, 0.02), 0.01), "liver")) is None


def test_guard_state_round_trips_and_decides_the_error_message():
    m = _model()
    g = StabilityGuard()
    assert g.state() == (0.0, None, None, 0.0)
    pos, vel = m.positions.copy(), np.zeros_like(m.positions)
    g.load_state(2.5e-3, pos, vel, 0.125)
    energy, good_pos, good_vel, good_time = g.state()
    assert (energy, good_time) == (2.5e-3, 0.125) and good_pos is pos and good_vel is vel
    with pytest.raises(TissueUnstableError, match=r"last good state, t=0\.125 s"):
        g.fail(m, 1e-3, "test")
    g.load_state(0.0, None, None, 0.0)
    with pytest.raises(TissueUnstableError, match="evaluated on the rest state"):
        g.fail(m, 1e-3, "test")


def test_contact_prepared_version_counts_preparations_and_keeps_the_kernel_arrays():
    cm = ContactModel(4, np.arange(4), [0.3], ContactParams(stiffness=300.0, damping=0.5))
    kind, tool = np.array([SPHERE], dtype=np.int64), np.zeros(1, dtype=np.int64)
    size = np.array([[0.01, 0.0, 0.0]])
    v0 = cm.prepared_version
    cm.prepare(kind, tool, size, 1e-3)
    v1 = cm.prepared_version
    assert v1 > v0
    first, again = cm.kernel_state(), cm.kernel_state()
    arrays = [(a, b) for a, b in zip(first, again) if isinstance(a, np.ndarray)]
    assert len(arrays) > 20 and all(a.ctypes.data == b.ctypes.data for a, b in arrays)   # the same memory
    cm.prepare(kind, tool, size, 1e-3)
    assert cm.prepared_version > v1
