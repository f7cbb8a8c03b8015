"""Warp kernels of the tools' command side over W worlds: the rate limiter of
``scene/simulation.py`` (each actuator target moves towards its goal by at most ``rate * dt``
per step) on a float64 copy of the controls, written to MuJoCo Warp's float32 ``ctrl``, and the
write of a per-world control schedule computed ahead (a force motor's pull, a jaw closure)."""

from __future__ import annotations

import warp as wp

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"enable_backward": False})

f64 = wp.float64


@wp.kernel
def rate_limit(ctrl64: wp.array2d(dtype=f64), goal: wp.array2d(dtype=f64), rate: wp.array2d(dtype=f64),
               moving: wp.array(dtype=wp.int32), dt: f64, ctrl: wp.array2d(dtype=wp.float32)):
    """One thread per world: ``moving[w]`` stays 1 while any target is more than 1e-12 from its goal."""
    w = wp.tid()
    if moving[w] == 0:
        return
    still = int(0)
    for a in range(ctrl64.shape[1]):
        c = ctrl64[w, a]
        delta = goal[w, a] - c
        lim = rate[w, a] * dt
        if delta > lim:
            delta = lim
        elif delta < -lim:
            delta = -lim
        c = c + delta
        ctrl64[w, a] = c
        ctrl[w, a] = wp.float32(c)
        if wp.abs(goal[w, a] - c) > f64(1e-12):
            still = 1
    moving[w] = still


@wp.kernel
def set_controls(k: int, actuators: wp.array(dtype=wp.int32), values: wp.array3d(dtype=f64),
                 ctrl64: wp.array2d(dtype=f64), ctrl: wp.array2d(dtype=wp.float32)):
    """World x listed actuator: the k-th MuJoCo step's control of a per-world schedule
    (``values`` (K, W, A)), written to the float64 controls and MuJoCo Warp's float32 ``ctrl``
    before the rate limiter runs (as ``Simulation.step_with_controls``)."""
    w, j = wp.tid()
    a = actuators[j]
    c = values[k, w, j]
    ctrl64[w, a] = c
    ctrl[w, a] = wp.float32(c)


@wp.kernel
def write_goals(worlds: wp.array(dtype=wp.int32), actuators: wp.array(dtype=wp.int32), values: wp.array2d(dtype=f64),
                set_rate: wp.int32, speed: f64, goal: wp.array2d(dtype=f64), rate: wp.array2d(dtype=f64),
                moving: wp.array(dtype=wp.int32)):
    """Listed world i x listed actuator j: ``goal[worlds[i], actuators[j]] = values[i, j]``, the world set
    moving, and with ``set_rate`` the actuator's rate set to ``speed``; on the device, so a command does
    not copy the (W, nu) goal arrays to the host and back (every thread of a world writes the same 1)."""
    i, j = wp.tid()
    w = worlds[i]
    a = actuators[j]
    goal[w, a] = values[i, j]
    if set_rate != 0:
        rate[w, a] = speed
    moving[w] = 1
