"""Warp kernels that write a subset of worlds in place (resets, per-world parameters), so that a
reset of a few worlds costs work on those worlds only, not a copy of every world's arrays."""

from __future__ import annotations

import warp as wp

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"enable_backward": False})

f64 = wp.float64


@wp.kernel
def scatter_rows(dst: wp.array2d(dtype=f64), worlds: wp.array(dtype=wp.int32), src: wp.array2d(dtype=f64)):
    """``dst[worlds[k], j] = src[k, j]``."""
    k, j = wp.tid()
    dst[worlds[k], j] = src[k, j]


@wp.kernel
def reset_nodes(worlds: wp.array(dtype=wp.int32), rest: wp.array(dtype=wp.vec3d), x: wp.array2d(dtype=wp.vec3d),
                v: wp.array2d(dtype=wp.vec3d), f_ext: wp.array2d(dtype=wp.vec3d)):
    k, i = wp.tid()
    w = worlds[k]
    x[w, i] = rest[i]
    v[w, i] = wp.vec3d()
    f_ext[w, i] = wp.vec3d()


@wp.kernel
def reset_springs(worlds: wp.array(dtype=wp.int32), s: wp.array2d(dtype=f64), dl: wp.array2d(dtype=f64)):
    k, e = wp.tid()
    w = worlds[k]
    s[w, e] = f64(0.0)
    dl[w, e] = f64(0.0)


@wp.kernel
def reset_contacts(worlds: wp.array(dtype=wp.int32), state: wp.array3d(dtype=wp.int32),
                   anchor: wp.array3d(dtype=wp.vec3d), point_force: wp.array3d(dtype=wp.vec3d),
                   point_fn: wp.array3d(dtype=f64), point_ft: wp.array3d(dtype=wp.vec3d),
                   point_depth: wp.array3d(dtype=f64)):
    """Contact states, anchors and per-point parts of the listed worlds cleared (the readouts
    computed from them, e.g. per-jaw forces, then read zero until the next step)."""
    k, c, g = wp.tid()
    w = worlds[k]
    state[w, c, g] = 0
    anchor[w, c, g] = wp.vec3d()
    point_force[w, c, g] = wp.vec3d()
    point_fn[w, c, g] = f64(0.0)
    point_ft[w, c, g] = wp.vec3d()
    point_depth[w, c, g] = f64(0.0)


@wp.kernel
def reset_world_scalars(worlds: wp.array(dtype=wp.int32), fresh: wp.array(dtype=wp.int32),
                        diverged: wp.array(dtype=wp.int32), moving: wp.array(dtype=wp.int32),
                        ctrl64: wp.array2d(dtype=f64), goal: wp.array2d(dtype=f64),
                        tool_force: wp.array2d(dtype=wp.vec3d), tool_torque: wp.array2d(dtype=wp.vec3d),
                        tool_fn: wp.array2d(dtype=f64), tool_ft: wp.array2d(dtype=f64),
                        tool_contacts: wp.array2d(dtype=wp.int32), tool_slipping: wp.array2d(dtype=wp.int32),
                        tool_depth: wp.array2d(dtype=f64), sum_force: wp.array2d(dtype=wp.vec3d),
                        sum_torque: wp.array2d(dtype=wp.vec3d)):
    """Per-world flags, controls and tool sums of the listed worlds back to their reset values."""
    k = wp.tid()
    w = worlds[k]
    fresh[w] = 1
    diverged[w] = 0
    moving[w] = 0
    for a in range(ctrl64.shape[1]):
        ctrl64[w, a] = f64(0.0)
        goal[w, a] = f64(0.0)
    for t in range(tool_force.shape[1]):
        tool_force[w, t] = wp.vec3d()
        tool_torque[w, t] = wp.vec3d()
        tool_fn[w, t] = f64(0.0)
        tool_ft[w, t] = f64(0.0)
        tool_contacts[w, t] = 0
        tool_slipping[w, t] = 0
        tool_depth[w, t] = f64(0.0)
        sum_force[w, t] = wp.vec3d()
        sum_torque[w, t] = wp.vec3d()


@wp.kernel
def keep_rows(reset: wp.array(dtype=wp.int32), before: wp.array2d(dtype=wp.float32),
              now: wp.array2d(dtype=wp.float32)):
    """``now[w, j] = before[w, j]`` in every world ``w`` not being reset (``reset[w] == 0``): a whole-batch
    computation put back where it was not asked for, on the device (float32 rows: MuJoCo Warp's data)."""
    w, j = wp.tid()
    if reset[w] == 0:
        now[w, j] = before[w, j]


@wp.kernel
def restore_rows(worlds: wp.array(dtype=wp.int32), snapshot: wp.array(dtype=wp.uint8),
                 rows: wp.array2d(dtype=wp.uint8)):
    """``rows[worlds[k], j] = snapshot[j]``: one world's recorded reset state (the raw bytes of its
    row of a MuJoCo Warp ``Data`` field) into the listed worlds."""
    k, j = wp.tid()
    rows[worlds[k], j] = snapshot[j]


@wp.kernel
def copy_rows(src_worlds: wp.array(dtype=wp.int32), dst_worlds: wp.array(dtype=wp.int32),
              src: wp.array2d(dtype=wp.uint8), dst: wp.array2d(dtype=wp.uint8)):
    """``dst[dst_worlds[k], j] = src[src_worlds[k], j]``: whole world rows (raw bytes) from one batch to
    another of the same scene."""
    k, j = wp.tid()
    dst[dst_worlds[k], j] = src[src_worlds[k], j]
