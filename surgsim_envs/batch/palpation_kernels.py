"""Warp kernels of Palpation-v0's per-step task bookkeeping, one thread per world (float64).

They compute on the device what :class:`~surgsim_envs.batch.palpation_env.BatchedPalpationEnv`
computes on the host in numpy (its default), with the same arithmetic in the same order
(:mod:`surgsim_envs.envs.palpation.terms`, the single env's ``_update`` and ``_record_sample``):

* :func:`reset_worlds`: a reset world's bookkeeping (best site, previous tip, report hold, peak
  force, samples, press sites, stiffness map, running estimate, contrast, potential, step count);
* :func:`evaluate_step`: the readouts (tip, contact force, indentation depth, stiffness sample),
  the best site, the quasi-static stiffness sample (map cell, median, stiffness-weighted estimate,
  contrast, potential), the press site, the report hold, termination and truncation, the guess
  and its error, the six declared reward terms and their sum;
* :func:`observe`: the observation rows (float32, the single env's layout) and the step counts.

Reproducing numpy's results bit for bit (the module compiles without floating-point contraction,
``fuse_fp=False``): ``np.hypot`` is glibc's (:func:`glibc_hypot`); ``w.sum()`` of a 1-D array is
numpy's pairwise summation (:func:`pairwise_sum`, blocks of 128 with 8 accumulators);
``(w[:, None] * xy).sum(axis=0)`` sums in order; the force norms take ``np.einsum``'s and BLAS's
orders (:mod:`surgsim_envs.batch.device_reductions`); ``np.median`` is the middle of a per-world
sorted buffer (the mean of the two middle values for an even count). The one operation not reproduced: ``x ** 3.0`` of
an array, which numpy computes with its own SIMD ``pow`` on AVX-512 hosts (up to 1 ulp from the C
library's ``pow``, which the kernels call); the estimate built from those weights, and what
follows from it (potential, shaping, localisation error and reward), can differ in the last bits.
"""

from __future__ import annotations

import warp as wp

from surgsim_envs.batch.device_reductions import dot_norm, einsum_norm

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"fuse_fp": False, "enable_backward": False})

#: numpy's pairwise summation block (``PW_BLOCKSIZE``)
PAIRWISE_BLOCK = 128
#: levels of pairwise splitting :func:`pairwise_sum` unrolls (Warp functions cannot recurse)
PAIRWISE_LEVELS = 6


# -- numpy's and glibc's arithmetic ---------------------------------------------------------------
@wp.func
def _hypot_kernel(ax: wp.float64, ay: wp.float64) -> wp.float64:
    h = wp.sqrt(ax * ax + ay * ay)
    t1 = wp.float64(0.0)
    t2 = wp.float64(0.0)
    if h <= wp.float64(2.0) * ay:
        delta = h - ay
        t1 = ax * (wp.float64(2.0) * delta - ax)
        t2 = (delta - wp.float64(2.0) * (ax - ay)) * delta
    else:
        delta = h - ax
        t1 = wp.float64(2.0) * delta * (ax - wp.float64(2.0) * ay)
        t2 = (wp.float64(4.0) * delta - ay) * ay + delta * delta
    return h - (t1 + t2) / (wp.float64(2.0) * h)


@wp.func
def glibc_hypot(x: wp.float64, y: wp.float64) -> wp.float64:
    """hypot(x, y) of finite x, y as glibc (2.35+) computes it without FMA (Borges' correction);
    ``np.hypot`` calls it."""
    x = wp.abs(x)
    y = wp.abs(y)
    ax = x
    ay = y
    if x < y:
        ax = y
        ay = x
    eps = wp.float64(5.551115123125783e-17)          # 0x1p-54
    scale = wp.float64(2.409919865102884e-181)       # 0x1p-600
    if ax > wp.float64(6.703903964971299e153):       # 0x1p+511: scale down
        if ay <= ax * eps:
            return ax + ay
        return _hypot_kernel(ax * scale, ay * scale) / scale
    if ay < wp.float64(1.4916681462400413e-154):     # 0x1p-511: scale up
        if ax >= ay / eps:
            return ax + ay
        return _hypot_kernel(ax / scale, ay / scale) * scale
    if ay <= ax * eps:
        return ax + ay
    return _hypot_kernel(ax, ay)


