"""Warp kernels of Slippage-v0's control schedule and per-step task bookkeeping, one thread per
world (float64).

They compute on the device what :class:`~surgsim_envs.batch.slippage_env.BatchedSlippageEnv`
computes on the host (its default), with the same arithmetic in the same order (the single env's
``_run``, ``_update`` and declared terms, :mod:`surgsim_envs.envs.slippage.terms`):

* :func:`reset_worlds`: a reset world's episode after its settle (its pull parameters, friction and
  Young's scale, its clock and the pull's start time, the wrist at the grasp, the slip tracker
  started on the contacted nodes, the pull, slip, squeeze, peak force, loss flag and step count
  cleared);
* :func:`control_schedule`: the (K, W, 2) jaw and pull controls of one control step (the compiled
  :func:`~surgsim_envs.envs.slippage.terms.control_schedule`: the jaw control moving towards the
  action's closure by at most ``closing_speed * h`` per MuJoCo step, the pull
  ``min(max_pull, pull_force(t - t0, ...))``, t advancing by h) for the live worlds, the held
  controls for the others, and every world's float64 clock advanced as MuJoCo's ``d.time += h``;
* :func:`evaluate_step`: the readouts (wrist, per-jaw normal forces, contact count), the slip
  tracker, the summed squeeze and its peak, the loss of grasp, truncation and success, the four
  declared reward terms and their sum, the pull / squeeze info;
* :func:`observe`: the observation rows (float32, the single env's layout) and the info metrics.

Reproducing the host's results bit for bit (the module compiles without floating-point
contraction, ``fuse_fp=False``): ``np.sum`` of the three jaw forces adds them in order; the slip
tracker's centroid adds the rows in node order and divides by the count, its norm is sqrt of BLAS's
in-order dot (:func:`~surgsim_envs.batch.device_reductions.dot_norm`), as is the wrist's
displacement ``(pos - pos0) @ pull_dir``; Python's ``max(0.0, x)`` / ``max(a, b)`` keep the first
argument unless the second is greater; the pull's sine is the C library's ``sin`` on the CPU
device, as numba's; the reward is Python's ``sum()`` of the terms in declared order
(:func:`~surgsim_envs.batch.device_reductions.python_sum_add`).
"""

from __future__ import annotations

import math

import warp as wp

from surgsim_envs.batch.device_reductions import python_sum_add, python_sum_total
from surgsim_envs.batch.grasp_scene_funcs import node_centroid, tool_count, wrist_position

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"fuse_fp": False, "enable_backward": False})

#: the grasper's jaws (the per-jaw observation entries)
JAWS = 3
#: 2 pi, as ``2.0 * math.pi`` (exact: a power of two times pi)
TWO_PI = wp.constant(wp.float64(2.0 * math.pi))


@wp.struct
class SlippageParams:
    """The config numbers the kernels read (SI units, weights as the declared terms read them)."""

    open_radius: wp.float64         # m, the jaw opening at qpos 0
    min_radius: wp.float64          # m, the opening at closure action +1
    closing_step: wp.float64        # m, closing_speed x h: the jaw control's largest move per MuJoCo step
    h: wp.float64                   # s, one MuJoCo step (dt x tissue sub-cycles)
    max_pull: wp.float64            # N, the motor limit
    max_slip: wp.float64            # m, loss of grasp beyond it
    slip_tolerance: wp.float64      # m, success at the time limit within it
    static_friction_ratio: wp.float64
    max_episode_steps: int
    jaw_act: int                    # the jaw actuator's column in the controls
    pull_act: int                   # the pull motor's column
    pull_dir: wp.vec3d              # the pull's unit direction
    compensated_sum: int            # 1: the reward sums as Python 3.12+'s sum() (Neumaier)
    w_slip: wp.float64
    w_squeeze: wp.float64
    w_hold: wp.float64
    w_drop: wp.float64


