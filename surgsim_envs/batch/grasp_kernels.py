"""Warp kernels of Grasp-v0's per-step task bookkeeping, one thread per world (float64).

They compute on the device what :class:`~surgsim_envs.batch.grasp_env.BatchedGraspEnv` computes on
the host (its default), with the same arithmetic in the same order (the single env's ``_update``
and ``_update_grasp``, :mod:`surgsim_envs.envs.grasp.terms`):

* :func:`reset_worlds`: a reset world's episode (its target, initial and best distance, grasp and
  slip tracker cleared, peak force, step count, friction and Young's scale for the info);
* :func:`evaluate_step`: the readouts (wrist, per-jaw normal forces, contact and slipping counts),
  the grasp (at least two jaws above ``hold_force``), the slip tracker (started on the contacted
  nodes when a grasp first holds; the relative displacement of wrist and those nodes' centroid),
  the peak of the summed jaw force, the distance to the target and its record while grasped,
  success and drop, truncation, the six declared reward terms and their sum;
* :func:`observe`: the observation rows (float32, the single env's layout) and the info metrics
  (step count, friction, Young's scale, slip distance, peak force).

Reproducing the host's results bit for bit (the module compiles without floating-point
contraction, ``fuse_fp=False``): the jaws' forces are summed in order (``total_normal_force``,
``excess_force_penalty``); ``vector_norm`` and ``np.linalg.norm`` of a 3-vector are sqrt of BLAS's
in-order dot (:func:`~surgsim_envs.batch.device_reductions.dot_norm`); the centroid
``positions[nodes].mean(axis=0)`` adds the rows in node order (a reduction over the outer axis:
no pairwise split) and divides by the count; the reward is Python's ``sum()`` of the terms in
declared order (:func:`~surgsim_envs.batch.device_reductions.python_sum_add`).
"""

from __future__ import annotations

import warp as wp

from surgsim_envs.batch.device_reductions import dot_norm, python_sum_add, python_sum_total
from surgsim_envs.batch.grasp_scene_funcs import node_centroid, tool_count, wrist_position

# forward kernels only: nothing differentiates them, and adjoints would double the compile time
wp.set_module_options({"fuse_fp": False, "enable_backward": False})

#: the grasper's jaws (the per-jaw observation entries and ``contact_reward``'s denominator)
JAWS = 3


@wp.struct
class GraspParams:
    """The config numbers the kernels read (SI units, weights as the declared terms read them)."""

    hold_force: wp.float64          # N, a jaw holds above it
    damage_force: wp.float64        # N per jaw
    tolerance: wp.float64           # m, success distance
    max_episode_steps: int
    open_radius: wp.float64         # m, the jaw opening at qpos 0
    static_friction_ratio: wp.float64
    compensated_sum: int            # 1: the reward sums as Python 3.12+'s sum() (Neumaier)
    w_excess_force: wp.float64
    w_contact: wp.float64
    w_progress: wp.float64
    w_slip: wp.float64
    w_drop: wp.float64
    w_success: wp.float64


@wp.struct
class GraspState:
    """Per-world episode state (W rows; the slip tracker's node set as a (W, N) mask)."""

    goal: wp.array(dtype=wp.vec3d)           # m, the wrist's target
    goal_dist0: wp.array(dtype=wp.float64)   # m, initial distance (>= 1e-6)
    best_dist: wp.array(dtype=wp.float64)    # m, closest approach while grasped
    distance: wp.array(dtype=wp.float64)     # m, last live step's distance (NaN until a world's first step)
    was_grasped: wp.array(dtype=wp.int32)
    slip_active: wp.array(dtype=wp.int32)
    slip_nodes: wp.array2d(dtype=wp.int32)   # 1 for the nodes the slip tracker follows
    slip_count: wp.array(dtype=wp.int32)
    tool0: wp.array(dtype=wp.vec3d)          # wrist when the tracker started
    centroid0: wp.array(dtype=wp.vec3d)      # the nodes' centroid then
    slip_distance: wp.array(dtype=wp.float64)
    peak: wp.array(dtype=wp.float64)         # N, peak summed jaw normal force
    steps: wp.array(dtype=wp.int32)
    mu: wp.array(dtype=wp.float64)
    young_scale: wp.array(dtype=wp.float64)