@wp.func
def _sum_block(a: wp.array2d(dtype=wp.float64), w: int, lo: int, n: int) -> wp.float64:
    """numpy's pairwise sum of ``a[w, lo:lo + n]`` for n <= 128 (no split)."""
    res = wp.float64(0.0)
    if n < 8:
        for i in range(n):
            res = res + a[w, lo + i]
        return res
    r0 = a[w, lo + 0]
    r1 = a[w, lo + 1]
    r2 = a[w, lo + 2]
    r3 = a[w, lo + 3]
    r4 = a[w, lo + 4]
    r5 = a[w, lo + 5]
    r6 = a[w, lo + 6]
    r7 = a[w, lo + 7]
    i = int(8)
    end = n - n % 8
    while i < end:
        r0 = r0 + a[w, lo + i + 0]
        r1 = r1 + a[w, lo + i + 1]
        r2 = r2 + a[w, lo + i + 2]
        r3 = r3 + a[w, lo + i + 3]
        r4 = r4 + a[w, lo + i + 4]
        r5 = r5 + a[w, lo + i + 5]
        r6 = r6 + a[w, lo + i + 6]
        r7 = r7 + a[w, lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res = res + a[w, lo + i]
        i += 1
    return res


@wp.func
def _half(n: int) -> int:
    n2 = n // 2
    return n2 - n2 % 8


@wp.func
def _sum_1(a: wp.array2d(dtype=wp.float64), w: int, lo: int, n: int) -> wp.float64:
    if n <= 128:
        return _sum_block(a, w, lo, n)
    n2 = _half(n)
    return _sum_block(a, w, lo, n2) + _sum_block(a, w, lo + n2, n - n2)


@wp.func
def _sum_2(a: wp.array2d(dtype=wp.float64), w: int, lo: int, n: int) -> wp.float64:
    if n <= 128:
        return _sum_block(a, w, lo, n)
    n2 = _half(n)
    return _sum_1(a, w, lo, n2) + _sum_1(a, w, lo + n2, n - n2)


@wp.func
def _sum_3(a: wp.array2d(dtype=wp.float64), w: int, lo: int, n: int) -> wp.float64:
    if n <= 128:
        return _sum_block(a, w, lo, n)
    n2 = _half(n)
    return _sum_2(a, w, lo, n2) + _sum_2(a, w, lo + n2, n - n2)


@wp.func
def _sum_4(a: wp.array2d(dtype=wp.float64), w: int, lo: int, n: int) -> wp.float64:
    if n <= 128:
        return _sum_block(a, w, lo, n)
    n2 = _half(n)
    return _sum_3(a, w, lo, n2) + _sum_3(a, w, lo + n2, n - n2)


@wp.func
def _sum_5(a: wp.array2d(dtype=wp.float64), w: int, lo: int, n: int) -> wp.float64:
    if n <= 128:
        return _sum_block(a, w, lo, n)
    n2 = _half(n)
    return _sum_4(a, w, lo, n2) + _sum_4(a, w, lo + n2, n - n2)


@wp.func
def pairwise_sum(a: wp.array2d(dtype=wp.float64), w: int, n: int) -> wp.float64:
    """``a[w, :n].sum()`` as numpy sums a contiguous float64 array (pairwise; n within
    :func:`pairwise_capacity`)."""
    if n <= 128:
        return _sum_block(a, w, 0, n)
    n2 = _half(n)
    return _sum_5(a, w, 0, n2) + _sum_5(a, w, n2, n - n2)


def pairwise_levels(n: int) -> int:
    """Levels of splitting numpy's pairwise sum of n numbers takes (0 for n <= 128)."""
    if n <= PAIRWISE_BLOCK:
        return 0
    n2 = n // 2
    n2 -= n2 % 8
    return 1 + max(pairwise_levels(n2), pairwise_levels(n - n2))


def pairwise_capacity() -> int:
    """The largest sample count up to which every count fits :func:`pairwise_sum`'s levels."""
    n = PAIRWISE_BLOCK
    while pairwise_levels(n + 1) <= PAIRWISE_LEVELS:
        n += 1
    return n


@wp.func
def insert_sorted(buf: wp.array2d(dtype=wp.float64), w: int, n: int, k: wp.float64):
    """Insert ``k`` into the ascending ``buf[w, :n]`` (it becomes ``buf[w, :n + 1]``)."""
    j = n
    while j > 0:
        if buf[w, j - 1] > k:
            buf[w, j] = buf[w, j - 1]
            j -= 1
        else:
            break
    buf[w, j] = k


@wp.func
def sorted_median(buf: wp.array2d(dtype=wp.float64), w: int, n: int) -> wp.float64:
    """``np.median`` of the ascending ``buf[w, :n]`` (n >= 1): the middle value, or the mean of the
    two middle values ``(a + b) / 2`` for an even count, as numpy's mean of the two computes it."""
    if n % 2 == 0:
        return (buf[w, n // 2 - 1] + buf[w, n // 2]) / wp.float64(2.0)
    return buf[w, n // 2]


# -- the task's terms ---------------------------------------------------------------------------
@wp.func
def localisation_potential(error: wp.float64, scale: wp.float64) -> wp.float64:
    """``terms.localisation_potential``: 1 - min(error / scale, 1)."""
    return wp.float64(1.0) - wp.min(error / scale, wp.float64(1.0))


@wp.func
def localisation_reward(error: wp.float64, scale: wp.float64, tolerance: wp.float64, weight: wp.float64,
                        bonus: wp.float64) -> wp.float64:
    """``terms.localisation_reward``."""
    b = wp.float64(0.0)
    if error <= tolerance:
        b = bonus
    return weight * (wp.float64(1.0) - wp.min(error / scale, wp.float64(1.0))) + b


@wp.func
def map_cell(x: wp.float64, y: wp.float64, cells: int, half_width: wp.float64) -> int:
    """``terms.cell_of``: row-major cell (row y, column x) of the map over +-half_width."""
    i = int(wp.floor((x + half_width) / (wp.float64(2.0) * half_width) * wp.float64(cells)))
    j = int(wp.floor((y + half_width) / (wp.float64(2.0) * half_width) * wp.float64(cells)))
    i = wp.min(wp.max(i, 0), cells - 1)
    j = wp.min(wp.max(j, 0), cells - 1)
    return j * cells + i


@wp.struct
class PalpationParams:
    """The config numbers the kernels read (SI units, weights as the declared terms read them)."""

    contact_z: wp.float64          # surface_z + tip_radius: the tip touches the rest surface
    press_min_depth: wp.float64
    control_dt: wp.float64
    sample_max_speed: wp.float64
    site_spacing: wp.float64
    max_rewarded_sites: int
    report_hold_steps: int
    min_report_seconds: wp.float64
    max_episode_steps: int
    map_cells: int
    map_half_width: wp.float64
    localisation_scale: wp.float64
    tolerance: wp.float64          # m (tolerance_mm * 1e-3)
    success_bonus: wp.float64
    damage_force: wp.float64
    w_damage: wp.float64
    w_coverage: wp.float64
    w_shaping: wp.float64
    w_time: wp.float64
    w_press_site: wp.float64
    w_localisation: wp.float64


@wp.struct
class PalpationState:
    """Per-world bookkeeping (W rows; sample and site buffers of ``capacity`` = max episode steps)."""

    best: wp.array(dtype=wp.vec3d)           # (x, y, k) of the stiffest sample site
    prev_tip: wp.array(dtype=wp.vec3d)
    report_held: wp.array(dtype=wp.int32)
    peak: wp.array(dtype=wp.float64)
    steps: wp.array(dtype=wp.int32)
    n_samples: wp.array(dtype=wp.int32)
    samples_xy: wp.array2d(dtype=wp.vec2d)   # (W, capacity), in the order taken
    samples_k: wp.array2d(dtype=wp.float64)
    sorted_k: wp.array2d(dtype=wp.float64)   # the same samples, ascending (the median)
    weights: wp.array2d(dtype=wp.float64)    # (k - median)+ ** 3 of the last estimate (work)
    n_sites: wp.array(dtype=wp.int32)
    sites: wp.array2d(dtype=wp.vec2d)
    cell_k: wp.array2d(dtype=wp.float64)     # (W, cells^2) max stiffness per map cell
    has_estimate: wp.array(dtype=wp.int32)
    estimate: wp.array(dtype=wp.vec2d)
    contrast: wp.array(dtype=wp.float64)
    phi: wp.array(dtype=wp.float64)
    phi_before: wp.array(dtype=wp.float64)
    error: wp.array(dtype=wp.float64)        # the guess's error (NaN before the episode ends)
    centre: wp.array(dtype=wp.vec2d)         # inclusion centre (x, y)


@wp.func
def _tip(xpos: wp.array2d(dtype=wp.vec3f), w: int, body: int) -> wp.vec3d:
    p = xpos[w, body]
    return wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))


@wp.func
def _force(tool_force: wp.array2d(dtype=wp.vec3d), bodies: wp.array(dtype=wp.int32), w: int) -> wp.vec3d:
    f = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    for b in range(bodies.shape[0]):
        f = f + tool_force[w, bodies[b]]
    return f


@wp.func
def _depth(tip: wp.vec3d, contact_z: wp.float64) -> wp.float64:
    return wp.max(wp.float64(0.0), contact_z - tip[2])


@wp.kernel
def reset_worlds(s: PalpationState, worlds: wp.array(dtype=wp.int32), centres: wp.array(dtype=wp.vec2d),
                 xpos: wp.array2d(dtype=wp.vec3f), body: int, nan: wp.float64):
    """Thread per listed world: a new episode's bookkeeping (the probe where the reset left it)."""
    t = wp.tid()
    w = worlds[t]
    zero = wp.float64(0.0)
    s.best[w] = wp.vec3d(zero, zero, zero)
    s.prev_tip[w] = _tip(xpos, w, body)
    s.report_held[w] = 0
    s.peak[w] = zero
    s.steps[w] = 0
    s.n_samples[w] = 0
    s.n_sites[w] = 0
    for c in range(s.cell_k.shape[1]):
        s.cell_k[w, c] = zero
    s.has_estimate[w] = 0
    s.estimate[w] = wp.vec2d(zero, zero)
    s.contrast[w] = wp.float64(1.0)
    s.phi[w] = zero
    s.phi_before[w] = zero
    s.error[w] = nan
    s.centre[w] = centres[t]


@wp.func
def _record_sample(s: PalpationState, p: PalpationParams, w: int, xy: wp.vec2d, k: wp.float64) -> int:
    """The single env's ``_record_sample``; returns 1 if the sample opened a map cell."""
    n = s.n_samples[w]
    s.samples_xy[w, n] = xy
    s.samples_k[w, n] = k
    insert_sorted(s.sorted_k, w, n, k)
    n += 1
    s.n_samples[w] = n
    cell = map_cell(xy[0], xy[1], p.map_cells, p.map_half_width)
    new_cell = 0
    if s.cell_k[w, cell] == wp.float64(0.0):
        new_cell = 1
    s.cell_k[w, cell] = wp.max(s.cell_k[w, cell], k)
    median = sorted_median(s.sorted_k, w, n)
    for i in range(n):
        s.weights[w, i] = wp.pow(wp.max(s.samples_k[w, i] - median, wp.float64(0.0)), wp.float64(3.0))
    total = pairwise_sum(s.weights, w, n)
    est = wp.vec2d()
    if total <= wp.float64(0.0):
        top = int(0)                                       # np.argmax: the first largest
        for i in range(1, n):
            if s.samples_k[w, i] > s.samples_k[w, top]:
                top = i
        est = s.samples_xy[w, top]
    else:
        sx = s.weights[w, 0] * s.samples_xy[w, 0][0]
        sy = s.weights[w, 0] * s.samples_xy[w, 0][1]
        for i in range(1, n):
            sx = sx + s.weights[w, i] * s.samples_xy[w, i][0]
            sy = sy + s.weights[w, i] * s.samples_xy[w, i][1]
        est = wp.vec2d(sx / total, sy / total)
    s.estimate[w] = est
    s.has_estimate[w] = 1
    contrast = wp.float64(1.0)
    if median > wp.float64(0.0):
        contrast = s.sorted_k[w, n - 1] / median
    s.contrast[w] = contrast
    err = glibc_hypot(est[0] - s.centre[w][0], est[1] - s.centre[w][1])
    s.phi[w] = localisation_potential(err, p.localisation_scale)
    return new_cell


@wp.func
def _new_site(s: PalpationState, w: int, xy: wp.vec2d, spacing: wp.float64) -> int:
    """``terms.is_new_site``: 1 if xy is at least ``spacing`` from every earlier site."""
    for i in range(s.n_sites[w]):
        q = s.sites[w, i]
        if not (glibc_hypot(xy[0] - q[0], xy[1] - q[1]) >= spacing):
            return 0
    return 1


@wp.kernel
def evaluate_step(s: PalpationState, p: PalpationParams, xpos: wp.array2d(dtype=wp.vec3f), body: int,
                  tool_force: wp.array2d(dtype=wp.vec3d), bodies: wp.array(dtype=wp.int32),
                  actions: wp.array2d(dtype=wp.float64), live: wp.array(dtype=wp.int32),
                  unstable: wp.array(dtype=wp.int32),
                  reward: wp.array(dtype=wp.float64), terms: wp.array2d(dtype=wp.float64),
                  terminated: wp.array(dtype=wp.bool), truncated: wp.array(dtype=wp.bool),
                  ended: wp.array(dtype=wp.bool), success: wp.array(dtype=wp.bool),
                  final: wp.array(dtype=wp.float64), force_n: wp.array(dtype=wp.float64),
                  stiffness: wp.array(dtype=wp.float64), peak: wp.array(dtype=wp.float64),
                  error: wp.array(dtype=wp.float64)):
    """Thread per world: the batched env's ``_evaluate`` (``live``: the world stepped its episode;
    ``unstable``: it diverged and was reset this step). ``terms`` (6, W): damage, coverage,
    shaping, time, press_site, localisation."""
    w = wp.tid()
    zero = wp.float64(0.0)
    is_live = live[w] != 0
    tip = _tip(xpos, w, body)
    f = _force(tool_force, bodies, w)
    depth = _depth(tip, p.contact_z)
    fmag = einsum_norm(f)
    if is_live:
        s.peak[w] = wp.max(s.peak[w], fmag)
        s.steps[w] = s.steps[w] + 1
        s.phi_before[w] = s.phi[w]
    new_cell = int(0)
    new_site = int(0)
    finished = int(0)
    pressing = depth >= p.press_min_depth
    k = zero
    if pressing:
        k = f[2] / depth
    if is_live and k > s.best[w][2]:
        s.best[w] = wp.vec3d(tip[0], tip[1], k)
    d = tip - s.prev_tip[w]
    speed = einsum_norm(d) / p.control_dt
    if is_live:
        s.prev_tip[w] = tip
    quasi_static = speed <= p.sample_max_speed
    xy = wp.vec2d(tip[0], tip[1])
    if is_live and k > zero and quasi_static:
        new_cell = _record_sample(s, p, w, xy, k)
    if is_live and pressing and quasi_static:
        if _new_site(s, w, xy, p.site_spacing) == 1:
            n = s.n_sites[w]
            s.sites[w, n] = xy
            s.n_sites[w] = n + 1
            if n + 1 <= p.max_rewarded_sites:
                new_site = 1
    held = int(0)
    if actions[w, 3] > zero:
        held = s.report_held[w] + 1
    s.report_held[w] = held
    steps = s.steps[w]
    term = is_live and held >= p.report_hold_steps and wp.float64(steps) * p.control_dt >= p.min_report_seconds
    trunc = is_live and (not term) and steps >= p.max_episode_steps
    fin = zero
    if term or trunc:
        guess = xy
        if s.has_estimate[w] != 0:
            guess = s.estimate[w]
        c = s.centre[w]
        err = glibc_hypot(guess[0] - c[0], guess[1] - c[1])
        s.error[w] = err
        r = localisation_reward(err, p.localisation_scale, p.tolerance, p.w_localisation, p.success_bonus)
        if term:
            finished = 1
        else:
            fin = r
    t_damage = zero
    t_coverage = zero
    t_shaping = zero
    t_time = zero
    t_press = zero
    t_loc = zero
    total = zero
    if is_live:
        t_damage = -p.w_damage * wp.max(zero, dot_norm(f) - p.damage_force)
        if new_cell != 0:
            t_coverage = p.w_coverage
        t_shaping = p.w_shaping * (s.phi[w] - s.phi_before[w])
        t_time = -p.w_time
        if new_site != 0:
            t_press = p.w_press_site
        if finished != 0:
            t_loc = localisation_reward(s.error[w], p.localisation_scale, p.tolerance, p.w_localisation,
                                        p.success_bonus)
        total = (((((zero + t_damage) + t_coverage) + t_shaping) + t_time) + t_press) + t_loc
        total = total + fin
    terms[0, w] = t_damage
    terms[1, w] = t_coverage
    terms[2, w] = t_shaping
    terms[3, w] = t_time
    terms[4, w] = t_press
    terms[5, w] = t_loc
    reward[w] = total
    terminated[w] = term or (unstable[w] != 0)
    truncated[w] = trunc
    ended[w] = term or trunc
    success[w] = (term or trunc) and s.error[w] <= p.tolerance
    final[w] = fin
    force_n[w] = fmag
    stiffness[w] = k
    peak[w] = s.peak[w]
    error[w] = s.error[w]


@wp.kernel
def observe(s: PalpationState, p: PalpationParams, xpos: wp.array2d(dtype=wp.vec3f), body: int,
            tool_force: wp.array2d(dtype=wp.vec3d), bodies: wp.array(dtype=wp.int32),
            obs: wp.array2d(dtype=wp.float32), steps: wp.array(dtype=wp.int64)):
    """Thread per world: the observation row (the single env's layout, float32) and the step count."""
    w = wp.tid()
    tip = _tip(xpos, w, body)
    f = _force(tool_force, bodies, w)
    for i in range(3):
        obs[w, i] = wp.float32(tip[i])
        obs[w, 3 + i] = wp.float32(f[i])
    obs[w, 6] = wp.float32(_depth(tip, p.contact_z))
    b = s.best[w]
    obs[w, 7] = wp.float32(b[0])
    obs[w, 8] = wp.float32(b[1])
    obs[w, 9] = wp.float32(b[2])
    obs[w, 10] = wp.float32(wp.float64(s.steps[w]) / wp.float64(p.max_episode_steps))
    est = wp.vec2d(tip[0], tip[1])
    if s.has_estimate[w] != 0:
        est = s.estimate[w]
    obs[w, 11] = wp.float32(est[0])
    obs[w, 12] = wp.float32(est[1])
    obs[w, 13] = wp.float32(s.contrast[w])
    cells = s.cell_k.shape[1]
    top = s.cell_k[w, 0]
    for c in range(1, cells):
        top = wp.max(top, s.cell_k[w, c])
    for c in range(cells):
        v = wp.float64(0.0)
        if top > wp.float64(0.0):
            v = s.cell_k[w, c] / top
        obs[w, 14 + c] = wp.float32(v)
    steps[w] = wp.int64(s.steps[w])
