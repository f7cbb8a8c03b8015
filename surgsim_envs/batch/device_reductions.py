"""Warp functions that reduce a few float64 numbers in the order the host's numpy, BLAS or Python
does, so that a task's device path (``device_outputs=True``) reproduces its numpy path bit for bit.

The calling kernels' modules compile without floating-point contraction (``fuse_fp=False``), as
this module does, so no product is fused into a sum:

* :func:`einsum_norm`: sqrt of ``np.einsum("ij,ij->i", f, f)`` of a row of 3, ``(f0 f0 + f2 f2) +
  f1 f1`` (its SIMD lanes, x86-64);
* :func:`dot_norm`: ``np.linalg.norm`` of a 3-vector and ``vector_norm``, sqrt of ``v.dot(v)``
  (BLAS, in order);
* :func:`python_sum_add` / :func:`python_sum_total`: ``sum()`` of Python floats from 0, in order;
  from Python 3.12 ``sum`` compensates (Neumaier), before it adds plainly: the caller passes which.
"""

from __future__ import annotations

import sys

import warp as wp

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"fuse_fp": False, "enable_backward": False})

#: this interpreter's ``sum()`` of floats is compensated (Neumaier's algorithm, Python 3.12+)
PYTHON_SUM_COMPENSATED = sys.version_info >= (3, 12)


@wp.func
def einsum_norm(v: wp.vec3d) -> wp.float64:
    """sqrt of ``np.einsum("ij,ij->i", f, f)`` of one row of 3 (x86-64 SIMD order)."""
    return wp.sqrt((v[0] * v[0] + v[2] * v[2]) + v[1] * v[1])


@wp.func
def dot_norm(v: wp.vec3d) -> wp.float64:
    """``vector_norm``: sqrt of ``v.dot(v)`` (BLAS, in order)."""
    return wp.sqrt((v[0] * v[0] + v[1] * v[1]) + v[2] * v[2])


@wp.func
def python_sum_add(acc: wp.vec2d, x: wp.float64, compensated: int) -> wp.vec2d:
    """One more term of Python's ``sum()``: ``acc`` is (running sum, compensation), (0, 0) at the
    start; ``compensated`` != 0 for Python 3.12+ (Neumaier), else a plain addition."""
    f = acc[0]
    t = f + x
    c = acc[1]
    if compensated != 0:
        if wp.abs(f) >= wp.abs(x):
            c = c + ((f - t) + x)
        else:
            c = c + ((x - t) + f)
    return wp.vec2d(t, c)


@wp.func
def python_sum_total(acc: wp.vec2d) -> wp.float64:
    """The value ``sum()`` returns for the terms added into ``acc`` (the compensation added when it
    is non-zero and finite, as CPython does)."""
    c = acc[1]
    if c != wp.float64(0.0) and wp.isfinite(c):
        return acc[0] + c
    return acc[0]
