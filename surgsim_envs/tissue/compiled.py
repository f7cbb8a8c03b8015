"""The compiled-step ABI: how a tissue model's own compiled step is called from a compiled loop.

A model that can be stepped from compiled code (the scene's compiled substeps) names the module of
its compiled step in the class attribute ``compiled_step_module`` (exact class only: a subclass
that changes the physics does not inherit it). That module defines ``COMPILED_STEP``, a
:class:`CompiledStep`: two numba ``cfunc`` s and the Python bookkeeping around them.

**The address table.** A compiled caller passes every array as ONE (rows, 4) int64 array, a row
``[address, shape0, shape1, shape2]`` per array (:class:`ArrayTable`; numba unboxes ~0.2 us per
array argument: 16-30 us per control step for the ~90 arrays when they were passed one by one,
CHANGELOG.md "Env step: address table, pluggable tissue step"). The accessors :func:`f8_1` ...
:func:`u1_2` rebuild each array from its row (float64 / int64 / bool / uint8, 1-3 dimensions,
C-contiguous views of the same memory, no copy). Layout:

* rows ``0 .. STEP_ROWS - 1`` (:data:`STEP_KINDS`, read with :func:`step_arrays`): positions (N,3) m,
  velocities (N,3) m/s, external (contact) forces (N,3) N, their stiffness (N,) N/m,
  ``integrated_external_forces`` (N,3) N, and the integrator state ``auto`` (5,): [critical dt,
  its dt, its step, 1 if this step is implicit, CG iterations of the last implicit step];
* rows ``MODEL_ROW ..``: the model's own section, ``CompiledStep.kinds``, the arrays
  ``CompiledStep.arrays(tissue, dt)`` returns (the model unpacks them at ``MODEL_ROW``);
* after that, the caller's own rows.

**The functions** (integer addresses, so a caller stays cacheable: numba keys a jitted-function
*argument* by its address, which would recompile in every process; called with :func:`call_step`,
:func:`call_energy`):

* ``step(tab_address, rows, dt, first, implicit) -> int`` (:func:`step_signature`): one step of dt
  in place under the external forces; ``first``: the first step since the last commit (its Maxwell
  coefficients span the interval since then); ``implicit``: integrator "auto" picked the implicit
  step (it writes the CG iterations to ``auto[4]``). Returns 1 if it changed
  ``integrated_external_forces`` (then the caller gives the tools the reaction of the difference).
* ``energy(tab_address, rows) -> float`` (:func:`energy_signature`): the stored elastic energy (J),
  as ``elastic_energy()``.

Being calls through a pointer, the model's kernels are never inlined into the caller: with fastmath
kernels, inlining changed the last bit of the calibrated model's volume forces; through the pointer
the step runs the same code as when Python calls it (bit for bit the model's Python step).
"""

from __future__ import annotations

import importlib
from typing import Callable

import numpy as np
from llvmlite import ir
from numba import carray, njit, types
from numba.extending import intrinsic

#: kind -> (dtype, ndim) of the accessors below
KINDS = {"f8_1": (np.float64, 1), "f8_2": (np.float64, 2), "f8_3": (np.float64, 3), "i8_1": (np.int64, 1),
         "i8_2": (np.int64, 2), "b1_1": (np.bool_, 1), "u1_2": (np.uint8, 2)}