@wp.kernel
def reset_worlds(s: GraspState, worlds: wp.array(dtype=wp.int32), goals: wp.array(dtype=wp.vec3d),
                 goal_dist0: wp.array(dtype=wp.float64), mu: wp.array(dtype=wp.float64),
                 young_scale: wp.array(dtype=wp.float64)):
    """Thread per listed world: a new episode (its draws from the host; ``distance`` is kept, as
    the host keeps each world's last distance)."""
    t = wp.tid()
    w = worlds[t]
    zero = wp.float64(0.0)
    s.goal[w] = goals[t]
    s.goal_dist0[w] = goal_dist0[t]
    s.best_dist[w] = goal_dist0[t]
    s.was_grasped[w] = 0
    s.slip_active[w] = 0
    s.slip_count[w] = 0
    s.slip_distance[w] = zero
    s.peak[w] = zero
    s.steps[w] = 0
    s.mu[w] = mu[t]
    s.young_scale[w] = young_scale[t]


@wp.kernel
def evaluate_step(s: GraspState, p: GraspParams, xpos: wp.array2d(dtype=wp.vec3f), body: int,
                  geom_fn: wp.array2d(dtype=wp.float64), jaw_columns: wp.array(dtype=wp.int32),
                  tool_contacts: wp.array2d(dtype=wp.int32), tool_slipping: wp.array2d(dtype=wp.int32),
                  tool_rows: wp.array(dtype=wp.int32), contact_mask: wp.array2d(dtype=wp.int32),
                  x: wp.array2d(dtype=wp.vec3d), live: wp.array(dtype=wp.int32), unstable: wp.array(dtype=wp.int32),
                  reward: wp.array(dtype=wp.float64), terms: wp.array2d(dtype=wp.float64),
                  terminated: wp.array(dtype=wp.bool), truncated: wp.array(dtype=wp.bool),
                  ended: wp.array(dtype=wp.bool), grasped_out: wp.array(dtype=wp.bool),
                  success: wp.array(dtype=wp.bool), dropped_out: wp.array(dtype=wp.bool),
                  distance: wp.array(dtype=wp.float64)):
    """Thread per world: the batched env's ``_evaluate`` (``live``: the world stepped its episode;
    ``unstable``: it diverged and was reset this step, terminated). ``terms`` (6, W): excess_force,
    contact, progress, slip, drop, success."""
    w = wp.tid()
    zero = wp.float64(0.0)
    t_excess = zero
    t_contact = zero
    t_progress = zero
    t_slip = zero
    t_drop = zero
    t_success = zero
    total = zero
    grasped = False
    succeeded = False
    dropped = False
    trunc = False
    if live[w] != 0:
        steps = s.steps[w] + 1
        s.steps[w] = steps
        pos = wrist_position(xpos, w, body)
        fn0 = geom_fn[w, jaw_columns[0]]
        fn1 = geom_fn[w, jaw_columns[1]]
        fn2 = geom_fn[w, jaw_columns[2]]
        contacts = tool_count(tool_contacts, tool_rows, w)
        slipping = tool_count(tool_slipping, tool_rows, w)
        holding = int(0)                                    # jaws_in_contact
        if fn0 > p.hold_force:
            holding += 1
        if fn1 > p.hold_force:
            holding += 1
        if fn2 > p.hold_force:
            holding += 1
        grasped = holding >= 2
        if grasped and s.slip_active[w] == 0:               # the slip tracker starts on the contacted nodes
            n = int(0)
            for i in range(contact_mask.shape[1]):
                m = contact_mask[w, i]
                s.slip_nodes[w, i] = m
                if m != 0:
                    n += 1
            if n > 0:
                s.slip_active[w] = 1
                s.slip_count[w] = n
                s.tool0[w] = pos
                s.centroid0[w] = node_centroid(x, s.slip_nodes, w, n)
        slip = zero
        if s.slip_active[w] != 0:
            rel = (pos - s.tool0[w]) - (node_centroid(x, s.slip_nodes, w, s.slip_count[w]) - s.centroid0[w])
            slip = dot_norm(rel)
        s.slip_distance[w] = slip
        force = (fn0 + fn1) + fn2                           # total_normal_force
        if force > s.peak[w]:
            s.peak[w] = force
        dist = dot_norm(s.goal[w] - pos)
        s.distance[w] = dist
        gain = zero
        if grasped:
            best = s.best_dist[w]
            gain = wp.max(zero, best - dist)                # record_progress
            if dist < best:
                s.best_dist[w] = dist
            s.was_grasped[w] = 1
            if dist <= p.tolerance:
                succeeded = True
        elif s.was_grasped[w] != 0 and contacts == 0:
            dropped = True
        excess = zero                                       # excess_force_penalty
        d = fn0 - p.damage_force
        if d > zero:
            excess = excess + d
        d = fn1 - p.damage_force
        if d > zero:
            excess = excess + d
        d = fn2 - p.damage_force
        if d > zero:
            excess = excess + d
        t_excess = -p.w_excess_force * excess
        t_contact = p.w_contact * wp.float64(holding) / wp.float64(JAWS)
        if grasped:
            t_progress = p.w_progress * gain / s.goal_dist0[w]
            fraction = zero
            if contacts > 0:
                fraction = wp.float64(slipping) / wp.float64(contacts)
            t_slip = -p.w_slip * fraction
        if dropped:
            t_drop = -p.w_drop
        if succeeded:
            t_success = p.w_success
        acc = wp.vec2d(zero, zero)
        acc = python_sum_add(acc, t_excess, p.compensated_sum)
        acc = python_sum_add(acc, t_contact, p.compensated_sum)
        acc = python_sum_add(acc, t_progress, p.compensated_sum)
        acc = python_sum_add(acc, t_slip, p.compensated_sum)
        acc = python_sum_add(acc, t_drop, p.compensated_sum)
        acc = python_sum_add(acc, t_success, p.compensated_sum)
        total = python_sum_total(acc)
        trunc = (not (succeeded or dropped)) and steps >= p.max_episode_steps
    terms[0, w] = t_excess
    terms[1, w] = t_contact
    terms[2, w] = t_progress
    terms[3, w] = t_slip
    terms[4, w] = t_drop
    terms[5, w] = t_success
    reward[w] = total
    term = succeeded or dropped
    terminated[w] = term or (unstable[w] != 0)
    truncated[w] = trunc
    ended[w] = term or trunc or (unstable[w] != 0)
    grasped_out[w] = grasped
    success[w] = succeeded
    dropped_out[w] = dropped
    distance[w] = s.distance[w]


@wp.kernel
def observe(s: GraspState, p: GraspParams, xpos: wp.array2d(dtype=wp.vec3f), body: int,
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
    to_goal = s.goal[w] - pos
    for i in range(3):
        obs[w, i] = wp.float32(pos[i])
        obs[w, 3 + i] = wp.float32(to_goal[i])
    obs[w, 6] = wp.float32(p.open_radius - wp.float64(qpos[w, jaw_qpos]))
    for j in range(JAWS):
        obs[w, 7 + j] = wp.float32(geom_fn[w, jaw_columns[j]])
        obs[w, 10 + j] = wp.float32(geom_ft[w, jaw_columns[j]])
    obs[w, 13] = wp.float32(tool_count(tool_slipping, tool_rows, w))
    obs[w, 14] = wp.float32(tool_count(tool_contacts, tool_rows, w))
    steps[w] = wp.int64(s.steps[w])
    mu[w] = s.mu[w]
    mu_static[w] = p.static_friction_ratio * s.mu[w]
    young_scale[w] = s.young_scale[w]
    slip_distance[w] = s.slip_distance[w]
    peak[w] = s.peak[w]
