"""An address table: many numpy arrays handed to a numba function as ONE int64 array.

Calling a numba function costs ~0.2 us per array argument (typing and unboxing each one; measured
16.7 us for a tuple of 80 arrays, 0.18 us for one array: CHANGELOG.md "Env step: address
table, pluggable tissue step"). The compiled substeps take ~90 arrays once per control step, so :class:`ArrayTable` packs
them once (rebuilt only when one of them is replaced) into rows ``[address, shape0, shape1,
shape2]``, and the compiled side rebuilds each array with ``numba.carray`` from its row
(:func:`f8_1` ... :func:`u1_2`: float64 / int64 / bool / uint8, 1-3 dimensions). The rebuilt arrays
are views of the same memory (no copy; C-contiguous, as checked when packing).

The table keeps a reference to every array it packed, so none is freed while the table lives;
the caller must rebuild it when an array is *replaced* (a new object): :meth:`ArrayTable.update`
repacks when the caller's key (e.g. the ids of the arrays that can be replaced) changes.
"""

from __future__ import annotations

import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic

#: kind -> (dtype, ndim) of the accessors below
KINDS = {"f8_1": (np.float64, 1), "f8_2": (np.float64, 2), "f8_3": (np.float64, 3), "i8_1": (np.int64, 1),
         "i8_2": (np.int64, 2), "b1_1": (np.bool_, 1), "u1_2": (np.uint8, 2)}


class ArrayTable:
    """The (n, 4) int64 table of a list of arrays (each C-contiguous, of the dtype and dimension its
    kind names, see :data:`KINDS`), kept until the caller's key changes."""

    def __init__(self):
        self._key: tuple | None = None
        self._keep: list = []
        self.table = np.zeros((0, 4), dtype=np.int64)

    def update(self, key: tuple, make_arrays, kinds) -> np.ndarray:
        """The table of ``make_arrays()`` (called only when ``key`` differs from the last one).
        ``key``: a tuple of ints that changes whenever any of the arrays is replaced, typically
        the ``id`` of every array that can be replaced (the table keeps every array it packed
        alive, so an id cannot be reused by another object while the table holds it)."""
        if key != self._key:
            arrays = list(make_arrays())
            self.table = self._pack(arrays, kinds)
            self._keep = arrays
            self._key = key
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
def _pointer(typingctx, addr, dtype):
    """``(dtype *) addr`` for an integer address and a numba number class (``np.float64`` ...)."""
    ty = dtype.instance_type
    sig = types.CPointer(ty)(types.int64, dtype)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_data_type(ty).as_pointer())

    return sig, codegen


@njit(cache=True, inline="always")
def f8_1(tab, i):
    return carray(_pointer(tab[i, 0], np.float64), (tab[i, 1],))


@njit(cache=True, inline="always")
def f8_2(tab, i):
    return carray(_pointer(tab[i, 0], np.float64), (tab[i, 1], tab[i, 2]))


@njit(cache=True, inline="always")
def f8_3(tab, i):
    return carray(_pointer(tab[i, 0], np.float64), (tab[i, 1], tab[i, 2], tab[i, 3]))


@njit(cache=True, inline="always")
def i8_1(tab, i):
    return carray(_pointer(tab[i, 0], np.int64), (tab[i, 1],))


@njit(cache=True, inline="always")
def i8_2(tab, i):
    return carray(_pointer(tab[i, 0], np.int64), (tab[i, 1], tab[i, 2]))


@njit(cache=True, inline="always")
def b1_1(tab, i):
    return carray(_pointer(tab[i, 0], np.bool_), (tab[i, 1],))


@njit(cache=True, inline="always")
def u1_2(tab, i):
    return carray(_pointer(tab[i, 0], np.uint8), (tab[i, 1], tab[i, 2]))