@wp.struct
class SlippageState:
    """Per-world episode state (W rows; the slip tracker's node set as a (W, N) mask)."""

    rate: wp.array(dtype=wp.float64)          # N/s, the pull's ramp
    amplitude: wp.array(dtype=wp.float64)     # N, its sinusoid
    frequency: wp.array(dtype=wp.float64)     # Hz
    phase: wp.array(dtype=wp.float64)         # rad
    t0: wp.array(dtype=wp.float64)            # s, the clock at the end of the settle (the pull's zero)
    clock: wp.array(dtype=wp.float64)         # s, the world's float64 simulation time (MuJoCo's d.time)
    pos0: wp.array(dtype=wp.vec3d)            # m, the wrist at the grasp (the tracker's start too)
    slip_nodes: wp.array2d(dtype=wp.int32)    # 1 for the nodes the slip tracker follows
    slip_count: wp.array(dtype=wp.int32)
    centroid0: wp.array(dtype=wp.vec3d)       # m, the nodes' centroid at the grasp
    pull: wp.array(dtype=wp.float64)          # N, the last control step's last pull control
    slip_distance: wp.array(dtype=wp.float64)
    slip_before: wp.array(dtype=wp.float64)
    normal_total: wp.array(dtype=wp.float64)  # N, the jaws' summed normal force
    peak: wp.array(dtype=wp.float64)          # N, its peak in the episode
    lost: wp.array(dtype=wp.int32)
    steps: wp.array(dtype=wp.int32)
    mu: wp.array(dtype=wp.float64)
    young_scale: wp.array(dtype=wp.float64)


@wp.func
def _dot(a: wp.vec3d, b: wp.vec3d) -> wp.float64:
    """``a @ b`` of two 3-vectors: BLAS's in-order dot."""
    return (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]


@wp.func
def _positive(x: wp.float64) -> wp.float64:
    """Python's ``max(0.0, x)``: 0.0 unless x > 0."""
    if x > wp.float64(0.0):
        return x
    return wp.float64(0.0)


@wp.func
def _pull_force(t: wp.float64, rate: wp.float64, amplitude: wp.float64, frequency: wp.float64,
                phase: wp.float64) -> wp.float64:
    """``pull_force``: ``max(0.0, rate * t + amplitude * sin(2 pi f t + phase))``."""
    return _positive(rate * t + amplitude * wp.sin(TWO_PI * frequency * t + phase))


@wp.func
def _least_squeeze(pull: wp.float64, mu: wp.float64) -> wp.float64:
    """``least_squeeze``: |pull| / mu, infinite for mu <= 0."""
    if mu > wp.float64(0.0):
        return wp.abs(pull) / mu
    return wp.float64(math.inf)


@wp.kernel
def reset_worlds(s: SlippageState, worlds: wp.array(dtype=wp.int32), rate: wp.array(dtype=wp.float64),
                 amplitude: wp.array(dtype=wp.float64), frequency: wp.array(dtype=wp.float64),
                 phase: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64),
                 young_scale: wp.array(dtype=wp.float64), clock: wp.array(dtype=wp.float64),
                 xpos: wp.array2d(dtype=wp.vec3f), body: int, contact_mask: wp.array2d(dtype=wp.int32),
                 x: wp.array2d(dtype=wp.vec3d), count: wp.array(dtype=wp.int32)):
    """Thread per listed world, after its settle: a new episode (its draws and clock from the
    host); the slip tracker starts on the contacted nodes (``count``: how many, 0 refused by the host)."""
    t = wp.tid()
    w = worlds[t]
    zero = wp.float64(0.0)
    s.rate[w] = rate[t]
    s.amplitude[w] = amplitude[t]
    s.frequency[w] = frequency[t]
    s.phase[w] = phase[t]
    s.mu[w] = mu[t]
    s.young_scale[w] = young_scale[t]
    s.clock[w] = clock[t]
    s.t0[w] = clock[t]
    pos = wrist_position(xpos, w, body)
    s.pos0[w] = pos
    n = int(0)
    for i in range(contact_mask.shape[1]):
        m = contact_mask[w, i]
        s.slip_nodes[w, i] = m
        if m != 0:
            n += 1
    s.slip_count[w] = n
    if n > 0:
        s.centroid0[w] = node_centroid(x, s.slip_nodes, w, n)
    count[t] = n
    s.pull[w] = zero
    s.slip_distance[w] = zero
    s.slip_before[w] = zero
    s.normal_total[w] = zero
    s.peak[w] = zero
    s.lost[w] = 0
    s.steps[w] = 0


