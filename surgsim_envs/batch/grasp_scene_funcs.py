"""Warp functions the grasp tasks' device kernels share (Grasp-v0 and Slippage-v0 read one grasp scene):
the wrist's position, a tool's contact counts and the centroid of the nodes a slip tracker follows,
each in the host code's arithmetic order."""

from __future__ import annotations

import warp as wp

# as the calling kernels' modules: no floating-point contraction; forward kernels only (nothing differentiates
# them, and adjoints would double the compile time)
wp.set_module_options({"fuse_fp": False, "enable_backward": False})

@wp.func
def wrist_position(xpos: wp.array2d(dtype=wp.vec3f), w: int, body: int) -> wp.vec3d:
    p = xpos[w, body]
    return wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))


@wp.func
def tool_count(counts: wp.array2d(dtype=wp.int32), rows: wp.array(dtype=wp.int32), w: int) -> int:
    """The tool's contact (or slipping) points: its bodies' counts summed."""
    n = int(0)
    for r in range(rows.shape[0]):
        n = n + counts[w, rows[r]]
    return n


@wp.func
def node_centroid(x: wp.array2d(dtype=wp.vec3d), nodes: wp.array2d(dtype=wp.int32), w: int, count: int) -> wp.vec3d:
    """``x[w][nodes].mean(axis=0)``: the rows added in node order, divided by the count."""
    sx = wp.float64(0.0)
    sy = wp.float64(0.0)
    sz = wp.float64(0.0)
    first = int(1)
    for i in range(nodes.shape[1]):
        if nodes[w, i] != 0:
            p = x[w, i]
            if first == 1:
                sx = p[0]
                sy = p[1]
                sz = p[2]
                first = 0
            else:
                sx = sx + p[0]
                sy = sy + p[1]
                sz = sz + p[2]
    n = wp.float64(count)
    return wp.vec3d(sx / n, sy / n, sz / n)
