"""Compiled substeps for the tasks' default pairing: :class:`ContactModel` against
:class:`MassSpringModel` with its symplectic integrator (the loop is
:func:`surgsim_envs.scene.substeps_loop.run_substeps`; this module supplies the model's table
section, step and energy, and registers them in :mod:`surgsim_envs.scene.compiled_substeps`).

The step is ``MassSpringModel``'s symplectic step (``symplectic_step_work``, the spring pass's work
buffer ``MassSpringModel.spring_work``) with the Maxwell coefficients of
``MassSpringModel.symplectic_kernel_state``: those of the first step span the interval since the
last commit, those of the others span dt. The energy is the model's ``elastic_energy()``: springs
and Maxwell branches plus the per-tet volume term.
"""

from __future__ import annotations

from numba import njit

from surgsim_envs.contact.model import ContactModel
from surgsim_envs.scene.array_table import b1_1, f8_1, f8_2, i8_1, i8_2
from surgsim_envs.scene.compiled_substeps import register_compiled_substeps
from surgsim_envs.scene.substeps_loop import SubstepsRunner, TissueOps
from surgsim_envs.tissue.mass_spring import MassSpringModel
from surgsim_envs.tissue.msd_kernels import elastic_energy, symplectic_step_work, volume_energy

#: the model's table section (after the loop's common slots), in :func:`unpack` order
KINDS = ["f8_1", "f8_1", "f8_1", "b1_1", "i8_1", "i8_1", "f8_1", "f8_1", "f8_1",   # inv_mass .. K2
         "f8_1", "f8_1", "f8_1", "f8_1", "f8_1", "f8_1", "f8_2",                   # kMg0 .. f_buf
         "i8_2", "f8_1", "f8_1", "f8_2", "f8_1"]                                   # tets, V0, kv, work, kM


def arrays(tissue, dt: float) -> list:
    """The table section of ``tissue`` for steps of ``dt`` s (the model's own arrays)."""
    (_, _, inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0,
     kv) = tissue.symplectic_kernel_state(dt)
    return [inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0, kv,
            tissue.spring_work(), tissue.kM]


@njit(cache=True)
def unpack(tab, at):
    return (f8_1(tab, at), f8_1(tab, at + 1), f8_1(tab, at + 2), b1_1(tab, at + 3), i8_1(tab, at + 4),
            i8_1(tab, at + 5), f8_1(tab, at + 6), f8_1(tab, at + 7), f8_1(tab, at + 8), f8_1(tab, at + 9),
            f8_1(tab, at + 10), f8_1(tab, at + 11), f8_1(tab, at + 12), f8_1(tab, at + 13), f8_1(tab, at + 14),
            f8_2(tab, at + 15), i8_2(tab, at + 16), f8_1(tab, at + 17), f8_1(tab, at + 18), f8_2(tab, at + 19),
            f8_1(tab, at + 20))


@njit(cache=True, nogil=True)
def step(pos, vel, fext, dt, first, t):
    """One symplectic step of the model under external forces ``fext`` (N,3) N."""
    (inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, kMg0, decay0, kMg, decay, s, dl, f_buf, tets, V0, kv, work,
     _) = t
    if first:
        symplectic_step_work(pos, vel, inv_mass, b0, fext, gravity, fixed, dt, si, sj, L0, K1, K2, kMg0, decay0, s,
                             dl, f_buf, tets, V0, kv, work)
    else:
        symplectic_step_work(pos, vel, inv_mass, b0, fext, gravity, fixed, dt, si, sj, L0, K1, K2, kMg, decay, s,
                             dl, f_buf, tets, V0, kv, work)


@njit(cache=True)
def energy(pos, t):
    """``MassSpringModel.elastic_energy()`` (J) after a step of dt."""
    (_, _, _, _, si, sj, L0, K1, K2, _, _, kMg, decay, s, dl, _, tets, V0, kv, _, kM) = t
    return elastic_energy(pos, si, sj, L0, K1, K2, kM, kMg, decay, s, dl) + volume_energy(pos, tets, V0, kv)


def committed(tissue, dt: float) -> None:
    tissue.committed_symplectic_steps(dt)


OPS = TissueOps("run_substeps_mass_spring", unpack, step, energy, KINDS, arrays, committed)


def runner(sim, tissue, contact, fns) -> SubstepsRunner:
    return SubstepsRunner(sim, tissue, contact, fns, OPS)


register_compiled_substeps(ContactModel, MassSpringModel, "symplectic", runner)