@wp.kernel
def control_schedule(s: SlippageState, p: SlippageParams, ctrl64: wp.array2d(dtype=wp.float64),
                     action: wp.array(dtype=wp.float64), live: wp.array(dtype=wp.int32),
                     values: wp.array3d(dtype=wp.float64)):
    """Thread per world: the control step's schedule ``values`` (K, W, 2: jaw, pull) from the
    world's float64 controls ``ctrl64``; a live world's jaw moves towards ``jaw_closure(action)``
    and its pull follows the episode's ramp and sinusoid (the last one kept as the step's pull),
    another world holds its controls; every world's clock advances K MuJoCo steps."""
    w = wp.tid()
    K = values.shape[0]
    jaw = ctrl64[w, p.jaw_act]
    t = s.clock[w]
    if live[w] != 0:
        goal = (action[w] + wp.float64(1.0)) / wp.float64(2.0) * (p.open_radius - p.min_radius)   # jaw_closure
        lim = p.closing_step
        rate = s.rate[w]
        amplitude = s.amplitude[w]
        frequency = s.frequency[w]
        phase = s.phase[w]
        t0 = s.t0[w]
        pull = s.pull[w]
        for k in range(K):
            d = goal - jaw
            if d < -lim:
                d = -lim
            if d > lim:
                d = lim
            jaw = jaw + d
            values[k, w, 0] = jaw
            pull = wp.min(p.max_pull, _pull_force(t - t0, rate, amplitude, frequency, phase))
            values[k, w, 1] = pull
            t = t + p.h
        s.pull[w] = pull
    else:
        held = ctrl64[w, p.pull_act]
        for k in range(K):
            values[k, w, 0] = jaw
            values[k, w, 1] = held
            t = t + p.h
    s.clock[w] = t


@wp.kernel
def evaluate_step(s: SlippageState, p: SlippageParams, xpos: wp.array2d(dtype=wp.vec3f), body: int,
                  geom_fn: wp.array2d(dtype=wp.float64), jaw_columns: wp.array(dtype=wp.int32),
                  tool_contacts: wp.array2d(dtype=wp.int32), tool_rows: wp.array(dtype=wp.int32),
                  x: wp.array2d(dtype=wp.vec3d), live: wp.array(dtype=wp.int32), unstable: wp.array(dtype=wp.int32),
                  reward: wp.array(dtype=wp.float64), terms: wp.array2d(dtype=wp.float64),
                  terminated: wp.array(dtype=wp.bool), truncated: wp.array(dtype=wp.bool),
                  ended: wp.array(dtype=wp.bool), success: wp.array(dtype=wp.bool),
                  dropped: wp.array(dtype=wp.bool), pull_force: wp.array(dtype=wp.float64),
                  normal_force: wp.array(dtype=wp.float64), least_squeeze: wp.array(dtype=wp.float64)):
    """Thread per world: the batched env's ``_evaluate`` (``live``: the world stepped its episode;
    ``unstable``: it diverged and was reset this step, terminated). ``terms`` (4, W): slip,
    excess_squeeze, hold, drop."""
    w = wp.tid()
    zero = wp.float64(0.0)
    t_slip = zero
    t_squeeze = zero
    t_hold = zero
    t_drop = zero
    total = zero
    lost = False
    trunc = False
    ok = False
    if live[w] != 0:
        steps = s.steps[w] + 1
        s.steps[w] = steps
        pos = wrist_position(xpos, w, body)
        fn0 = geom_fn[w, jaw_columns[0]]
        fn1 = geom_fn[w, jaw_columns[1]]
        fn2 = geom_fn[w, jaw_columns[2]]
        contacts = tool_count(tool_contacts, tool_rows, w)
        before = s.slip_distance[w]
        s.slip_before[w] = before
        rel = (pos - s.pos0[w]) - (node_centroid(x, s.slip_nodes, w, s.slip_count[w]) - s.centroid0[w])
        slip = wp.sqrt(_dot(rel, rel))                      # np.linalg.norm
        s.slip_distance[w] = slip
        force = (fn0 + fn1) + fn2                           # np.sum(fn)
        s.normal_total[w] = force
        if force > s.peak[w]:
            s.peak[w] = force
        lost = contacts == 0 or slip > p.max_slip
        if lost:
            s.lost[w] = 1
        else:
            s.lost[w] = 0
        pull = s.pull[w]
        t_slip = -p.w_slip * _positive(slip - before) * wp.float64(1e3)                       # slip_penalty
        t_squeeze = -p.w_squeeze * _positive(force - _least_squeeze(pull, s.mu[w]))          # excess_squeeze_penalty
        if not lost:
            t_hold = p.w_hold
        if lost:
            t_drop = -p.w_drop
        acc = wp.vec2d(zero, zero)
        acc = python_sum_add(acc, t_slip, p.compensated_sum)
        acc = python_sum_add(acc, t_squeeze, p.compensated_sum)
        acc = python_sum_add(acc, t_hold, p.compensated_sum)
        acc = python_sum_add(acc, t_drop, p.compensated_sum)
        total = python_sum_total(acc)
        trunc = (not lost) and steps >= p.max_episode_steps
        ok = trunc and slip <= p.slip_tolerance
    terms[0, w] = t_slip
    terms[1, w] = t_squeeze
    terms[2, w] = t_hold
    terms[3, w] = t_drop
    reward[w] = total
    terminated[w] = lost or (unstable[w] != 0)
    truncated[w] = trunc
    ended[w] = lost or trunc or (unstable[w] != 0)
    success[w] = ok
    dropped[w] = lost
    pull_force[w] = s.pull[w]
    normal_force[w] = s.normal_total[w]
    least_squeeze[w] = _least_squeeze(s.pull[w], s.mu[w])


