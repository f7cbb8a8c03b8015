"""W copies of one scene stepped together on a Warp device: tissue and contact in Warp kernels
(float64), tools in MuJoCo Warp (float32).

One physics step, in the order of ``scene/simulation.py``'s generic loop (DESIGN.md "One physics
step"), for all worlds at once:

1. :func:`~surgsim_envs.batch.rigid_kernels.rate_limit` - actuator targets towards their goals;
2. ``mujoco_warp.step1`` - tool kinematics and velocities at t (MuJoCo's ``mj_step1``);
3. :func:`~surgsim_envs.batch.contact_kernels.gather_geoms`, ``contact_points``, ``tool_sums`` -
   contact forces from the tissue at t and the tools at t, and their reaction per tool body;
4. the tissue model's kernels (mass-spring: springs, volume term, node gather + symplectic Euler);
5. :func:`~surgsim_envs.batch.contact_kernels.write_reaction` - the reaction into ``xfrc_applied``;
6. ``mujoco_warp.step2`` - tools to t + dt with that reaction (``mj_step2``); the rows are cleared.

Tools and tissue see the same force over the same interval, as on the CPU. On a GPU each call of
:meth:`BatchSimulation.step` (and of a control schedule) is captured once as a CUDA graph and
replayed (:mod:`~surgsim_envs.batch.step_graph`): the steps above do device work only. Built from a CPU
:class:`~surgsim_envs.scene.Simulation` (the template: its MuJoCo model, its tissue's parameters
and its contact law), so a one-world batch steps the same scene as the template.

Supported now: one tissue of the mass-spring model with the symplectic integrator (with tissue
sub-cycling), sphere, capsule, box and cylinder tool geoms, contact at the nodes (no embedded
surface samples), explicit contact damping.
Anything else raises :class:`~surgsim_envs.batch.backend.BatchUnavailableError` naming it.
"""

from __future__ import annotations

import dataclasses
from contextlib import contextmanager

import mujoco
import numpy as np

from surgsim_envs.batch import contact_kernels as ck
from surgsim_envs.batch import mass_spring_kernels as msk
from surgsim_envs.batch import reset_kernels as rsk
from surgsim_envs.batch import rigid_kernels as rk
from surgsim_envs.batch.backend import BatchUnavailableError, device_name, require
from surgsim_envs.batch.state import (ContactState, MassSpringFields, MassSpringTopology, TissueState, ToolState,
                                      _put, _tiled, csr)
from surgsim_envs.batch.step_graph import StepGraphs
from surgsim_envs.contact import ROUNDED_BOX
from surgsim_envs.errors import ConfigError
from surgsim_envs.tissue.mass_spring import MassSpringModel

_GEOM_KIND = {int(mujoco.mjtGeom.mjGEOM_SPHERE): ck.SPHERE, int(mujoco.mjtGeom.mjGEOM_CAPSULE): ck.CAPSULE,
              int(mujoco.mjtGeom.mjGEOM_BOX): ck.BOX, int(mujoco.mjtGeom.mjGEOM_CYLINDER): ck.CYLINDER}
#: upper bound of the worlds one batch holds (memory: about 1 kB per tissue node-world)
MAX_WORLDS = 1 << 20


def _mass_spring_parts(tissue, dt: float, W: int, device: str):
    """(topology, per-world fields) of a symplectic mass-spring tissue, every world its copy."""
    wp, _ = require()
    if not isinstance(tissue, MassSpringModel) or tissue.active_integrator != "symplectic":
        raise BatchUnavailableError(
            f"the batched backend steps the mass-spring model with the symplectic integrator; this scene's tissue is "
            f"{type(tissue).__name__} with integrator {getattr(tissue, 'active_integrator', None)!r} (not batched yet)")
    (_, _, inv_mass, b0, gravity, fixed, si, sj, L0, K1, K2, _, _, kMg, decay, _, _, _, tets, V0,
     kv) = tissue.symplectic_kernel_state(dt)
    n, ne, nt = tissue.n_nodes, len(si), len(tets)
    spring_nodes = np.concatenate([si, sj])
    sign = np.concatenate([np.ones(ne), -np.ones(ne)])
    s_start, s_order = csr(spring_nodes, n)
    corner_nodes = np.asarray(tets, dtype=np.int64).reshape(-1)
    c_start, c_order = csr(corner_nodes, n)
    rest = np.array(tissue.rest_positions, dtype=np.float64)
    fx = np.asarray(tissue.fixed, dtype=bool)
    rest[fx] = np.asarray(tissue.fixed_targets)[fx]
    topo = MassSpringTopology(
        si=_put(wp, si.astype(np.int32), wp.int32, device), sj=_put(wp, sj.astype(np.int32), wp.int32, device),
        L0=_put(wp, L0, wp.float64, device), decay=_put(wp, decay, wp.float64, device),
        tets=_put(wp, np.asarray(tets, dtype=np.int32).reshape(-1, 4), wp.int32, device),
        V0=_put(wp, V0 if nt else np.ones(0), wp.float64, device),
        inv_mass=_put(wp, inv_mass, wp.float64, device), b0=_put(wp, b0, wp.float64, device),
        fixed=_put(wp, fx.astype(np.int32), wp.int32, device), gravity=tuple(float(g) for g in gravity),
        spring_start=_put(wp, s_start, wp.int32, device), node_springs=_put(wp, (s_order % ne).astype(np.int32), wp.int32, device),
        spring_sign=_put(wp, sign[s_order], wp.float64, device), corner_start=_put(wp, c_start, wp.int32, device),
        node_corners=_put(wp, c_order, wp.int32, device), rest=rest, n_nodes=n, n_springs=ne, n_tets=nt)
    fields = MassSpringFields(K1=_put(wp, _tiled(K1, W), wp.float64, device), K2=_put(wp, _tiled(K2, W), wp.float64, device),
                              kM=_put(wp, _tiled(tissue.kM, W), wp.float64, device),
                              kMg=_put(wp, _tiled(kMg, W), wp.float64, device),
                              kv=_put(wp, _tiled(kv if nt else np.zeros(0), W), wp.float64, device))
    return topo, fields


def _row_sum(a: np.ndarray) -> np.ndarray:
    """(W,) sums of the columns of ``a`` (W, k) added left to right (the CPU report's order)."""
    total = a[:, 0].copy() if a.shape[1] else np.zeros(a.shape[0])
    for j in range(1, a.shape[1]):
        total = total + a[:, j]
    return total