class ArrayTable:
    """The (n, 4) int64 table of a list of arrays (each C-contiguous, of the dtype and dimension its
    kind names, see :data:`KINDS`), kept until the caller's key changes."""

    def __init__(self):
        #: the caller's key of the arrays last packed (None: none yet)
        self.key: tuple | None = None
        self._keep: list = []
        self.table = np.zeros((0, 4), dtype=np.int64)

    def update(self, key: tuple, make_arrays, kinds) -> np.ndarray:
        """The table of ``make_arrays()`` (called only when ``key`` differs from the last one).
        ``key``: a tuple of ints that changes whenever any of the arrays is replaced, typically
        the ``id`` of every array that can be replaced (the table keeps every array it packed
        alive, so an id cannot be reused by another object while the table holds it)."""
        if key != self.key:
            arrays = list(make_arrays())
            self.table = self._pack(arrays, kinds)
            self._keep = arrays
            self.key = key
        return self.table

    @staticmethod
    def _pack(arrays, kinds) -> np.ndarray:
        if len(arrays) != len(kinds):
            raise ValueError(f"{len(arrays)} arrays for {len(kinds)} kinds")
        tab = np.zeros((len(arrays), 4), dtype=np.int64)
        for i, (a, kind) in enumerate(zip(arrays, kinds)):
            dtype, ndim = KINDS[kind]
            if not (isinstance(a, np.ndarray) and a.dtype == dtype and a.ndim == ndim and a.flags.c_contiguous):
                raise TypeError(f"array table slot {i}: expected a C-contiguous {np.dtype(dtype).name} array of "
                                f"{ndim} dimension(s) ({kind}), got "
                                f"{type(a).__name__} {getattr(a, 'dtype', '')} {getattr(a, 'shape', '')}")
            tab[i, 0] = a.ctypes.data
            tab[i, 1:1 + ndim] = a.shape
        return tab


@intrinsic
def pointer(typingctx, addr, dtype):
    """``(dtype *) addr`` for an integer address and a numba number class (``np.float64`` ...)."""
    ty = dtype.instance_type
    sig = types.CPointer(ty)(types.int64, dtype)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_data_type(ty).as_pointer())

    return sig, codegen


@njit(cache=True, inline="always")
def f8_1(tab, i):
    return carray(pointer(tab[i, 0], np.float64), (tab[i, 1],))


@njit(cache=True, inline="always")
def f8_2(tab, i):
    return carray(pointer(tab[i, 0], np.float64), (tab[i, 1], tab[i, 2]))


@njit(cache=True, inline="always")
def f8_3(tab, i):
    return carray(pointer(tab[i, 0], np.float64), (tab[i, 1], tab[i, 2], tab[i, 3]))


@njit(cache=True, inline="always")
def i8_1(tab, i):
    return carray(pointer(tab[i, 0], np.int64), (tab[i, 1],))


@njit(cache=True, inline="always")
def i8_2(tab, i):
    return carray(pointer(tab[i, 0], np.int64), (tab[i, 1], tab[i, 2]))


@njit(cache=True, inline="always")
def b1_1(tab, i):
    return carray(pointer(tab[i, 0], np.bool_), (tab[i, 1],))


@njit(cache=True, inline="always")
def u1_2(tab, i):
    return carray(pointer(tab[i, 0], np.uint8), (tab[i, 1], tab[i, 2]))



# ---------------------------------------------------------------------------------------------
# the step ABI
#: kinds of the first rows of the table: positions, velocities, external forces, their stiffness,
#: integrated_external_forces, the integrator state "auto" (see the module docstring)
STEP_KINDS = ["f8_2", "f8_2", "f8_2", "f8_1", "f8_2", "f8_1"]
STEP_ROWS = len(STEP_KINDS)
#: the row where a model's own section starts
MODEL_ROW = STEP_ROWS


def step_signature():
    """numba signature of a model's step function (see the module docstring)."""
    return types.int64(types.int64, types.int64, types.float64, types.int64, types.int64)


def energy_signature():
    """numba signature of a model's energy function (see the module docstring)."""
    return types.float64(types.int64, types.int64)


@njit(cache=True, inline="always")
def table_at(address, rows):
    """The (rows, 4) address table at ``address`` (inside a model's step / energy function)."""
    return carray(pointer(address, np.int64), (rows, 4))


@njit(cache=True, inline="always")
def step_arrays(tab):
    """(positions, velocities, external forces, their stiffness, integrated_external_forces, auto):
    the table's first ``STEP_ROWS`` rows."""
    return f8_2(tab, 0), f8_2(tab, 1), f8_2(tab, 2), f8_1(tab, 3), f8_2(tab, 4), f8_1(tab, 5)