@wp.kernel
def observe(s: SlippageState, p: SlippageParams, xpos: wp.array2d(dtype=wp.vec3f), body: int,
            qpos: wp.array2d(dtype=wp.float32), jaw_qpos: int, geom_fn: wp.array2d(dtype=wp.float64),
            geom_ft: wp.array2d(dtype=wp.float64), jaw_columns: wp.array(dtype=wp.int32),
            tool_contacts: wp.array2d(dtype=wp.int32), tool_slipping: wp.array2d(dtype=wp.int32),
            tool_rows: wp.array(dtype=wp.int32),
            obs: wp.array2d(dtype=wp.float32), steps: wp.array(dtype=wp.int64), mu: wp.array(dtype=wp.float64),
            mu_static: wp.array(dtype=wp.float64), young_scale: wp.array(dtype=wp.float64),
            slip_distance: wp.array(dtype=wp.float64), peak: wp.array(dtype=wp.float64)):
    """Thread per world: the observation row (the single env's layout, float32) and the info
    metrics of the world's current episode."""
    w = wp.tid()
    pos = wrist_position(xpos, w, body)
    obs[w, 0] = wp.float32(p.open_radius - wp.float64(qpos[w, jaw_qpos]))
    for j in range(JAWS):
        obs[w, 1 + j] = wp.float32(geom_fn[w, jaw_columns[j]])
        obs[w, 4 + j] = wp.float32(geom_ft[w, jaw_columns[j]])
    obs[w, 7] = wp.float32(tool_count(tool_slipping, tool_rows, w))
    obs[w, 8] = wp.float32(tool_count(tool_contacts, tool_rows, w))
    obs[w, 9] = wp.float32(s.pull[w])
    obs[w, 10] = wp.float32(_dot(pos - s.pos0[w], p.pull_dir))
    obs[w, 11] = wp.float32(s.slip_distance[w])
    steps[w] = wp.int64(s.steps[w])
    mu[w] = s.mu[w]
    mu_static[w] = p.static_friction_ratio * s.mu[w]
    young_scale[w] = s.young_scale[w]
    slip_distance[w] = s.slip_distance[w]
    peak[w] = s.peak[w]