class BatchSimulation:
    """W worlds of the scene of ``template`` (a CPU :class:`~surgsim_envs.scene.Simulation`, at its
    reset state) on Warp device ``device`` ("cpu" runs everywhere; "cuda" where a GPU exists).

    Commands: :meth:`set_goals` (actuator goals per world, the rate limiter moves the controls as
    the CPU scene does), :meth:`step` (physics steps), :meth:`reset_worlds`. Readouts as numpy
    arrays (a copy) or the device arrays themselves (``.arrays()``; DLPack-capable Warp arrays).
    ``graphs``: "auto" (CUDA graphs of the physics calls on a GPU, plain launches elsewhere), "on"
    (ConfigError where impossible) or "off" (:class:`~surgsim_envs.batch.step_graph.StepGraphs`).
    """

    def __init__(self, template, worlds: int, *, device: str = "cpu", graphs: str = "auto"):
        wp, mjw = require()
        if isinstance(worlds, bool) or not isinstance(worlds, (int, np.integer)) or not 1 <= worlds <= MAX_WORLDS:
            raise ConfigError(f"worlds={worlds!r} must be an integer in [1, {MAX_WORLDS}] (scene copies)")
        self.device = device_name(device)
        self.W = W = int(worlds)
        self.dt = float(template.dt)
        #: tissue sub-steps of dt per MuJoCo step of n dt (the template's ``tissue_subcycles``)
        self.subcycles = int(template.tissue_subcycles)
        if len(template.tissues) != 1:
            raise BatchUnavailableError(f"the batched backend steps one tissue per scene; this one has "
                                        f"{len(template.tissues)}")
        (tissue_name, tissue), = template.tissues.items()
        contact = template.contacts[tissue_name]
        self.template = template
        m = template.model
        if m.nmocap:
            raise BatchUnavailableError("mocap-driven tools (haptic proxies) are not batched yet")
        geoms, bodies = [], []
        for tool in template.tools.values():
            geoms += [int(g) for g in tool.geom_ids]
        bodies = sorted({int(m.geom_bodyid[g]) for g in geoms})
        kinds = []
        for g in geoms:
            t = int(m.geom_type[g])
            if t not in _GEOM_KIND:
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
                raise BatchUnavailableError(f"tool geom {name!r} (type {t}) is not batched yet: the batched contact "
                                            "supports sphere, capsule, box and cylinder geoms")
            kinds.append(_GEOM_KIND[t])
        if np.any(template.shape_kinds == ROUNDED_BOX):
            raise BatchUnavailableError("rounded tool edges (a grasper's jaw_edges='round') are not batched yet; "
                                        "use jaw_edges='sharp'")
        if contact.n_samples:
            raise BatchUnavailableError(f"embedded surface contact samples ({contact.surface_subdivisions} "
                                        "subdivisions) are not batched yet; build the scene with surface_samples=None")
        if contact.params.implicit_damping:
            raise BatchUnavailableError("implicit contact damping is not batched yet (explicit damping only)")
        G, B = len(geoms), max(len(bodies), 1)
        self.geom_ids, self.bodies = geoms, bodies
        self.tool_index = {name: sorted({bodies.index(int(m.geom_bodyid[g])) for g in tool.geom_ids})
                           for name, tool in template.tools.items()}
        self.tool_body = {name: int(tool.body_id) for name, tool in template.tools.items()}
        self.tool_actuators = {name: [int(a) for a in tool.actuator_ids] for name, tool in template.tools.items()}
        self.tool_home = {name: np.array(tool.home, dtype=float) for name, tool in template.tools.items()}
        self.tool_frame = {name: np.array(tool.frame, dtype=float) for name, tool in template.tools.items()}
        dev = self.device
        with wp.ScopedDevice(dev):
            self.topology, self.fields = _mass_spring_parts(tissue, self.dt, W, dev)
            self._base_fields = {k: getattr(self.fields, k).numpy()[0].copy() for k in ("K1", "K2", "kM", "kMg", "kv")}
            self._build_spring_weights(tissue)
            self.tissue_state = TissueState.at_rest(self.topology.rest, self.topology.n_springs, W, dev)
            self._rest = _put(wp, self.topology.rest, wp.vec3d, dev)
            C = len(contact.candidate_nodes)
            self.contact = ContactState.zeros(W, tissue.n_nodes, C, G, B, dev)
            self._cand = _put(wp, contact.candidate_nodes.astype(np.int32), wp.int32, dev)
            self._kind = _put(wp, np.array(kinds, dtype=np.int32), wp.int32, dev)
            self._tool = _put(wp, np.array([bodies.index(int(m.geom_bodyid[g])) for g in geoms], np.int32), wp.int32, dev)
            self._size = _put(wp, np.asarray(m.geom_size[geoms], dtype=np.float64).reshape(-1, 3), wp.float64, dev)
            self._geom_ids = _put(wp, np.array(geoms, np.int32), wp.int32, dev)
            self._geom_body = _put(wp, np.array([m.geom_bodyid[g] for g in geoms], np.int32), wp.int32, dev)
            self._geom_root = _put(wp, np.array([m.body_rootid[m.geom_bodyid[g]] for g in geoms], np.int32), wp.int32, dev)
            self._bodies = _put(wp, np.array(bodies, np.int32), wp.int32, dev)
            mu = np.zeros(B) + float(contact.tool_friction[0])
            mu[:len(contact.tool_friction)] = contact.tool_friction[:B]
            mu_s = np.zeros(B) + float(contact.tool_static_friction[0])
            mu_s[:len(contact.tool_static_friction)] = contact.tool_static_friction[:B]
            self.contact.mu.assign(_tiled(mu, W))
            self.contact.mu_s.assign(_tiled(mu_s, W))
            k_n = float(contact.stiffness_for(self.dt))
            k_t = float(contact.params.tangential_stiffness or k_n)
            self._k_n, self._c_n, self._k_t = k_n, float(contact.params.damping), k_t
            template.reset()
            mjm = template.model
            self._mjm = mjm
            mjm.opt.timestep = self.dt * self.subcycles
            rate = np.full(mjm.nu, np.inf)
            for tool in template.tools.values():
                for a, r in tool.actuator_rates().items():
                    rate[a] = r
            self.tools = ToolState(model=mjw.put_model(mjm), data=mjw.put_data(mjm, template.data, nworld=W),
                                   ctrl64=wp.zeros((W, mjm.nu), dtype=wp.float64, device=dev),
                                   goal=wp.zeros((W, mjm.nu), dtype=wp.float64, device=dev),
                                   rate=_put(wp, _tiled(rate, W), wp.float64, dev),
                                   moving=wp.zeros(W, dtype=wp.int32, device=dev))
        self.steps = 0
        self._mjw, self._wp = mjw, wp
        self._model_name = type(tissue).name
        self._critical_dt = float(tissue.critical_dt())     # at rest, for the divergence message
        #: CUDA graphs of the physics calls (:mod:`surgsim_envs.batch.step_graph`; plain launches on the CPU)
        self.graphs = StepGraphs(wp, self.device, graphs)
        self._schedule_buffers: dict = {}
        #: [(one world's reset row, (W, bytes) rows)] of every per-world MuJoCo Warp Data array, recorded
        #: at the first reset (MuJoCo Warp's reset_data + forward) and restored at the later ones
        self._reset_snapshot = None
        self._csr = self._kv_base = None        # device copies of the spring weights and volume constants
        self._world_rows = None                 # world_rows(), built at first use
        if self.graphs.enabled:               # a graph keeps the addresses it recorded: allocate before it
            self._f_spring, self._f_corner

    # ------------------------------------------------------------------------------------------
    # stepping
    def step(self, n: int = 1) -> None:
        """``n`` physics steps of dt in every world (module docstring); with tissue sub-cycling
        (``subcycles`` > 1) n must be a multiple of it (whole MuJoCo steps)."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ConfigError(f"step(n): n must be a whole number of physics steps >= 0, got {n!r}")
        if n % self.subcycles:
            raise ConfigError(f"step(n): with tissue_subcycles={self.subcycles} the worlds advance in whole MuJoCo "
                              f"steps of {self.subcycles} physics steps; {n} is not a multiple of it")
        K = int(n) // self.subcycles
        if K:
            self._run(("step", K), lambda: self._mujoco_steps(K))
            self.steps += int(n)

    def _mujoco_steps(self, K: int) -> None:
        for _ in range(K):
            self._one_step()

    def _run(self, key, body) -> None:
        """``body`` (device work only) as a replayed CUDA graph where graphs are on, plainly while
        profiling (its phases synchronise the device)."""
        if self.phase_seconds is None:
            self.graphs.run(key, body)
        else:
            body()

    def step_with_controls(self, actuators, values) -> None:
        """``K`` MuJoCo steps (each ``subcycles`` physics steps) with a per-world control schedule
        computed ahead: before the k-th, ``ctrl[w, actuators] = values[k, w]`` in every world w (then
        the rate limiter, where a world's targets still move), as :meth:`Simulation.step_with_controls`
        does for one scene. ``actuators`` (A,) ids; ``values`` (K, W, A) in the actuators' units (a
        force motor's newtons, a jaw's closing travel in m); one host-to-device copy per call."""
        ids = np.asarray(actuators, dtype=np.int64).reshape(-1)
        nu = self._mjm.nu
        if len(ids) == 0 or ids.min() < 0 or ids.max() >= nu:
            raise ConfigError(f"actuators must be ids in [0, {nu}), got {ids.tolist()}")
        vals = np.asarray(values, dtype=np.float64)
        if vals.ndim != 3 or vals.shape[1:] != (self.W, len(ids)):
            raise ConfigError(f"values must have shape (steps, {self.W}, {len(ids)}) (MuJoCo steps, worlds, "
                              f"actuators), got {vals.shape}")
        if not np.all(np.isfinite(vals)):
            raise ConfigError("control values contain NaN/inf; give finite numbers")
        if not len(vals):
            return
        wp = self._wp
        with wp.ScopedDevice(self.device):
            vals_d = wp.array(np.ascontiguousarray(vals), dtype=wp.float64)
        self._scheduled_steps(ids, vals_d)

    def step_with_control_array(self, actuators, values) -> None:
        """:meth:`step_with_controls` with the schedule already on the device: ``values`` a float64
        Warp array (K, W, A) on this batch's device (e.g. filled by a task's schedule kernel),
        stepped without a host copy; the caller keeps its values finite."""
        wp = self._wp
        ids = self._actuator_ids(actuators)
        if not isinstance(values, wp.array) or values.dtype != wp.float64 or values.ndim != 3 \
                or tuple(values.shape[1:]) != (self.W, len(ids)):
            raise ConfigError(f"values must be a float64 Warp array of shape (steps, {self.W}, {len(ids)}) (MuJoCo "
                              f"steps, worlds, actuators); got {type(values).__name__} "
                              f"{getattr(values, 'shape', None)}; give numpy values to step_with_controls instead")
        if str(values.device) != str(wp.get_device(self.device)):
            raise ConfigError(f"values are on device {values.device}, the batch on {self.device}; allocate them "
                              f"on {self.device}")
        self._scheduled_steps(ids, values)

    def controls_array(self):
        """(W, nu) float64 device array: every actuator's float64 control in every world (what
        :meth:`controls` copies to the host), the batch's own: read it, do not write it."""
        return self.tools.ctrl64

    def _scheduled_steps(self, ids: np.ndarray, vals_d) -> None:
        """The MuJoCo steps of the (K, W, A) device schedule ``vals_d`` of actuators ``ids``."""
        wp = self._wp
        K = int(vals_d.shape[0])
        if not K:
            return
        if self.graphs.enabled and self.phase_seconds is None:
            # the graph records the addresses of its schedule: the values are copied into its own buffer
            key = ("schedule", K, ids.tobytes())
            if key not in self._schedule_buffers:
                with wp.ScopedDevice(self.device):
                    self._schedule_buffers[key] = (wp.array(ids.astype(np.int32), dtype=wp.int32),
                                                   wp.empty(tuple(vals_d.shape), dtype=wp.float64))
            ids_d, buf = self._schedule_buffers[key]
            wp.copy(buf, vals_d)
            self.graphs.run(key, lambda: self._schedule_body(ids_d, buf))
        else:
            with wp.ScopedDevice(self.device):
                ids_d = wp.array(ids.astype(np.int32), dtype=wp.int32)
            self._schedule_body(ids_d, vals_d)
        self.steps += K * self.subcycles

    def _schedule_body(self, ids_d, vals_d) -> None:
        """The MuJoCo steps of the schedule ``vals_d`` (K, W, A) of actuators ``ids_d`` (device work only)."""
        wp, t = self._wp, self.tools
        for k in range(vals_d.shape[0]):
            with wp.ScopedDevice(self.device):
                wp.launch(rk.set_controls, dim=(self.W, ids_d.shape[0]), inputs=[k, ids_d, vals_d, t.ctrl64,
                                                                                 t.data.ctrl])
            self._one_step()

    def _one_step(self) -> None:
        """One MuJoCo step of n dt (n = ``subcycles``) with n tissue + contact sub-steps of dt, as
        ``Simulation._subcycled_steps`` (n = 1: its generic loop): inside the MuJoCo step the geoms
        move along their velocity at its start; the tools get the mean of the n reactions."""
        wp, mjw = self._wp, self._mjw
        W, dev, n = self.W, self.device, self.subcycles
        t, d, c, ts = self.tools, self.tools.data, self.contact, self.tissue_state
        dt = wp.float64(self.dt)
        G, B, C = len(self.geom_ids), len(self.bodies), self._cand.shape[0]
        mark = self._mark
        with wp.ScopedDevice(dev):
            mark(None)
            wp.launch(rk.rate_limit, dim=W, inputs=[t.ctrl64, t.goal, t.rate, t.moving, wp.float64(self.dt * n), d.ctrl])
            mark("rate_limit")
            mjw.step1(t.model, d)
            mark("mujoco_warp.step1")
            wp.launch(ck.gather_geoms, dim=(W, G), inputs=[self._geom_ids, self._geom_body, self._geom_root, self._bodies,
                                                          d.geom_xpos, d.geom_xmat, d.cvel, d.subtree_com, d.xipos,
                                                          c.gpos, c.gmat, c.gang, c.glin, c.tcom])
            if n > 1:
                wp.copy(c.gpos0, c.gpos)
            mark("contact")
            for j in range(n):
                if j:
                    wp.launch(ck.advance_geoms, dim=(W, G), inputs=[c.gpos0, c.glin, wp.float64(j * self.dt), c.gpos])
                wp.launch(ck.contact_points, dim=(W, C), inputs=[ts.x, ts.v, self._cand, self._kind, self._tool, self._size,
                                                                c.gpos, c.gmat, c.gang, c.glin, c.mu, c.mu_s,
                                                                wp.float64(self._k_n), wp.float64(self._c_n),
                                                                wp.float64(self._k_t), c.anchor, c.state, c.f_ext,
                                                                c.point_force, c.point_fn, c.point_ft, c.point_depth])
                wp.launch(ck.tool_sums, dim=(W, B), inputs=[ts.x, self._cand, self._tool, c.point_force, c.point_fn,
                                                           c.point_ft, c.point_depth, c.state, c.tcom, c.tool_force,
                                                           c.tool_torque, c.tool_fn, c.tool_ft, c.tool_contacts,
                                                           c.tool_slipping, c.tool_depth])
                wp.launch(ck.add_wrench, dim=(W, B), inputs=[c.tool_force, c.tool_torque, c.sum_force, c.sum_torque])
                mark("contact")
                self._tissue_step(dt)
                mark("tissue")
            wp.launch(ck.write_reaction, dim=(W, B), inputs=[self._bodies, c.sum_force, c.sum_torque, wp.float64(n),
                                                            d.xfrc_applied])
            mark("reaction")
            mjw.step2(t.model, d)
            wp.launch(ck.zero_reaction, dim=(W, B), inputs=[self._bodies, d.xfrc_applied])
            mark("mujoco_warp.step2")

    #: phase -> seconds spent in it (wall clock, device synchronised after each phase) while
    #: profiling (:meth:`profile`); None: not profiling (no synchronisation between phases)
    phase_seconds: dict | None = None

    def profile(self, on: bool = True) -> None:
        """Start (on) or stop timing the phases of every step into :attr:`phase_seconds` (the device
        is synchronised after each phase, which costs time on a GPU: for the shares, not the totals)."""
        self.phase_seconds = {} if on else None

    def _mark(self, phase) -> None:
        if self.phase_seconds is None:
            return
        import time

        self._wp.synchronize_device(self.device)
        now = time.perf_counter()
        if phase is not None:
            self.phase_seconds[phase] = self.phase_seconds.get(phase, 0.0) + now - self._t_mark
        self._t_mark = now

    def _tissue_step(self, dt) -> None:
        wp = self._wp
        W, ts, topo, fl, c = self.W, self.tissue_state, self.topology, self.fields, self.contact
        wp.launch(msk.spring_forces, dim=(W, topo.n_springs),
                  inputs=[ts.x, topo.si, topo.sj, topo.L0, fl.K1, fl.K2, fl.kM, fl.kMg, topo.decay, ts.fresh, ts.s,
                          ts.dl, self._f_spring])
        if topo.n_tets:
            wp.launch(msk.volume_forces, dim=(W, topo.n_tets), inputs=[ts.x, topo.tets, topo.V0, fl.kv, self._f_corner])
        wp.launch(msk.integrate_nodes, dim=(W, topo.n_nodes),
                  inputs=[ts.x, ts.v, topo.spring_start, topo.node_springs, topo.spring_sign, topo.corner_start,
                          topo.node_corners, self._f_spring, self._f_corner, c.f_ext, topo.inv_mass, topo.b0,
                          wp.vec3d(*topo.gravity), topo.fixed, dt, ts.fresh, ts.diverged])

    @property
    def _f_spring(self):
        buf = getattr(self, "_f_spring_buf", None)
        if buf is None:
            wp = self._wp
            buf = self._f_spring_buf = wp.zeros((self.W, self.topology.n_springs), dtype=wp.vec3d, device=self.device)
        return buf

    @property
    def _f_corner(self):
        buf = getattr(self, "_f_corner_buf", None)
        if buf is None:
            wp = self._wp
            buf = self._f_corner_buf = wp.zeros((self.W, max(4 * self.topology.n_tets, 1)), dtype=wp.vec3d,
                                                device=self.device)
        return buf

    # ------------------------------------------------------------------------------------------
    # commands
    def set_tool_targets(self, name: str, positions, speed: float | None = None, worlds=None) -> None:
        """Move tool ``name``'s origin towards ``positions`` ((W, 3) m, world; or (len(worlds), 3)
        for the worlds listed) at ``speed`` m/s (None: the tool's default rate), as
        :meth:`Simulation.set_tool_target` does for one scene."""
        if name not in self.tool_actuators:
            raise ConfigError(f"unknown tool {name!r}; tools in this scene: {sorted(self.tool_actuators)}")
        idx = np.arange(self.W) if worlds is None else np.asarray(worlds, dtype=np.int64).reshape(-1)
        pos = np.asarray(positions, dtype=np.float64)
        if pos.shape != (len(idx), 3) or not np.all(np.isfinite(pos)):
            raise ConfigError(f"positions must be finite ({len(idx)}, 3) m, got shape {pos.shape}")
        tool = self.template.tools[name]
        local = (pos - self.tool_home[name]) @ self.tool_frame[name]     # = frame.T @ (p - home) per row
        travel = float(tool.config.travel)
        if np.abs(local).max(initial=0.0) > travel + 1e-12:
            raise ConfigError(f"a target of tool {name!r} lies outside its reach of +-{travel} m about its home "
                              f"{self.tool_home[name].round(4).tolist()} m; choose closer targets")
        if speed is not None and not (isinstance(speed, (int, float)) and speed > 0):
            raise ConfigError(f"speed must be a positive number (m/s), or math.inf for no limit, got {speed!r}")
        self._write_goals(idx, self.tool_actuators[name][:3], local, speed)

    def set_actuator_goals(self, actuators, goals, speed: float | None = None, worlds=None) -> None:
        """Move actuators ``actuators`` (A,) ids towards ``goals`` ((W, A), or (A,) for every listed
        world) at ``speed`` (units/s; None: their default rate), as :meth:`Simulation.set_actuator_goal`;
        e.g. a grasper's jaw: goal = open_radius - radius."""
        ids = np.asarray(actuators, dtype=np.int64).reshape(-1)
        nu = self._mjm.nu
        if len(ids) == 0 or ids.min() < 0 or ids.max() >= nu:
            raise ConfigError(f"actuators must be ids in [0, {nu}), got {ids.tolist()}")
        idx = np.arange(self.W) if worlds is None else np.asarray(worlds, dtype=np.int64).reshape(-1)
        g = np.broadcast_to(np.asarray(goals, dtype=np.float64), (len(idx), len(ids)))
        if not np.all(np.isfinite(g)):
            raise ConfigError("actuator goals must be finite numbers")
        if speed is not None and not (isinstance(speed, (int, float)) and speed > 0):
            raise ConfigError(f"speed must be a positive number, or math.inf for no limit, got {speed!r}")
        self._write_goals(idx, ids, g, speed)

    def _index_array(self, ids) -> object:
        """An int32 device array of ``ids``, kept for the ids met before (all worlds, a tool's actuators)."""
        key = np.asarray(ids, dtype=np.int32).tobytes()
        cache = self.__dict__.setdefault("_index_arrays", {})
        if key not in cache:
            if len(cache) > 64:
                cache.clear()
            cache[key] = self._wp.array(np.frombuffer(key, dtype=np.int32), dtype=self._wp.int32,
                                        device=self.tools.goal.device)
        return cache[key]

    def _write_goals(self, worlds: np.ndarray, actuators, values: np.ndarray, speed: float | None) -> None:
        """Goals ``values`` (len(worlds), len(actuators)) of the listed worlds' actuators, those worlds set
        moving, and their rates set to ``speed`` unless it is None, written on the device
        (:func:`~surgsim_envs.batch.rigid_kernels.write_goals`: only the listed values travel)."""
        if len(worlds) == 0:
            return
        wp, t, dev = self._wp, self.tools, self.tools.goal.device
        wp.launch(rk.write_goals, dim=(len(worlds), len(actuators)), device=dev,
                  inputs=[self._index_array(worlds), self._index_array(actuators),
                          wp.array(np.ascontiguousarray(values, dtype=np.float64), dtype=wp.float64, device=dev),
                          wp.int32(speed is not None), wp.float64(0.0 if speed is None else float(speed)),
                          t.goal, t.rate, t.moving])

    #: MuJoCo state components (mjtState bits, in the state vector's order) and the MuJoCo Warp
    #: ``Data`` field each restores into (None: must be empty in a batched scene)
    _STATE_FIELDS = ((mujoco.mjtState.mjSTATE_TIME, "time"), (mujoco.mjtState.mjSTATE_QPOS, "qpos"),
                     (mujoco.mjtState.mjSTATE_QVEL, "qvel"), (mujoco.mjtState.mjSTATE_ACT, "act"),
                     (mujoco.mjtState.mjSTATE_HISTORY, None), (mujoco.mjtState.mjSTATE_WARMSTART, "qacc_warmstart"),
                     (mujoco.mjtState.mjSTATE_CTRL, "ctrl"), (mujoco.mjtState.mjSTATE_QFRC_APPLIED, "qfrc_applied"),
                     (mujoco.mjtState.mjSTATE_XFRC_APPLIED, "xfrc_applied"),
                     (mujoco.mjtState.mjSTATE_EQ_ACTIVE, "eq_active"), (mujoco.mjtState.mjSTATE_MOCAP_POS, "mocap_pos"),
                     (mujoco.mjtState.mjSTATE_MOCAP_QUAT, "mocap_quat"), (mujoco.mjtState.mjSTATE_USERDATA, "userdata"),
                     (mujoco.mjtState.mjSTATE_PLUGIN, None), (mujoco.mjtState.mjSTATE_PLASTIC, None))

    def set_rigid_states(self, state, worlds=None) -> None:
        """Restore the tools' MuJoCo state ``state`` (a ``mjSTATE_INTEGRATION`` vector of the
        template's model, from ``mujoco.mj_getState``: time, qpos, qvel, act, warm start, controls,
        applied forces, equality flags) into the listed worlds (all if None), in MuJoCo Warp's
        float32 ``Data``; the float64 controls take the state's controls and the rate limiter stops
        in those worlds (as after ``mj_setState`` on a just-reset CPU scene). Tissue and contact
        state are untouched: restore a contact-free state (an approach snapshot,
        :mod:`surgsim_envs.scene.approach_snapshot`) on worlds just reset with :meth:`reset_worlds`.
        The kinematics follow at the next step's ``step1`` (readouts of poses are stale until then).
        One host round trip per field (a reset, not a step)."""
        m = self._mjm
        spec = int(mujoco.mjtState.mjSTATE_INTEGRATION)
        vec = np.asarray(state, dtype=np.float64).reshape(-1)
        size = mujoco.mj_stateSize(m, spec)
        if vec.shape != (size,) or not np.all(np.isfinite(vec)):
            raise ConfigError(f"state must be a finite mjSTATE_INTEGRATION vector of {size} numbers of this scene's "
                              f"MuJoCo model (mujoco.mj_getState(model, data, state, mjSTATE_INTEGRATION)), got "
                              f"shape {vec.shape}")
        idx = np.arange(self.W) if worlds is None else np.asarray(worlds, dtype=np.int64).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= self.W):
            raise ConfigError(f"worlds must be indices in [0, {self.W}), got {idx.tolist()}")
        if not len(idx):
            return
        d, t, at = self.tools.data, self.tools, 0
        ctrl = np.zeros(m.nu)
        for bit, field in self._STATE_FIELDS:
            n = mujoco.mj_stateSize(m, int(bit))
            part, at = vec[at:at + n], at + n
            if field is None:
                if n:
                    raise BatchUnavailableError(f"restoring MuJoCo state component {bit.name} ({n} numbers) is not "
                                                "batched yet")
                continue
            if not n:
                continue
            if field == "ctrl":
                ctrl = part
            arr = getattr(d, field)
            host = arr.numpy()
            host[idx] = part.reshape(host.shape[1:]).astype(host.dtype)
            arr.assign(host)
        c64, moving = t.ctrl64.numpy(), t.moving.numpy()
        c64[idx] = ctrl
        moving[idx] = 0
        t.ctrl64.assign(c64)
        t.moving.assign(moving)

    @contextmanager
    def held(self, worlds):
        """Inside, the physics steps every world as usual; on leaving, worlds ``worlds`` get back
        the state they had on entering: tissue and contact state, controls, goals and rate-limiter
        flags, MuJoCo's integration state and the kinematics the readouts read between steps (body
        and geom poses, actuator forces; MuJoCo Warp recomputes the rest at the next ``step1``), so
        they read and step on bit for bit as if nothing had run. So some worlds can run a reset's
        settle while the others stand still (Slippage-v0's grasp when many worlds autoreset at once;
        a few settle in a small batch instead, :meth:`copy_worlds_from`). Costs a host copy of every
        per-world array and the steps inside for all worlds: for resets, not for every step."""
        W = self.W
        idx = np.asarray(worlds, dtype=np.int64).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= W):
            raise ConfigError(f"worlds must be indices in [0, {W}), got {idx.tolist()}")
        arrays = self._per_world_arrays()
        saved = [a.numpy().copy() for a in arrays] if len(idx) else []
        yield
        if not len(idx):
            return
        for a, before in zip(arrays, saved):
            now = a.numpy()
            now[idx] = before[idx]
            a.assign(now)

    def _per_world_arrays(self) -> list:
        """Every device array whose rows are worlds and that carries state from one step to the next."""
        wp, W = self._wp, self.W
        out = []
        for record in (self.tissue_state, self.contact):
            for name in record.__dataclass_fields__:
                a = getattr(record, name)
                if isinstance(a, wp.array) and a.shape[0] == W:
                    out.append(a)
        t = self.tools
        out += [t.ctrl64, t.goal, t.rate, t.moving]
        fields = [f for _, f in self._STATE_FIELDS if f is not None] + list(self._READOUT_FIELDS)
        out += [getattr(t.data, f) for f in fields if getattr(t.data, f).size]
        return out

    #: MuJoCo Warp ``Data`` fields computed by a step that the readouts read between steps
    _READOUT_FIELDS = ("xpos", "xquat", "xmat", "xipos", "ximat", "geom_xpos", "geom_xmat", "actuator_force")

    def _float_rows(self, arr):
        """A (W, M) float32 view of MuJoCo Warp data field ``arr`` (W, ...) of float32 scalars, vectors,
        quaternions or matrices (one row per world, no copy)."""
        wp = self._wp
        comps = wp.types.type_size(arr.dtype)
        float32_based = any(wp.types.types_equal(arr.dtype, t) for t in (wp.float32, wp.vec3f, wp.quatf, wp.mat33f))
        if not arr.is_contiguous or not float32_based or arr.shape[0] != self.W:
            raise ValueError(f"a (W, ...) contiguous float32 field is needed, got {arr.dtype} {arr.shape}")
        return wp.array(ptr=arr.ptr, dtype=wp.float32, shape=(self.W, arr.size // self.W * comps),
                        device=arr.device)

    def reset_worlds(self, worlds=None) -> None:
        """Back to the template's reset state in the listed worlds (all if None): tissue at rest,
        branches and contacts cleared, MuJoCo data reset, controls and goals zero. The first reset
        runs MuJoCo Warp's ``reset_data`` + ``forward`` (``forward`` in every world; the other
        worlds' poses and actuator forces, what the readouts read between steps, are put back) and
        records the first reset world's row of every per-world ``Data`` array; later resets copy
        that row into the listed worlds (``reset_kernels.restore_rows``) and leave the other worlds
        untouched: the same state, without ``reset_data``'s kernels built at every call (~15 ms of
        Python each) and a ``forward`` of every world."""
        wp, mjw = self._wp, self._mjw
        mask = np.ones(self.W, dtype=bool)
        if worlds is not None:
            mask[:] = False
            mask[np.asarray(worlds, dtype=np.int64).reshape(-1)] = True
        if not mask.any():
            return
        ts, c, t = self.tissue_state, self.contact, self.tools
        topo = self.topology
        with wp.ScopedDevice(self.device):
            idx = wp.array(np.flatnonzero(mask).astype(np.int32), dtype=wp.int32)
            k = idx.shape[0]
            wp.launch(rsk.reset_nodes, dim=(k, topo.n_nodes), inputs=[idx, self._rest, ts.x, ts.v, c.f_ext])
            wp.launch(rsk.reset_springs, dim=(k, topo.n_springs), inputs=[idx, ts.s, ts.dl])
            wp.launch(rsk.reset_contacts, dim=(k, c.state.shape[1], c.state.shape[2]),
                      inputs=[idx, c.state, c.anchor, c.point_force, c.point_fn, c.point_ft, c.point_depth])
            wp.launch(rsk.reset_world_scalars, dim=k, inputs=[idx, ts.fresh, ts.diverged, t.moving, t.ctrl64, t.goal,
                                                              c.tool_force, c.tool_torque, c.tool_fn, c.tool_ft,
                                                              c.tool_contacts, c.tool_slipping, c.tool_depth,
                                                              c.sum_force, c.sum_torque])
            if self._reset_snapshot is not None:      # the recorded reset state, row by row
                for snap, rows in self._reset_snapshot:
                    wp.launch(rsk.restore_rows, dim=(k, rows.shape[1]), inputs=[idx, snap, rows])
                return
            mjw.reset_data(t.model, t.data, reset=wp.array(mask, dtype=bool))
            rows = [self._float_rows(getattr(t.data, f)) for f in self._READOUT_FIELDS] if not mask.all() else []
            saved = [wp.clone(r) for r in rows]
            mjw.forward(t.model, t.data)
            if rows:                        # forward runs in every world: the others' readouts stay as they were
                flags = wp.array(mask.astype(np.int32), dtype=wp.int32)
                for now, before in zip(rows, saved):
                    wp.launch(rsk.keep_rows, dim=now.shape, inputs=[flags, before, now])
            first = int(np.flatnonzero(mask)[0])
            self._reset_snapshot = [(wp.clone(view[first]), view) for _, view in self._data_rows()]

    def world_rows(self) -> dict:
        """{name: (W, row bytes) uint8 view} of every per-world array of the batch: tissue and contact
        state, the per-world material, the rate limiter's commands and every per-world MuJoCo Warp
        ``Data`` array; a world's rows are its whole state (views of the arrays, built once: their
        addresses do not change)."""
        if self._world_rows is None:
            wp, W = self._wp, self.W
            rows = {}
            t = self.tools
            records = {"tissue": self.tissue_state, "contact": self.contact, "fields": self.fields}
            for rec_name, rec in records.items():
                for f in dataclasses.fields(rec):
                    a = getattr(rec, f.name)
                    if isinstance(a, wp.array) and a.ndim and a.shape[0] == W and a.size:
                        rows[f"{rec_name}.{f.name}"] = self._byte_rows(a)
            for name in ("ctrl64", "goal", "rate", "moving"):
                rows[f"tools.{name}"] = self._byte_rows(getattr(t, name))
            rows.update({f"data.{name}": view for name, view in self._data_rows()})
            self._world_rows = rows
        return self._world_rows

    def copy_worlds_from(self, src: "BatchSimulation", src_worlds, dst_worlds) -> None:
        """Worlds ``dst_worlds`` of this batch take the whole state (:meth:`world_rows`) of worlds
        ``src_worlds`` of ``src``, a batch of the same scene (e.g. a small batch that ran a reset's
        settle for a few worlds, so that the others need not step); device copies, no host round trip."""
        wp = self._wp
        s_idx = np.asarray(src_worlds, dtype=np.int64).reshape(-1)
        d_idx = np.asarray(dst_worlds, dtype=np.int64).reshape(-1)
        if len(s_idx) != len(d_idx) or (len(s_idx) and (s_idx.min() < 0 or s_idx.max() >= src.W
                                                           or d_idx.min() < 0 or d_idx.max() >= self.W)):
            raise ConfigError(f"src_worlds and dst_worlds must be as many indices in [0, {src.W}) and [0, {self.W}), "
                              f"got {s_idx.tolist()} and {d_idx.tolist()}")
        if not len(s_idx):
            return
        mine, theirs = self.world_rows(), src.world_rows()
        if set(mine) != set(theirs) or any(mine[k].shape[1] != theirs[k].shape[1] for k in mine):
            raise ConfigError("copy_worlds_from needs a batch of the same scene (its per-world arrays differ)")
        with wp.ScopedDevice(self.device):
            si = wp.array(s_idx.astype(np.int32), dtype=wp.int32)
            di = wp.array(d_idx.astype(np.int32), dtype=wp.int32)
            for name, dst in mine.items():
                wp.launch(rsk.copy_rows, dim=(len(s_idx), dst.shape[1]), inputs=[si, di, theirs[name], dst])

    def _byte_rows(self, a):
        """A (W, row bytes) uint8 view of the contiguous per-world array ``a``."""
        wp = self._wp
        if not a.is_contiguous:
            raise BatchUnavailableError(f"a per-world array of shape {a.shape} is not contiguous; it cannot be copied "
                                        "row by row")
        nbytes = a.size * wp.types.type_size_in_bytes(a.dtype)
        return wp.array(ptr=a.ptr, dtype=wp.uint8, shape=(self.W, nbytes // self.W), device=a.device)

    def _data_rows(self) -> list:
        """[(name, (W, row bytes) uint8 view)] of every per-world MuJoCo Warp ``Data`` array (those whose
        leading dimension is the world count: found by comparing one- and two-world ``put_data``)."""
        wp, mjw, W = self._wp, self._mjw, self.W
        probes = [mjw.put_data(self._mjm, self.template.data, nworld=n) for n in (1, 2)]

        def arrays(d, prefix=""):
            for f in dataclasses.fields(d):
                a = getattr(d, f.name)
                if isinstance(a, wp.array):
                    yield prefix + f.name, a
                elif dataclasses.is_dataclass(a):
                    yield from arrays(a, prefix + f.name + ".")

        one, two = dict(arrays(probes[0])), dict(arrays(probes[1]))
        out = []
        for name, a in arrays(self.tools.data):
            p1, p2 = one[name], two[name]
            per_world = (p1.ndim and p1.shape[0] == 1 and p2.shape[0] == 2 and a.shape[0] == W
                         and p1.shape[1:] == p2.shape[1:] == a.shape[1:])
            if not per_world or not a.size:
                continue
            out.append((name, self._byte_rows(a)))
        return out

    def set_tool_friction(self, mu, mu_static=None, worlds=None) -> None:
        """Coulomb friction of every tool body in the listed worlds (all if None): ``mu`` kinetic,
        ``mu_static`` static (None: equal to ``mu``), each one number per listed world ((k,)) or one
        per world and tool body ((k, B)); as the CPU tasks set ``ContactModel.tool_friction`` /
        ``tool_static_friction`` per episode. Needs 0 <= mu <= mu_static (finite)."""
        idx = np.arange(self.W) if worlds is None else np.asarray(worlds, dtype=np.int64).reshape(-1)
        B = len(self.bodies) or 1
        values = []
        for name, v in (("mu", mu), ("mu_static", mu if mu_static is None else mu_static)):
            a = np.asarray(v, dtype=np.float64)
            if a.shape == (len(idx),):
                a = np.repeat(a[:, None], B, axis=1)
            if a.shape != (len(idx), B) or not np.all(np.isfinite(a)) or np.any(a < 0):
                raise ConfigError(f"{name} must be finite numbers >= 0, one per listed world ({len(idx)},) or per "
                                  f"world and tool body ({len(idx)}, {B}); got shape {a.shape}")
            values.append(a)
        if np.any(values[1] < values[0]):
            raise ConfigError("mu_static must be >= mu (static friction at least the kinetic); got "
                              f"mu_static - mu down to {float((values[1] - values[0]).min()):.3g}")
        if not len(idx):
            return
        self._assign_rows(self.contact.mu, idx, values[0])
        self._assign_rows(self.contact.mu_s, idx, values[1])

    def tool_friction(self) -> tuple[np.ndarray, np.ndarray]:
        """(kinetic, static) Coulomb friction per world and tool body, (W, B) each."""
        return self.contact.mu.numpy().copy(), self.contact.mu_s.numpy().copy()

    @property
    def material_tets(self) -> int:
        """Tets of the template's material (the columns of :meth:`set_young_factors`' factors)."""
        sw = self._spring_weight_matrix
        return self.topology.n_tets if isinstance(sw, str) else int(sw.shape[1])

    def set_young_factors(self, factors, worlds=None) -> None:
        """Per-world, per-tet Young's modulus factors ``factors`` (W, T), or (len(worlds), T) for the
        worlds listed, relative to the template's
        material when the batch was built (domain randomisation, e.g. a stiffer inclusion): every
        spring constant, Maxwell branch constant and volume stiffness is linear in the Young's moduli
        of the tets around it (docs/models/mass_spring.md), so each world's are the template's scaled
        by the mean factor of the spring's tets weighted by E_t V_t (the tet's factor for the volume
        term). Needs a template whose materials differ in Young's modulus only (as the tasks build
        it); checked against the CPU model's own re-derivation in tests/test_batch_equivalence.py."""
        f = np.asarray(factors, dtype=np.float64)
        nt = self.material_tets         # with or without a volume term
        idx = np.arange(self.W) if worlds is None else np.asarray(worlds, dtype=np.int64).reshape(-1)
        if f.shape != (len(idx), nt) or not np.all(np.isfinite(f)) or np.any(f <= 0):
            raise ConfigError(f"factors must be positive finite ({len(idx)}, {nt}) per-tet Young's modulus factors, "
                              f"got shape {f.shape}")
        if not len(idx):
            return
        spring_w = self._spring_weights()
        edge = spring_w @ f.T            # (E, worlds): volume-weighted mean factor of each spring's tets
        base = self._base_fields
        for key in ("K1", "K2", "kM", "kMg"):
            self._assign_rows(getattr(self.fields, key), idx, (base[key][:, None] * edge).T)
        if self.topology.n_tets:
            self._assign_rows(self.fields.kv, idx, base["kv"][None, :] * f)

    def set_young_factor_array(self, factors, worlds) -> None:
        """:meth:`set_young_factors` with the factors already on the device: ``factors`` a float64
        Warp array (k, T) (e.g. written by a task's reset kernels), ``worlds`` an int32 Warp array
        (k,) of the worlds they belong to, both on this batch's device; no host copy. The caller
        keeps the factors positive and finite (they are not read back to check)."""
        wp = self._wp
        nt = self.material_tets
        ok = (isinstance(factors, wp.array) and factors.dtype == wp.float64 and factors.ndim == 2
              and factors.shape[1] == nt and isinstance(worlds, wp.array) and worlds.dtype == wp.int32
              and worlds.ndim == 1 and worlds.shape[0] == factors.shape[0])
        if not ok:
            raise ConfigError(f"factors must be a float64 Warp array (k, {nt}) and worlds an int32 Warp array (k,); got "
                              f"{type(factors).__name__} {getattr(factors, 'shape', None)} and {type(worlds).__name__} "
                              f"{getattr(worlds, 'shape', None)}; give numpy factors to set_young_factors instead")
        for a in (factors, worlds):
            if str(a.device) != str(wp.get_device(self.device)):
                raise ConfigError(f"factors and worlds must be on the batch's device {self.device}, got {a.device}")
        k = factors.shape[0]
        if not k:
            return
        csr = self._spring_weight_arrays()
        f = self.fields
        with wp.ScopedDevice(self.device):
            wp.launch(msk.scale_spring_constants, dim=(k, self.topology.n_springs),
                      inputs=[worlds, factors, *csr, f.K1, f.K2, f.kM, f.kMg])
            if self.topology.n_tets:
                wp.launch(msk.scale_volume_constants, dim=(k, self.topology.n_tets),
                          inputs=[worlds, factors, self._base_kv_array(), f.kv])

    def _spring_weight_arrays(self) -> tuple:
        """The spring weights (:meth:`_spring_weights`) as device CSR arrays (indptr, cols, weights)
        and the template's K1, K2, kM, kMg rows (4, E), built at first use."""
        if self._csr is None:
            wp = self._wp
            sw = self._spring_weights().tocsr()
            base = np.stack([self._base_fields[k] for k in ("K1", "K2", "kM", "kMg")])
            with wp.ScopedDevice(self.device):
                self._csr = (wp.array(sw.indptr.astype(np.int32), dtype=wp.int32),
                             wp.array(sw.indices.astype(np.int32), dtype=wp.int32),
                             wp.array(sw.data.astype(np.float64), dtype=wp.float64),
                             wp.array(np.ascontiguousarray(base), dtype=wp.float64))
        return self._csr

    def _base_kv_array(self):
        """The template's volume stiffness per tet (T,) on the device."""
        if self._kv_base is None:
            wp = self._wp
            with wp.ScopedDevice(self.device):
                self._kv_base = wp.array(np.ascontiguousarray(self._base_fields["kv"]), dtype=wp.float64)
        return self._kv_base

    def _assign_rows(self, arr, idx: np.ndarray, values: np.ndarray) -> None:
        """``arr[idx] = values`` on the device (all rows at once when idx is every world; else only
        the listed rows travel)."""
        wp = self._wp
        if len(idx) == self.W and np.array_equal(idx, np.arange(self.W)):
            arr.assign(np.ascontiguousarray(values))
            return
        with wp.ScopedDevice(self.device):
            src = wp.array(np.ascontiguousarray(values, dtype=np.float64), dtype=wp.float64)
            wp.launch(rsk.scatter_rows, dim=src.shape, inputs=[arr, wp.array(idx.astype(np.int32), dtype=wp.int32), src])

    def _spring_weights(self):
        """(E, T) sparse: row e holds the tets around spring e weighted by E_t V_t / their total
        (the template's Young's moduli and volumes when the batch was built)."""
        sw = self._spring_weight_matrix
        if isinstance(sw, str):
            raise ConfigError(sw)
        return sw

    def _build_spring_weights(self, tissue) -> None:
        """:meth:`_spring_weights` from the template tissue at build (or the reason it cannot be used)."""
        import scipy.sparse as sp

        fields = tissue.fields
        for name in ("poisson", "relax_fraction", "relax_time", "nonlinear", "density", "damping"):
            vals = np.asarray(fields[name])
            if vals.size and np.ptp(vals) > 1e-12 * np.abs(vals).max():
                self._spring_weight_matrix = (f"set_young_factors needs a template whose materials differ in Young's "
                                              f"modulus only; its field {name!r} varies (build it without region "
                                              "materials)")
                return
        tets = np.asarray(tissue.volume.tets, dtype=np.int64)
        weight = np.abs(np.asarray(tissue.volume.tet_volumes(), dtype=np.float64)) * np.asarray(fields["young"])
        n = tissue.n_nodes
        pairs = np.sort(np.stack([tets[:, [0, 0, 0, 1, 1, 2]].ravel(), tets[:, [1, 2, 3, 2, 3, 3]].ravel()], 1), 1)
        si, sj = np.asarray(tissue.si, np.int64), np.asarray(tissue.sj, np.int64)
        keys = np.minimum(si, sj) * n + np.maximum(si, sj)
        order = np.argsort(keys)
        edge = order[np.searchsorted(keys, pairs[:, 0] * n + pairs[:, 1], sorter=order)]
        tet = np.repeat(np.arange(len(tets)), 6)
        m = sp.csr_matrix((np.repeat(weight, 6), (edge, tet)), shape=(len(si), len(tets)))
        total = np.asarray(m.sum(axis=1)).ravel()
        self._spring_weight_matrix = sp.diags(1.0 / total) @ m

    def diverged_worlds(self) -> np.ndarray:
        """Indices of the worlds whose tissue became non-finite since their last reset."""
        return np.flatnonzero(self.tissue_state.diverged.numpy())

    def check_stable(self) -> None:
        """Raise :class:`~surgsim_envs.errors.TissueUnstableError` naming the diverged worlds, if any."""
        bad = self.diverged_worlds()
        if len(bad):
            from surgsim_envs.errors import TissueUnstableError

            raise TissueUnstableError(self._model_name, self.dt, self._critical_dt,
                                      f"non-finite node positions in {len(bad)} of {self.W} batched worlds "
                                      f"(first: {bad[:8].tolist()})")

    # ------------------------------------------------------------------------------------------
    # readouts (numpy copies; arrays() gives the device arrays)
    def tool_positions(self, name: str) -> np.ndarray:
        """(W, 3) m world position of tool ``name``'s origin (MuJoCo Warp's float32 ``xpos``)."""
        return self.tools.data.xpos.numpy()[:, self.tool_body[name]].astype(np.float64)

    def tool_forces(self, name: str) -> np.ndarray:
        """(W, 3) N contact force ON tool ``name`` (all its bodies) in the last physics step."""
        idx = self.tool_index[name]
        f = self.contact.tool_force.numpy()
        return f[:, idx[0]] + 0.0 if len(idx) == 1 else np.zeros((self.W, 3)) + f[:, idx].sum(axis=1)

    def tool_contact_report(self, name: str) -> dict[str, np.ndarray]:
        """Per world, tool ``name``'s contact report of the last tissue step, as
        :meth:`Simulation.tool_contact_report` (summed over its bodies in order): normal_force N
        (sum of normal magnitudes), tangential_force N (sum over its bodies of each body's summed
        friction force's magnitude), contacts and slipping (points; one count per body), penetration
        m (deepest). Each entry (W,)."""
        idx = self._tool_rows(name)
        c = self.contact
        fn, ft = c.tool_fn.numpy()[:, idx], c.tool_ft.numpy()[:, idx]
        nc, ns = c.tool_contacts.numpy()[:, idx], c.tool_slipping.numpy()[:, idx]
        pen = c.tool_depth.numpy()[:, idx]
        return {"normal_force": 0.0 + _row_sum(fn), "tangential_force": 0.0 + _row_sum(ft),
                "contacts": nc.sum(axis=1), "slipping": ns.sum(axis=1),
                "penetration": np.maximum(0.0, pen.max(axis=1, initial=0.0))}

    def geom_forces(self, geom_ids) -> tuple[np.ndarray, np.ndarray]:
        """(normal (W, k) N, tangential (W, k) N) per world of the tool geoms ``geom_ids`` (MuJoCo
        ids), as the CPU contact result's ``geom_normal_force`` / ``geom_tangential_force``: the sum
        of the normal magnitudes of each geom's contact points and the magnitude of their summed
        friction force, in the last tissue step (one thread per (world, geom): ``geom_sums``)."""
        rows = self.geom_columns(geom_ids)
        geom_fn, geom_ft = self.geom_sum_arrays()
        return geom_fn.numpy()[:, rows].copy(), geom_ft.numpy()[:, rows].copy()

    def geom_columns(self, geom_ids) -> list[int]:
        """The columns of the tool geoms ``geom_ids`` (MuJoCo ids) in the per-geom arrays of
        :meth:`geom_sum_arrays` (ConfigError for a geom that is not a tool contact geom)."""
        rows = []
        for g in np.asarray(geom_ids, dtype=np.int64).reshape(-1).tolist():
            if g not in self.geom_ids:
                raise ConfigError(f"geom {g} is not a tool contact geom of this batch; tool geoms: {self.geom_ids}")
            rows.append(self.geom_ids.index(g))
        return rows

    def geom_sum_arrays(self):
        """(normal (W, G), tangential (W, G)) float64 device arrays, N: every tool geom's sums of the
        last tissue step (``geom_sums``, computed now; columns :meth:`geom_columns`). The arrays are
        the batch's own, rewritten by the next call: copy what must be kept."""
        c, wp = self.contact, self._wp
        with wp.ScopedDevice(self.device):
            wp.launch(ck.geom_sums, dim=(self.W, len(self.geom_ids)),
                      inputs=[c.point_fn, c.point_ft, c.point_depth, c.geom_fn, c.geom_ft])
        return c.geom_fn, c.geom_ft

    def jaw_forces(self, name: str) -> dict[str, np.ndarray]:
        """Per world, the per-jaw contact forces of grasper ``name``, as :meth:`Simulation.jaw_forces`:
        {"normal": (W, 3) N, "tangential": (W, 3) N} (last tissue step)."""
        jaws = self._jaw_tool(name).jaw_geom_ids
        fn, ft = self.geom_forces(jaws)
        return {"normal": fn, "tangential": ft}

    def tool_displacements(self, name: str, origins, direction) -> np.ndarray:
        """(W,) m, per world tool ``name``'s displacement from ``origins`` ((W, 3) m) along the unit
        vector ``direction`` (3,) (e.g. a pulled wrist's travel since the grasp, as Slippage-v0's
        ``(pos - pos0) @ pull_dir``); from MuJoCo Warp's float32 ``xpos``."""
        o = np.asarray(origins, dtype=np.float64)
        u = np.asarray(direction, dtype=np.float64).reshape(-1)
        if o.shape != (self.W, 3) or not np.all(np.isfinite(o)):
            raise ConfigError(f"origins must be finite ({self.W}, 3) m, got shape {o.shape}")
        if u.shape != (3,) or not np.all(np.isfinite(u)) or abs(float(np.linalg.norm(u)) - 1.0) > 1e-9:
            raise ConfigError(f"direction must be a unit 3-vector, got {u.tolist()}; divide it by its norm")
        return (self.tool_positions(name) - o) @ u

    def controls(self, actuators) -> np.ndarray:
        """(W, A) the float64 controls of actuators ``actuators`` (A,) ids in every world: the
        schedule's or rate limiter's last value (a jaw's closing travel m, a force motor's N)."""
        ids = self._actuator_ids(actuators)
        return self.tools.ctrl64.numpy()[:, ids].copy()

    def actuator_forces(self, actuators) -> np.ndarray:
        """(W, A) N (or N m) the force each of actuators ``actuators`` applied in the last MuJoCo
        step (MuJoCo Warp's float32 ``actuator_force``; for a force motor of gain 1, its control
        clamped to its range: a pull's force), as ``MjData.actuator_force``."""
        ids = self._actuator_ids(actuators)
        return self.tools.data.actuator_force.numpy()[:, ids].astype(np.float64)

    def _actuator_ids(self, actuators) -> np.ndarray:
        ids = np.asarray(actuators, dtype=np.int64).reshape(-1)
        nu = self._mjm.nu
        if len(ids) == 0 or ids.min() < 0 or ids.max() >= nu:
            raise ConfigError(f"actuators must be ids in [0, {nu}), got {ids.tolist()}")
        return ids

    def jaw_openings(self, name: str) -> np.ndarray:
        """(W,) m, per world the distance from grasper ``name``'s axis to jaw 1's inner face (as
        :meth:`Simulation.jaw_opening`; from MuJoCo Warp's float32 ``qpos``)."""
        tool = self._jaw_tool(name)
        q = self.tools.data.qpos.numpy()[:, int(tool.jaw_qpos_adr[0])].astype(np.float64)
        return float(tool.config.open_radius) - q

    def contact_node_mask(self):
        """(W, N) int32 device array: 1 for the tissue nodes that felt a contact force in the last
        tissue step (|f|^2 > 0; the nodes a grasp's slip tracker starts from), else 0."""
        c, wp = self.contact, self._wp
        with wp.ScopedDevice(self.device):
            wp.launch(ck.contact_node_mask, dim=c.f_ext.shape, inputs=[c.f_ext, c.node_mask])
        return c.node_mask

    def contact_nodes(self, world: int) -> np.ndarray:
        """Indices of the tissue nodes of world ``world`` that felt a contact force in the last
        tissue step (``grasp.terms.contact_nodes`` of one world)."""
        return np.flatnonzero(self.contact_node_mask().numpy()[int(world)])

    def _tool_rows(self, name: str) -> list:
        if name not in self.tool_index:
            raise ConfigError(f"unknown tool {name!r}; tools in this scene: {sorted(self.tool_index)}")
        return self.tool_index[name]

    def _jaw_tool(self, name: str):
        self._tool_rows(name)
        tool = self.template.tools[name]
        if getattr(tool, "jaw_geom_ids", None) is None or not len(tool.jaw_geom_ids):
            raise ConfigError(f"tool {name!r} has no jaws (a {tool.kind}); jaw readouts need a grasper")
        return tool

    def tissue_positions(self) -> np.ndarray:
        """(W, N, 3) m tissue node positions."""
        return self.tissue_state.x.numpy().copy()

    def arrays(self) -> dict:
        """The device arrays by name (Warp arrays: ``__dlpack__`` / ``wp.to_torch`` share them)."""
        return {"tissue_positions": self.tissue_state.x, "tissue_velocities": self.tissue_state.v,
                "contact_forces": self.contact.f_ext, "tool_force": self.contact.tool_force,
                "tool_torque": self.contact.tool_torque, "tool_normal_force": self.contact.tool_fn,
                "tool_tangential_force": self.contact.tool_ft, "tool_contacts": self.contact.tool_contacts,
                "tool_slipping": self.contact.tool_slipping, "tool_friction": self.contact.mu,
                "xpos": self.tools.data.xpos, "qpos": self.tools.data.qpos}

    def memory_bytes(self) -> dict:
        """Bytes of the batched state on the device: tissue state, material fields, contact state,
        work buffers (MuJoCo Warp's own data not counted)."""
        fl = sum(getattr(self.fields, k).capacity for k in ("K1", "K2", "kM", "kMg", "kv"))
        return {"tissue_state": self.tissue_state.nbytes(), "material_fields": fl, "contact": self.contact.nbytes(),
                "work": self._f_spring.capacity + self._f_corner.capacity}