@intrinsic
def call_step(typingctx, fn, address, rows, dt, first, implicit):
    """``fn(address, rows, dt, first, implicit)`` for the integer address ``fn`` of a step function."""
    sig = types.int64(types.int64, types.int64, types.int64, types.float64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64, f64 = ir.IntType(64), ir.DoubleType()
        fnty = ir.FunctionType(i64, [i64, i64, f64, i64, i64])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), list(args[1:]))

    return sig, codegen


@intrinsic
def call_energy(typingctx, fn, address, rows):
    """``fn(address, rows)`` for the integer address ``fn`` of an energy function."""
    sig = types.float64(types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(ir.DoubleType(), [i64, i64])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), list(args[1:]))

    return sig, codegen


class CompiledStep:
    """A model's compiled step (see the module docstring) and the Python bookkeeping around it.

    step, energy: numba ``cfunc`` objects of :func:`step_signature` / :func:`energy_signature`.
    kinds: the kinds of the model's table section; integrators: the integrators it serves.
    arrays(tissue, dt): that section's arrays (the model's own, valid until replaced).
    key(tissue, dt): a hashable that changes whenever ``arrays`` would return other arrays besides
        what :meth:`table_key` already covers (e.g. the interval its coefficients span).
    committed(tissue, dt): the model's bookkeeping after a caller stepped it at least once.
    Subclasses may refine :meth:`applies`, :meth:`plan`, :meth:`finish` and :meth:`active_after`.
    """

    def __init__(self, step, energy, kinds, integrators, arrays: Callable, key: Callable, committed: Callable):
        self.step, self.energy = step, energy
        self.kinds, self.integrators = list(kinds), tuple(integrators)
        self.arrays, self.key, self.committed = arrays, key, committed

    def table_key(self, tissue, dt: float) -> tuple:
        """Changes whenever the table's tissue rows must be repacked: the model's
        :attr:`~surgsim_envs.tissue.base.TissueModel.state_version` (bumped by ``notify_changed()``:
        reset, a material change, new buffers), the identity of ``positions`` and ``velocities``
        (which callers may assign) and :attr:`key`."""
        return (tissue.state_version, id(tissue.positions), id(tissue.velocities), self.key(tissue, dt))

    def applies(self, tissue, rigid_subcycles: int) -> bool:
        """Whether a compiled caller can step ``tissue`` with ``rigid_subcycles`` tissue steps per
        call-free stretch (a MuJoCo step); False: the caller keeps its Python loop."""
        return True

    def plan(self, tissue, dt: float) -> int | None:
        """Called before a caller's compiled run: the most steps it may take before calling again
        (the model re-evaluates something in Python then), or None for no limit."""
        return None

    def finish(self, tissue) -> None:
        """Called after a run that :meth:`plan` limited."""

    def active_after(self, tissue, implicit: bool) -> str:
        """The concrete integrator integrator "auto" took when the last step was ``implicit``."""
        explicit, implicit_name = tissue.auto_pair
        return implicit_name if implicit else explicit

    def commit(self, tissue, dt: float, implicit: bool) -> None:
        """Bookkeeping after a caller took at least one step of ``dt`` with this compiled step (the
        last one ``implicit`` or not): the model's own, then the tissue's record of the last step."""
        self.committed(tissue, dt)
        tissue.record_compiled_step(dt, self.active_after(tissue, implicit) if tissue.integrator == "auto" else None)


_LOADED: dict[type, CompiledStep | None] = {}


def compiled_step_class(cls) -> CompiledStep | None:
    """The compiled step model class ``cls`` itself declares (``compiled_step_module``, not
    inherited), loaded on first use; None if it declares none."""
    if cls not in _LOADED:
        module = cls.__dict__.get("compiled_step_module")
        _LOADED[cls] = importlib.import_module(module).COMPILED_STEP if module else None
    return _LOADED[cls]


def compiled_step_of(tissue) -> CompiledStep | None:
    """The compiled step for ``tissue`` (its exact class, its integrator), or None."""
    ops = compiled_step_class(type(tissue))
    if ops is None or str(tissue.integrator) not in ops.integrators:
        return None
    return ops
