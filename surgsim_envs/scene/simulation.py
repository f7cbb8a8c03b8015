"""The step loop that joins MuJoCo (rigid tools) to the tissue models and the contact model.

One physics step (DESIGN.md "One physics step"), in exactly this order:

1. controls / mocap: rate-limited actuator targets move towards their goals;
2. ``mujoco.mj_step1``: tool kinematics and velocities at time t (and rigid collisions);
3. ``contact.compute``: tool geoms at ``d.geom_xpos``/``d.geom_xmat`` against the tissue nodes at t;
4. ``tissue.step(dt, forces, stiffness)``: tissue to t + dt under the contact forces;
5. ``d.xfrc_applied[tool bodies] = reaction wrench`` (minus the forces on the tissue, torque
   about each body's centre of mass ``d.xipos``);
6. ``mujoco.mj_step2``: tools to t + dt with that reaction; then the written ``xfrc_applied``
   rows are zeroed again so nothing stale is applied by later MuJoCo calls.

Tools and tissue therefore see the same force over the same interval: action equals reaction
and total linear momentum is conserved when nothing else acts (tests/test_momentum.py).
No MuJoCo callbacks are used (never ``set_mjcb_passive``); tissue nodes are not MuJoCo dofs.

The order is written once in Python, :meth:`Simulation._reference_steps` (the reference loop; with
``tissue_subcycles`` n > 1 each MuJoCo step carries n tissue steps, n = 1 is the one-to-one loop
above). When the scene's tissue model has a compiled step (:mod:`surgsim_envs.scene.step.compiled`;
built in: MassSpringModel "symplectic" (the tasks' default) and "auto", CalibratedMassSpringModel
"symplectic", "auto" and "subcycled"), all substeps of a control step run instead in one numba call
(:mod:`surgsim_envs.scene.step.loop`), MuJoCo's C ``mj_step1``/``mj_step2`` included: it mirrors
the reference loop, bit for bit (tests/test_compiled_substeps.py);
``Simulation(..., compiled_substeps=False)`` forces the reference loop.
Units: m, s, kg, N, rad.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from surgsim_envs.contact import BOX, CAPSULE, CYLINDER, ROUNDED_BOX, SPHERE, ContactModel, ContactParams
from surgsim_envs.scene.contact_options import contact_law_for, contact_params_for, static_friction_ratio
from surgsim_envs import validate
from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.builder import Scene
from surgsim_envs.scene.step.buffers import StepBuffers
from surgsim_envs.scene.step.compiled import compiled_substeps_for, key_of
from surgsim_envs.scene.step import quasi_static
from surgsim_envs.scene.step.quasi_static import quasi_static_step
from surgsim_envs.scene.step.kernels import add_wrench, advance_geoms, gather_geoms, rate_limit, write_rows, zero_rows
from surgsim_envs.scene.config import validate_step

_KIND = {int(mujoco.mjtGeom.mjGEOM_SPHERE): SPHERE, int(mujoco.mjtGeom.mjGEOM_CAPSULE): CAPSULE,
         int(mujoco.mjtGeom.mjGEOM_BOX): BOX, int(mujoco.mjtGeom.mjGEOM_CYLINDER): CYLINDER}
_EQ = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)


def _seq_sum(values: list, rows: list):
    """``values[rows]`` summed in order from the first: numpy's sum of fewer than 8 entries (it sums
    8 and more pairwise), so the same bits."""
    total = values[rows[0]]
    for i in rows[1:]:
        total += values[i]
    return total


def _report_rows(r, rows: list) -> dict:
    """:meth:`Simulation.tool_contact_report` of one tissue's report ``r`` over 1-7 tool ``rows``, on
    Python numbers (the same numbers as the numpy sums and max there)."""
    pl = r.penetration.tolist()
    pen = [pl[i] for i in rows]
    top = max(pen) if all(v == v for v in pen) else math.nan     # numpy's max propagates NaN
    return {"normal_force": 0.0 + _seq_sum(r.normal_force.tolist(), rows),     # 0.0 + as the loop there
            "tangential_force": 0.0 + _seq_sum(r.tangential_force.tolist(), rows),
            "contacts": int(_seq_sum(r.contacts.tolist(), rows)), "slipping": int(_seq_sum(r.slipping.tolist(), rows)),
            "penetration": max(0.0, top)}


class Simulation:
    """Owns the MjModel/MjData, the tissue models and one ContactModel per tissue.

    scene: a built :class:`~surgsim_envs.scene.builder.Scene`.
    dt: physics step in s (default the scene config's, 1 ms), validated range
        :data:`~surgsim_envs.scene.config.DT_RANGE`; substeps: physics steps per :meth:`step`.
    seed: seeds :attr:`rng` (the physics itself is deterministic).
    compiled_substeps: run the substeps of a step in one compiled call when a loop is registered
        for the scene's (contact, tissue, integrator) (:mod:`surgsim_envs.scene.step.compiled`;
        same physics bit for bit); False, or no compiled step: the reference loop. The attribute
        :attr:`compiled_substeps` may be switched at any time.
    tissue_subcycles: n >= 1. With n > 1 MuJoCo steps the tools with ``n * dt`` while tissue and
        contact step ``n`` times with ``dt`` inside each MuJoCo step (:meth:`_reference_steps`):
        the tool geoms move along their velocity at the start of the MuJoCo step, and the tools get
        the time average of the ``n`` reactions, so the impulse they receive equals the impulse the
        tissue received (momentum conserved). Step counts stay in physics steps of ``dt`` and must
        be multiples of n. Default 1 (off): the documented one-to-one loop.

    Raises ConfigError if a tissue starts inside a tool (initial penetration).
    """

    def __init__(self, scene: Scene, *, dt: float | None = None, substeps: int | None = None, seed: int | None = None,
                 compiled_substeps: bool = True, tissue_subcycles: int = 1):
        if not isinstance(scene, Scene):
            raise ConfigError(f"Simulation needs a Scene from surgsim_envs.scene.build_scene(...), got {type(scene).__name__}")
        cfg = scene.config
        self.scene = scene
        self.dt = float(cfg.dt if dt is None else dt)
        self.substeps = cfg.substeps if substeps is None else substeps
        validate_step(self.dt, self.substeps)
        validate.integer(tissue_subcycles, "tissue_subcycles", lo=1, hi=100, fix="tissue steps per MuJoCo step")
        self.tissue_subcycles = int(tissue_subcycles)
        self.model = scene.model
        self.model.opt.timestep = self.dt * self.tissue_subcycles
        self.data = mujoco.MjData(self.model)
        # cached views of the MjData arrays the step loop touches (an attribute access builds a new view)
        self._views = {k: getattr(self.data, k) for k in ("geom_xpos", "geom_xmat", "cvel", "subtree_com", "xipos",
                                                          "ctrl", "xfrc_applied")}
        self.tissues = dict(scene.tissues)
        self.tools = dict(scene.tools)
        self.proxies = dict(scene.proxies)
        self.bindings = dict(scene.bindings)
        self.seed = int(cfg.seed if seed is None else seed)
        self.rng = np.random.default_rng(self.seed)
        self._setup_contact_arrays()
        v = self._views   # the arguments of gather_geoms, bound once (views and buffers never change)
        self._gather_args = (self._geom_ids, self._geom_body, self._geom_root, self._bodies, v["geom_xpos"],
                             v["geom_xmat"], v["cvel"], v["subtree_com"], v["xipos"], self._gpos, self._gmat,
                             self._gvel, self._tcom)
        self._setup_controls()
        #: the arrays the step loops work on (bound once; see StepBuffers)
        self.step_buffers = StepBuffers(self._gather_args, v["ctrl"], self._goal, self._rate, v["xfrc_applied"],
                                        self._bodies, self._wrench)
        self.contacts: dict[str, ContactModel] = {}
        params = ContactParams(stiffness=cfg.contact.stiffness, damping=cfg.contact.damping,
                               tangential_stiffness=cfg.contact.tangential_stiffness)
        ratio = static_friction_ratio(cfg.contact)
        for name, model in self.tissues.items():
            mat_mu = float(model.material.friction)
            mu = np.array([self._body_friction[b] if self._body_friction[b] is not None else mat_mu
                           for b in range(len(self._bodies))], dtype=np.float64)
            if len(mu) == 0:
                mu = np.zeros(1)
            self.contacts[name] = ContactModel(model.n_nodes, model.surface_nodes, mu,
                                               contact_params_for(params, cfg.contact, model),
                                               node_masses=model.masses, surface=model.surface,
                                               surface_subdivisions=self._surface_subdivisions(model),
                                               tool_static_friction=ratio * mu)
            self.contacts[name].set_contact_law(contact_law_for(cfg.contact, model, self.contacts[name].n_samples))
        self._pairs = [(self.tissues[n], self.contacts[n]) for n in self.tissues]
        for contact in self.contacts.values():   # validated once here; the step loop uses compute_prepared
            contact.prepare(self._shape_kind, self._shape_tool, self._shape_size, self.dt)
        self._has_tools = bool(len(self._geom_ids))
        self.compiled_substeps = bool(compiled_substeps)
        self._runner = None
        self._runner_key = None
        self._target_fast: dict = {}     # set_tool_target fast path: name -> (tool, first actuator, travel)
        self.steps = 0
        #: extra solves of quasi-static steps whose contact set moved (scene/step/quasi_static.py), since build
        self.contact_set_resolves = 0
        self.reset()
        self._check_initial_penetration()

    # ------------------------------------------------------------------------------------------
    # set-up
    def _setup_contact_arrays(self) -> None:
        m = self.model
        geoms, owner_tool = [], []
        for tool in self.tools.values():
            for gid in tool.geom_ids:
                geoms.append(int(gid))
                owner_tool.append(tool.name)
        bodies = sorted({int(m.geom_bodyid[g]) for g in geoms})
        self._bodies = np.array(bodies, dtype=np.int64)
        body_index = {b: i for i, b in enumerate(bodies)}
        self._geom_ids = np.array(geoms, dtype=np.int64)
        self._geom_body = np.array([m.geom_bodyid[g] for g in geoms], dtype=np.int64)
        self._geom_root = np.array([m.body_rootid[b] for b in self._geom_body], dtype=np.int64)
        self._shape_tool = np.array([body_index[int(b)] for b in self._geom_body], dtype=np.int64)
        kinds = []
        rounded = {int(g) for tool in self.tools.values() for g in tool.rounded_geom_ids}
        for g in geoms:
            t = int(m.geom_type[g])
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)
            if t not in _KIND:
                raise ConfigError(f"tool geom {name!r} has a type the "
                                  "contact model does not support; use sphere, capsule, box or cylinder")
            if g in rounded and _KIND[t] != BOX:
                raise ConfigError(f"tool geom {name!r} is declared rounded but is not a box; only box geoms round")
            kinds.append(ROUNDED_BOX if g in rounded else _KIND[t])
        self._shape_kind = np.array(kinds, dtype=np.int64)
        self._shape_size = np.ascontiguousarray(m.geom_size[self._geom_ids], dtype=np.float64).reshape(-1, 3)
        G, T = len(geoms), max(len(bodies), 1)
        self._gpos = np.zeros((G, 3))
        self._gmat = np.zeros((G, 9))
        self._gvel = np.zeros((G, 6))
        self._tcom = np.zeros((T, 3))
        self._wrench = np.zeros((len(bodies), 6))
        self._geom_index = {g: k for k, g in enumerate(geoms)}
        # which contact bodies belong to which tool; friction per body
        self._tool_bodies = {}
        self._body_friction: list[float | None] = [None] * len(bodies)
        for tool in self.tools.values():
            idx = sorted({body_index[int(m.geom_bodyid[g])] for g in tool.geom_ids})
            self._tool_bodies[tool.name] = np.array(idx, dtype=np.int64)
            for i in idx:
                self._body_friction[i] = tool.config.friction
        self._tool_geom_rows = {tool.name: np.array([self._geom_index[int(g)] for g in tool.geom_ids], dtype=np.int64)
                                for tool in self.tools.values()}

    def _surface_subdivisions(self, tissue) -> int:
        """Edge subdivisions of the embedded surface contact points for ``tissue`` from
        ``ContactConfig.surface_samples`` ("auto": ceil(median surface edge / smallest probe tip
        radius), i.e. samples only when a probe tip is smaller than the lattice spacing; 1 = nodes only)."""
        from surgsim_envs.contact.surface_points import MAX_SUBDIVISIONS, typical_edge_length

        opt = getattr(self.scene.config.contact, "surface_samples", "auto")
        if opt is None:
            return 1
        if opt == "auto":
            tips = [float(t.contact_feature_radius) for t in self.tools.values() if t.contact_feature_radius is not None]
            if not tips:
                return 1
            edge = typical_edge_length(tissue.positions, tissue.surface)
            return int(min(max(math.ceil(edge / min(tips) - 1e-9), 1), MAX_SUBDIVISIONS))
        if isinstance(opt, bool) or not isinstance(opt, (int, np.integer)) or not 1 <= opt <= MAX_SUBDIVISIONS:
            raise ConfigError(f"ContactConfig.surface_samples={opt!r}; use 'auto', None (nodes only) or an "
                              f"integer 1..{MAX_SUBDIVISIONS} of edge subdivisions per surface triangle")
        return int(opt)

    def _setup_controls(self) -> None:
        m = self.model
        self._goal = np.zeros(m.nu)
        self._rate = np.full(m.nu, np.inf)
        for tool in self.tools.values():
            for a, rate in tool.actuator_rates().items():
                self._rate[a] = rate
        self._moving = False

    def _check_initial_penetration(self) -> None:
        if not len(self._geom_ids):
            return
        d = self.data
        self._gather()
        for name, (tissue, contact) in zip(self.tissues, self._pairs):
            res = contact.compute(tissue.positions, tissue.velocities, self._shape_kind, self._shape_tool,
                                  self._shape_size, self._gpos, self._gmat, self._gvel, self._tcom, self.dt)
            pen = res.report.penetration.copy()
            contact.reset()
            if np.any(pen > 1e-9):
                b = int(np.argmax(pen))
                tool = next(t for t, idx in self._tool_bodies.items() if b in idx)
                raise ConfigError(f"tissue '{name}' starts inside tool '{tool}' (initial penetration "
                                  f"{pen[b] * 1e3:.2f} mm); move the tool away from the tissue (tool position "
                                  f"{d.xpos[self._bodies[b]].round(4).tolist()} m) or the tissue (TissueConfig.position)")

    # ------------------------------------------------------------------------------------------
    # state
    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    def reset(self, seed: int | None = None) -> None:
        """Back to the initial state: MuJoCo data, tool targets at home, tissues at rest, contacts cleared."""
        if seed is not None:
            self.seed = int(seed)
        self.rng = np.random.default_rng(self.seed)
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.ctrl[:] = 0.0
        self._goal[:] = 0.0
        self._moving = False
        for tissue in self.tissues.values():
            tissue.reset()
        for contact in self.contacts.values():
            contact.reset()
        self.steps = 0
        mujoco.mj_forward(m, d)

    # ------------------------------------------------------------------------------------------
    # stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` control steps of ``substeps`` physics steps each."""
        self._physics_steps(int(n) * self.substeps)

    def run(self, duration: float) -> None:
        """Advance by ``duration`` seconds (rounded to whole MuJoCo steps of ``tissue_subcycles``
        physics steps)."""
        validate.non_negative(duration, "duration", unit="s", fix="the simulated time to advance")
        n = self.tissue_subcycles
        self._physics_steps(int(round(duration / (self.dt * n))) * n)

    def _gather(self) -> None:
        gather_geoms(*self._gather_args)

    def physics_step(self, n: int = 1) -> None:
        """``n`` physics steps (default one) in the documented order (module docstring), in one
        compiled call where the scene has one: the same physics as ``n`` calls of one step."""
        if not (isinstance(n, (int, np.integer)) and n >= 0):     # once per step: the check inline
            validate.integer(n, "physics_step(n): n", lo=0, unit="steps", fix="give a whole number of steps")
        if n:
            self._physics_steps(int(n))

    def step_with_controls(self, actuators, values) -> None:
        """``len(values)`` MuJoCo steps (each ``tissue_subcycles`` physics steps); before the k-th,
        ``d.ctrl[actuators] = values[k]`` (then the rate limiter, as for any step). ``actuators``
        (A,) actuator ids, ``values`` (K, A) controls in the actuators' units: a control schedule
        computed ahead (e.g. a pull force as a function of time) runs in one compiled call instead
        of one :meth:`physics_step` per substep."""
        ids = np.ascontiguousarray(actuators, dtype=np.int64).reshape(-1)
        vals = np.ascontiguousarray(values, dtype=np.float64)
        if vals.ndim != 2 or vals.shape[1] != len(ids):
            raise ConfigError(f"values must have shape (steps, {len(ids)}) for {len(ids)} actuator(s), got {vals.shape}")
        if len(ids) and (ids.min() < 0 or ids.max() >= self.model.nu):
            raise ConfigError(f"actuator ids must lie in [0, {self.model.nu}), got {ids.tolist()}")
        if not np.all(np.isfinite(vals)):
            raise ConfigError("control values contain NaN/inf; give finite numbers")
        self._physics_steps(len(vals) * self.tissue_subcycles, ids, vals)

    @property
    def pairs(self) -> list:
        """[(tissue model, its ContactModel)] in scene order (the step loops' view of the scene)."""
        return self._pairs

    @property
    def has_tool_geoms(self) -> bool:
        """Whether the scene has tool geoms that touch tissue (else no contact runs)."""
        return self._has_tools

    @property
    def controls_moving(self) -> bool:
        """Whether an actuator target is still moving towards its goal (the rate limiter runs)."""
        return self._moving

    @controls_moving.setter
    def controls_moving(self, value: bool) -> None:
        self._moving = bool(value)

    def compiled_runner(self):
        """The compiled loop for the current scene state, or None (the reference loop)."""
        if not self.compiled_substeps:
            return None
        key = key_of(self)
        if key != self._runner_key:
            self._runner_key = key
            self._runner = compiled_substeps_for(self) if key is not None else None
        return self._runner

    def _physics_steps(self, count: int, ctrl_ids=None, ctrl_values=None) -> None:
        n = self.tissue_subcycles
        if count % n:
            raise ConfigError(f"with tissue_subcycles={n} the simulation advances in whole MuJoCo steps of {n} "
                              f"physics steps; {count} is not a multiple of {n} (choose substeps / durations "
                              f"that are)")
        runner = self.compiled_runner() if count > 0 else None
        if runner is not None:
            if ctrl_ids is None:
                runner.run(count)
            else:
                runner.run(count, ctrl_ids, ctrl_values)
            return
        self._reference_steps(count // n, ctrl_ids, ctrl_values)

    def _reference_steps(self, rigid_steps: int, ctrl_ids=None, ctrl_values=None) -> None:
        """``rigid_steps`` MuJoCo steps of ``n * dt`` (n = ``tissue_subcycles``), each with n tissue +
        contact steps of ``dt``, in the documented order (module docstring): the reference loop, the
        one place the physics order is written in Python (the compiled loop,
        :mod:`surgsim_envs.scene.step.loop`, mirrors it). n = 1 is the documented one-to-one loop;
        with n > 1 the tool geoms translate with their velocity at the start of the MuJoCo step
        (orientation and the torque reference point held) and the reaction written is the mean of the
        n reactions. ``ctrl_ids``/``ctrl_values``: before the k-th MuJoCo step
        ``ctrl[ctrl_ids] = ctrl_values[k]``.

        A handful of Python calls per step (measured: CHANGELOG.md "Env step: per-substep Python out of
        the physics loop"): every array is bound once outside the loop (cached MjData views, the contact
        buffers), the contact arguments were validated once in ``__init__`` (``ContactModel.prepare``)
        and the tissue takes them through ``step_prevalidated`` (NaN/inf still refused, guard still
        runs); the rate limiter, the reaction sum and write are numba kernels."""
        m, d, h, n = self.model, self.data, self.dt, self.tissue_subcycles
        big = h * n
        v = self._views
        ctrl, xfrc = v["ctrl"], v["xfrc_applied"]
        goal, rate = self._goal, self._rate
        step1, step2 = mujoco.mj_step1, mujoco.mj_step2
        gather_args = self._gather_args
        gpos, gmat, gvel, tcom = self._gpos, self._gmat, self._gvel, self._tcom
        bodies, w, pairs = self._bodies, self._wrench, self._pairs
        gpos0 = np.empty_like(gpos) if n > 1 else gpos
        tissues = list(self.tissues.values())
        has_tools = self._has_tools
        for k in range(rigid_steps):
            if ctrl_ids is not None:
                ctrl[ctrl_ids] = ctrl_values[k]
            if self._moving:
                self._moving = rate_limit(ctrl, goal, rate, big)
            step1(m, d)
            if not has_tools:
                for tissue in tissues:
                    for _ in range(n):
                        tissue.step(h)
                step2(m, d)
                self.steps += n
                continue
            gather_geoms(*gather_args)
            if n > 1:
                np.copyto(gpos0, gpos)
            w[:] = 0.0
            for j in range(n):
                if j:
                    advance_geoms(gpos, gpos0, gvel, j * h)
                for tissue, contact in pairs:
                    restore = tissue.resolves_contact_set and (quasi_static.RESTORE_FRICTION
                                                               or contact.solves_friction_cap
                                                               or contact.solves_plane_law)
                    friction = contact.friction_state() if restore else None
                    res = contact.compute_prepared(tissue.positions, tissue.velocities, gpos, gmat, gvel, tcom)
                    if tissue.resolves_contact_set:
                        self.contact_set_resolves += quasi_static_step(tissue, contact, h, res, gpos, gmat, gvel, tcom,
                                                                       friction)
                    else:
                        tissue.step_prevalidated(h, res.forces, res.stiffness)
                    # CONTRACT (tissue contract v2): an implicit integrator integrates forces + an increment
                    # from the contact stiffness; the tools must get the reaction of exactly
                    # tissue.integrated_external_forces or momentum leaks (11-14 % measured).
                    contact.attribute_increment_prepared(tissue.integrated_external_forces)
                    add_wrench(w, res.tool_force, res.tool_torque)
            if n > 1:
                w /= n
            write_rows(xfrc, bodies, w)
            step2(m, d)
            zero_rows(xfrc, bodies)
            self.steps += n

    # ------------------------------------------------------------------------------------------
    # tool commands
    def tool(self, name: str):
        """The ToolSpec of tool ``name`` (ConfigError listing the tools if unknown)."""
        try:
            return self.tools[name]
        except KeyError:
            raise ConfigError(f"unknown tool {name!r}; tools in this scene: {sorted(self.tools)}") from None

    def set_tool_target(self, name: str, position, speed: float | None = None, tilt=None) -> None:
        """Move tool ``name``'s origin (probe tip centre / grasper wrist) towards ``position`` (3,) m, world.

        speed: m/s rate limit (None = the tool config's ``speed``; inf = jump). tilt: (2,) rad about
        world x and y (probes built with ``orientation=True``). The grasper moves only along and
        across its axis within its slide ``travel``.
        """
        fast = self._target_fast.get(name) if tilt is None else None
        if fast is not None and type(position) is np.ndarray and position.dtype == np.float64 \
                and position.shape == (3,):
            # fast path of the checks below (same arithmetic, same result) for a position-driven tool
            # with consecutive actuators: finite (d.d finite; an overflow takes the checked path),
            # within reach, goal rows by slice
            tool, lo, travel = fast
            d = position - tool.home
            if math.isfinite(d.dot(d)):
                local = tool.frame.T @ d
                l0, l1, l2 = local.tolist()
                lim = travel + 1e-12
                if abs(l0) <= lim and abs(l1) <= lim and abs(l2) <= lim:
                    self._goal[lo:lo + 3] = local
                    if speed is not None:
                        if type(speed) is float and speed > 0:
                            self._rate[lo:lo + 3] = speed
                        else:
                            self._set_rate(tool.actuator_ids[:3], speed)
                    self._moving = True
                    return
        tool = self.tool(name)
        if tool.config.drive == "proxy":
            raise ConfigError(f"tool '{name}' is driven by a haptic proxy; move it with set_proxy_pose('{tool.proxy}', ...)")
        if tool.config.drive != "position":
            raise ConfigError(f"tool '{name}' has drive={tool.config.drive!r} and no actuators; build it with drive='position'")
        pos = np.asarray(position, dtype=float).reshape(-1)
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise ConfigError(f"tool target position must be 3 finite numbers (m), got {position!r}")
        local = tool.frame.T @ (pos - tool.home)
        travel = tool.config.travel
        if max(abs(v) for v in local.tolist()) > travel + 1e-12:
            raise ConfigError(f"target {pos.round(4).tolist()} m is outside tool '{name}''s reach of +-{travel} m "
                              f"about its home {tool.home.round(4).tolist()} m; raise its travel or choose a closer target")
        act = tool.actuator_ids[:3]
        self._goal[act] = local
        if speed is not None:
            self._set_rate(act, speed)
        if tilt is not None:
            if len(tool.actuator_ids) < 5:
                raise ConfigError(f"tool '{name}' has no orientation joints; build it with orientation=True")
            tilt = np.asarray(tilt, dtype=float).reshape(-1)
            if tilt.shape != (2,) or np.any(np.abs(tilt) > 1.0):
                raise ConfigError(f"tilt must be two angles in [-1, 1] rad, got {tilt.tolist()}")
            self._goal[tool.actuator_ids[3:5]] = tilt
        self._moving = True
        act = [int(i) for i in act]
        if name not in self._target_fast and act == list(range(act[0], act[0] + 3)):
            self._target_fast[name] = (tool, act[0], float(travel))

    def _set_rate(self, actuators, speed) -> None:
        if not (isinstance(speed, (int, float)) and speed > 0):
            raise ConfigError(f"speed must be a positive number (m/s), or math.inf for no limit, got {speed!r}")
        self._rate[actuators] = float(speed)

    def set_actuator_goal(self, actuator: int, goal: float, speed: float | None = None) -> None:
        """Move actuator ``actuator``'s target towards ``goal`` at ``speed`` (None = its default rate);
        the command primitive tool kinds build on (:mod:`surgsim_envs.scene.tools`)."""
        self._goal[actuator] = float(goal)
        if speed is not None:
            self._set_rate([actuator], speed)
        self._moving = True

    @property
    def shape_kinds(self) -> np.ndarray:
        """(G,) the contact shape code of every tool geom, in the order of the contact arrays
        (:mod:`surgsim_envs.contact.shapes`: a box a tool declares rounded is ROUNDED_BOX); a copy."""
        return self._shape_kind.copy()

    def geom_rows(self, geom_ids) -> list[int]:
        """Rows of the contact arrays (``ContactModel.result.geom_*``) of the tool geoms ``geom_ids``."""
        return [self._geom_index[int(g)] for g in geom_ids]

    def set_jaw_opening(self, name: str, radius: float, speed: float | None = None) -> None:
        """Close or open tool ``name``'s jaws to ``radius`` m (axis to each jaw's inner face) at ``speed`` m/s."""
        tool = self.tool(name)
        tool.require("set_jaw_opening")
        tool.set_jaw_opening(self, radius, speed)

    def jaw_opening(self, name: str) -> float:
        """Current distance (m) from the axis to jaw 1's inner face of tool ``name``."""
        tool = self.tool(name)
        tool.require("jaw_opening")
        return tool.jaw_opening(self)

    def _proxy_tool(self, name: str):
        if name in self.proxies:
            return self.proxies[name]
        tool = self.tools.get(name)
        if tool is not None and tool.proxy:
            return tool
        raise ConfigError(f"unknown haptic proxy {name!r}; proxies in this scene: {sorted(self.proxies)}")

    def set_proxy_pose(self, name: str, position, quat=None) -> None:
        """Place haptic proxy ``name`` (or the proxy of tool ``name``) at ``position`` (3,) m and ``quat`` (4,)."""
        tool = self._proxy_tool(name)
        pos = np.asarray(position, dtype=float).reshape(-1)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ConfigError(f"proxy position must be 3 finite numbers (m), got {position!r}")
        self.data.mocap_pos[tool.mocap_id] = pos
        if quat is not None:
            q = np.asarray(quat, dtype=float).reshape(-1)
            if q.shape != (4,) or not np.isfinite(q).all() or np.linalg.norm(q) < 1e-9:
                raise ConfigError(f"proxy quat must be 4 finite numbers (w, x, y, z), got {quat!r}")
            self.data.mocap_quat[tool.mocap_id] = q / np.linalg.norm(q)

    def coupling_force(self, name: str) -> np.ndarray:
        """(6,) [force N, torque N m] the weld (virtual coupling) exerts ON the tool, world frame."""
        tool = self._proxy_tool(name)
        d = self.data
        rows = np.flatnonzero((d.efc_type == _EQ) & (d.efc_id == tool.proxy_eq_id))
        out = np.zeros(6)
        out[:len(rows)] = d.efc_force[rows][:6]
        return out

    def proxy_force(self, name: str) -> np.ndarray:
        """(3,) N, the force the hand feels: the coupling force on the proxy (= minus that on the tool)."""
        return -self.coupling_force(name)[:3]

    # ------------------------------------------------------------------------------------------
    # readouts
    def tool_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,) m, quaternion (4,) w x y z) of the tool's main body (probe tip centre / wrist)."""
        tool = self.tool(name)
        return self.data.xpos[tool.body_id].copy(), self.data.xquat[tool.body_id].copy()

    def tool_position(self, name: str) -> np.ndarray:
        """(3,) m world position of the tool origin."""
        return self.data.xpos[self.tool(name).body_id].copy()

    def tool_force(self, name: str) -> np.ndarray:
        """(3,) N total contact force ON tool ``name`` from all tissues in the last physics step."""
        idx = self._tool_bodies[self.tool(name).name]
        if len(idx) == 1 and len(self._pairs) == 1:     # one body, one tissue: 0 + its row, as below
            return self._pairs[0][1].result.tool_force[idx[0]] + 0.0
        out = np.zeros(3)
        for contact in self.contacts.values():
            if len(idx) == 1:            # one body: its row (the sum over one row, without the reduction)
                out += contact.result.tool_force[idx[0]]
            else:
                out += contact.result.tool_force[idx].sum(axis=0)
        return out

    def contact_report(self) -> dict[str, dict[str, float]]:
        """Per tool, summed over its bodies and all tissues, for the last physics step:
        normal_force N (sum of normal magnitudes), tangential_force N (sum over the tool's bodies of
        the magnitude of each body's summed friction force), contacts (nodes), slipping (nodes),
        penetration m (max depth)."""
        return {name: self.tool_contact_report(name) for name in self.tools}

    def tool_contact_report(self, name: str) -> dict[str, float]:
        """:meth:`contact_report` of tool ``name`` only (the same numbers; what a task reads per step)."""
        idx = self._tool_bodies[self.tool(name).name]
        if 0 < len(idx) < 8 and len(self._pairs) == 1:
            return _report_rows(self._pairs[0][1].report, idx.tolist())
        fn = ft = 0.0
        nc = ns = 0
        pen = 0.0
        for contact in self.contacts.values() if len(idx) else ():
            r = contact.report
            fn += float(r.normal_force[idx].sum())
            ft += float(r.tangential_force[idx].sum())
            nc += int(r.contacts[idx].sum())
            ns += int(r.slipping[idx].sum())
            pen = max(pen, float(r.penetration[idx].max()))
        return {"normal_force": fn, "tangential_force": ft, "contacts": nc, "slipping": ns, "penetration": pen}

    def jaw_forces(self, name: str) -> dict[str, np.ndarray]:
        """Per-jaw contact forces of tool ``name``: {"normal": (3,) N, "tangential": (3,) N}."""
        tool = self.tool(name)
        tool.require("jaw_forces")
        return tool.jaw_forces(self)

    def tissue(self, name: str | None = None):
        """The TissueModel ``name`` (the only one if None)."""
        if name is None:
            if len(self.tissues) != 1:
                raise ConfigError(f"this scene has {len(self.tissues)} tissues; name one of {sorted(self.tissues)}")
            return next(iter(self.tissues.values()))
        try:
            return self.tissues[name]
        except KeyError:
            raise ConfigError(f"unknown tissue {name!r}; tissues in this scene: {sorted(self.tissues)}") from None

    def tissue_positions(self, name: str | None = None) -> np.ndarray:
        """(N,3) m copy of the node positions of tissue ``name``."""
        return self.tissue(name).positions.copy()

    def momentum(self) -> np.ndarray:
        """(3,) kg m/s total linear momentum of all MuJoCo bodies plus all tissue nodes (diagnostic)."""
        m, d = self.model, self.data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_subtreeVel(m, d)
        p = m.body_subtreemass[0] * d.subtree_linvel[0]
        for tissue in self.tissues.values():
            p = p + tissue.momentum()
        return p

    # ------------------------------------------------------------------------------------------
    @property
    def render_model(self) -> mujoco.MjModel:
        """The render MjModel: the physics model plus the tissue surface flexes (scene/visual.py);
        give it to ``mujoco.Renderer`` / ``mujoco.viewer``, never step it."""
        return self.scene.visual.model

    @property
    def render_data(self) -> mujoco.MjData:
        """The render MjData as of the last :meth:`sync_visual`."""
        return self.scene.visual.data

    def sync_visual(self) -> mujoco.MjData:
        """Copy the physics state into the render twin and write every tissue surface into its
        ``flexvert_xpos`` (call right before rendering); returns :attr:`render_data`."""
        return self.scene.visual.sync(self.model, self.data)
