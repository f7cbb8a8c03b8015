"""MuJoCo's ``mj_step1`` / ``mj_step2`` callable from numba-compiled code.

The compiled substep loop (:mod:`surgsim_envs.scene.step.compiled`) runs every physics substep of a
control step in one numba call, so it must call MuJoCo without going back to Python. The Python
bindings expose the C pointers of a model and its data (``MjModel._address``, ``MjData._address``)
and ship the shared library they are linked against (``mujoco/libmujoco.so.*``); loading that same
file with ctypes gives the same library instance (one copy of MuJoCo's global state), and
:func:`call_model_data` calls a ``void f(const mjModel*, mjData*)`` through its address. Addresses
are arguments, not constants baked into the code, so the kernels stay cacheable (``cache=True``).

Caveat (documented choice): a MuJoCo *error* raised inside such a call (not a warning: warnings are
only counted in ``mjData.warning``) would go to the bindings' error handler without a Python frame
to turn it into an exception. ``mj_step1``/``mj_step2`` raise errors only for malformed models,
which the bindings' own ``mj_forward`` in ``Simulation.reset`` has already run on.
"""

from __future__ import annotations

import ctypes
import glob
import os

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


@intrinsic
def call_model_data(typingctx, fn, model, data):
    """``fn(model, data)`` for integer addresses (intp) of a ``void f(const mjModel*, mjData*)``,
    an ``mjModel`` and an ``mjData``."""
    sig = types.void(types.intp, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        fnp, pm, pd = args
        voidptr = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [voidptr, voidptr])
        f = builder.inttoptr(fnp, fnty.as_pointer())
        builder.call(f, [builder.inttoptr(pm, voidptr), builder.inttoptr(pd, voidptr)])
        return context.get_dummy_value()

    return sig, codegen


_LIB = None


def _library() -> ctypes.CDLL:
    global _LIB
    if _LIB is None:
        import mujoco

        folder = os.path.dirname(mujoco.__file__)
        found = sorted(glob.glob(os.path.join(folder, "libmujoco.so*")) + glob.glob(os.path.join(folder, "libmujoco*.dylib"))
                       + glob.glob(os.path.join(folder, "mujoco.dll")))
        if not found:
            raise OSError(f"no MuJoCo shared library next to the bindings in {folder}")
        _LIB = ctypes.CDLL(found[0])
    return _LIB


def step_functions() -> tuple[int, int]:
    """``(address of mj_step1, address of mj_step2)`` in the library the bindings use.
    Raises OSError if the library cannot be found (callers then keep the Python loop)."""
    lib = _library()
    return (ctypes.cast(lib.mj_step1, ctypes.c_void_p).value, ctypes.cast(lib.mj_step2, ctypes.c_void_p).value)


def model_data_addresses(model, data) -> tuple[int, int]:
    """``(mjModel*, mjData*)`` of a bindings ``MjModel`` / ``MjData`` as integers."""
    return int(model._address), int(data._address)
