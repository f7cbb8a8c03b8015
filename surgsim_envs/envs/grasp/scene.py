"""The grasp scene shared by the grasp tasks (Grasp-v0, Slippage-v0): config fields and env part.

:class:`GraspSceneConfig` holds what both tasks set the same way (timing, organ, tissue model
and resolution, jaw speed, friction and stiffness randomisation, rendering);
:class:`GraspSceneEnv` owns one Simulation per organ, the per-episode randomisation of friction
and stiffness (through ``model.scale_material``) and the grasper readings. Each task composes
its own observation terms, reward terms and termination from these and the term functions of
:mod:`surgsim_envs.envs.grasp.terms`; neither task inherits the other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import numpy as np

from surgsim_envs.envs.base import SurgSimEnv
from surgsim_envs import validate
from surgsim_envs.envs.checks import (check_contact_stiffness_per_area, check_control_rate, check_explicit_step,
                                     check_integrator, check_on_unstable, check_positive, check_range,
                                     check_render_size, check_task_resolution, require_capabilities, sample)
from surgsim_envs.envs.grasp.simulation import build_grasp_simulation, check_grasp_organ, organ_key
from surgsim_envs.envs.grasp.terms import SlipTracker
from surgsim_envs.errors import ConfigError
from surgsim_envs.materials import get_material


@dataclass
class GraspSceneConfig:
    """Settings every grasp task shares (SI units); ranges are (low, high) sampled per episode."""

    control_hz: float = 50.0
    dt: float = 4e-4                   # s; squeezed, strain-stiffened tissue needs < 0.5 ms
    tissue_subcycles: int | str = 1    # tissue + contact steps of dt per MuJoCo step (1: one each; see Simulation;
    #                                    "auto": resolved_subcycles)
    episode_seconds: float = 3.0
    organ: Any = "spleen"              # "spleen", "liver_lobe", a closed mesh file (STL/OBJ/PLY/VTK) or a Volume
    material: Any = "spleen"           # the organ's material: a preset name, a Material or a dict ({"preset": ..., field: value})
    model: str = "mass_spring"         # any registered tissue model with the "forces" capability
    integrator: str = "symplectic"     # if the model has it and it is stable over young_scale, else "auto"
    resolution: float | str | None = None   # None: the organ's task lattice; a spacing in m; "auto"
    error_tolerance: float = 0.1       # resolution="auto": force error limit (fraction)
    step_budget_us: float = 5_000.0    # resolution="auto": compute limit, us per simulated ms
    on_unstable: str = "raise"         # "terminate": a tissue divergence ends the episode (info["unstable"])
    closing_speed: float = 0.03        # m/s, jaw rate limit
    # N/m^3, jaw-tissue contact stiffness per unit surface area: "auto" = 1e8 for quasi-static tissue
    # models (their equilibrium solve takes it at any spacing), the scene's 200 N/m per node for the
    # others (what an explicit step keeps stable); None = always per node (ContactConfig.stiffness_per_area)
    contact_stiffness_per_area: Any = "auto"
    # the jaws' edges in the tissue contact: "sharp" (box jaws) or "round" (every edge rounded to half
    # the jaw thickness; GrasperConfig.jaw_edges, docs/contact.md); not batched
    jaw_edges: str = "sharp"
    mu: Sequence[float] = (0.6, 1.0)                 # tool-tissue Coulomb friction (kinetic)
    static_friction_ratio: float = 1.0  # static friction mu_s = ratio * mu (>= 1; 1 = one coefficient)
    young_scale: Sequence[float] = (0.8, 1.2)        # organ Young's modulus scale
    camera: str = "overview"
    render_width: int = 480
    render_height: int = 480

    def validate(self) -> None:
        what = type(self).__name__
        for key in ("control_hz", "dt", "episode_seconds", "closing_speed"):
            check_positive(getattr(self, key), f"{what}.{key}")
        validate.real(self.closing_speed, f"{what}.closing_speed", lo=1e-4, unit="m/s",
                      fix="the jaws' closing speed, at least 0.1 mm/s (the default is 0.03)")
        check_control_rate(self, what)
        check_task_resolution(self, what)
        check_on_unstable(self.on_unstable, what)
        check_contact_stiffness_per_area(self.contact_stiffness_per_area, f"{what}.contact_stiffness_per_area")
        if self.jaw_edges not in ("sharp", "round"):
            raise ConfigError(f"{what}.jaw_edges={validate.short_repr(self.jaw_edges)}; choose 'sharp' (box jaws, the "
                              "default) or 'round' (jaw edges rounded to half the jaw thickness in the tissue contact)")
        check_integrator(self, what)
        check_render_size(self, what)
        n = self.tissue_subcycles
        substeps = max(1, int(round(1.0 / self.control_hz / self.dt)))
        if n != "auto" and (isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100 or substeps % n):
            raise ConfigError(f"{what}.tissue_subcycles={n!r} must be an integer in [1, 100] that divides the "
                              f"{substeps} physics steps of a control step, or 'auto'")
        if n != "auto" and n > 1 and n * self.dt > MAX_SUBCYCLED_RIGID_DT * (1 + 1e-9):
            raise ConfigError(f"{what}.tissue_subcycles={n!r} makes the MuJoCo step {n} x dt = {n * self.dt:g} s, "
                              f"above {MAX_SUBCYCLED_RIGID_DT:g} s where the grasper's jaw servo goes unstable; use "
                              f"at most {max(1, int(MAX_SUBCYCLED_RIGID_DT / self.dt * (1 + 1e-9)))} or 'auto'")
        check_grasp_organ(self.organ, f"{what}.organ")
        try:
            get_material(self.material)
        except (ConfigError, TypeError, ValueError) as exc:
            raise ConfigError(f"{what}.material={validate.short_repr(self.material)}: {exc}") from None
        check_range(self.mu, "mu", 0.0, 2.0)
        from surgsim_envs.scene.contact_options import static_friction_ratio

        static_friction_ratio(self)
        check_range(self.young_scale, "young_scale", 0.5, 1.25)


#: s, the longest MuJoCo step the tasks' grasper takes with sub-cycling: its jaw servo (kp 20 kN/m on
#: 20 g jaws) is stable at 0.8 ms and unstable from 1.6 ms even without tissue (measured,
#: docs/benchmarks.md "Grasp-v0: why 0.4 ms, and tissue sub-cycles")
MAX_SUBCYCLED_RIGID_DT = 8e-4


def resolved_subcycles(config) -> int:
    """``config.tissue_subcycles`` as an integer: "auto" is 2 when 2 divides the physics steps of a
    control step and the MuJoCo step ``2 dt`` stays within :data:`MAX_SUBCYCLED_RIGID_DT`, else 1."""
    n = config.tissue_subcycles
    if n != "auto":
        return int(n)
    substeps = max(1, int(round(1.0 / config.control_hz / config.dt)))
    return 2 if substeps % 2 == 0 and 2 * config.dt <= MAX_SUBCYCLED_RIGID_DT * (1 + 1e-9) else 1


class GraspSceneEnv(SurgSimEnv):
    """The env part every grasp task shares (see the module docstring)."""

    TASK_ID: ClassVar[str] = ""
    REQUIRES: ClassVar[tuple[str, ...]] = ("forces", "unstructured_mesh")      # tissue capabilities the task needs
    tool_name = "grasper"

    def _build_scene(self) -> None:
        self._select(self.config.organ)
        self.slip = SlipTracker()

    def _on_new_simulation(self, sim) -> None:
        """Hook: a simulation for a new organ was just built (e.g. Slippage turns a drive into a motor)."""

    def _select(self, organ: str) -> None:
        check_grasp_organ(organ)
        key = organ_key(organ)
        if key not in self._sims:
            c = self.config
            require_capabilities(c.model, self.REQUIRES, self.TASK_ID)
            self._sims[key] = build_grasp_simulation(organ, c.dt, self.substeps, c.closing_speed, c.resolution,
                                                       c.error_tolerance, c.step_budget_us, model=c.model,
                                                       integrator=c.integrator, material=c.material,
                                                       max_young_scale=check_range(c.young_scale, "young_scale")[1],
                                                       tissue_subcycles=resolved_subcycles(c),
                                                       contact_stiffness_per_area=c.contact_stiffness_per_area,
                                                       jaw_edges=c.jaw_edges)
            self.sim = self._sims[key]
            self._select_tool()
            self._on_new_simulation(self.sim)
        self.sim = self._sims[key]
        self.organ = organ
        self._select_tool()

    def _select_tool(self) -> None:
        tool = self.sim.tool(self.tool_name)
        self.tool = tool
        self.home = tool.home.copy()
        self.frame = tool.frame
        self.gcfg = tool.config
        self.pull_dir = -np.asarray(self.gcfg.axis, dtype=float) / np.linalg.norm(self.gcfg.axis)

    def _reach(self) -> tuple[float, float, float]:
        """(low, high, span) m of the wrist's reachable world coordinates: home +- travel."""
        t = float(self.gcfg.travel) * np.sqrt(3.0)      # slides along the (rotated) wrist axes
        return float(self.home.min()) - t, float(self.home.max()) + t, 2.0 * t

    def _randomise_common(self, options: dict[str, Any]) -> None:
        c, rng = self.config, self.np_random
        self._select(options.get("organ", self.config.organ))
        mu = sample(rng, options.get("mu", c.mu), "mu", 0.0, 2.0)
        scale = sample(rng, options.get("young_scale", c.young_scale), "young_scale", 0.5, 1.25)
        self.sim.tissue().scale_material("young", scale)   # the contract's only way to change stiffness
        for contact in self.sim.contacts.values():
            contact.tool_friction[:] = mu
            contact.tool_static_friction[:] = c.static_friction_ratio * mu   # mu_s >= mu (validated)
        self.sim.reset(seed=int(rng.integers(2**31)))
        check_explicit_step(self.sim.tissue(), self.sim.dt, f"young_scale {scale:.2f}")
        self.mu, self.young_scale = mu, scale
        self.slip.reset()
        self.slip_distance = 0.0
        self.was_grasped = False

    def readings(self):
        """(wrist position (3,) m, per-jaw normal (3,) N, per-jaw tangential (3,) N, contact report),
        read once per physics state (the step's ``_update``, its terms and ``_observe`` share them; do not
        modify them)."""
        sim = self.sim
        key = (sim, sim.steps, self.steps)         # reset() and the unstable path clear the key
        if self._readings_key != key:
            jaws = sim.jaw_forces(self.tool_name)
            rep = sim.tool_contact_report(self.tool_name)
            self._readings_value = (sim.tool_position(self.tool_name), jaws["normal"], jaws["tangential"], rep)
            self._readings_key = key
        return self._readings_value

    def _metrics(self) -> dict[str, Any]:
        return {"organ": self.organ, "mu": self.mu, "mu_static": self.config.static_friction_ratio * self.mu,
                "young_scale": self.young_scale,
                "slip_distance_m": self.slip_distance, "success": False, "is_success": False, "dropped": False}
