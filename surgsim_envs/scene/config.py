"""Configuration dataclasses of a scene: tissues, tools, cameras and the step loop.

Everything is data (SI units: m, kg, s, N, rad) so that scenes can be loaded from TOML files and
compared. :func:`surgsim_envs.scene.config_check.validate_scene_config` checks a whole
:class:`SceneConfig` (this module holds the data and the field checks the tool kinds share).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError

#: allowed physics time step range (s); the tissue models' stable regions lie inside it
DT_RANGE = (1e-5, 5e-3)
#: allowed physics steps per control step
SUBSTEPS_RANGE = (1, 1000)


@dataclass
class TissueConfig:
    """One deformable organ.

    organ: a registered volume name ("slab", "block", "slab_inclusion", "spleen", "liver_lobe"),
        a mesh file path (closed surface STL/OBJ/PLY/OFF, filled with lattice tets; or a legacy
        VTK tet mesh; ``volume_options={"units": "mm"}`` if not in metres) or a
        :class:`~surgsim_envs.geometry.Volume` (:func:`surgsim_envs.geometry.organ_volume`).
        Meshes are set on their bed and rendered with their smooth surface.
    model: tissue model registry name ("mass_spring", "fem", or a plugin); "auto" lets
        ``resolution="auto"`` choose the model too.
    material: preset name, dict of :class:`~surgsim_envs.tissue.Material` fields, or a Material.
    spacing: node spacing (m) of the volumetric discretisation (None = the organ's default).
    resolution: None (use ``spacing``), a spacing in m (overrides ``spacing``) or "auto": the
        builder picks the cheapest measured (model, integrator, spacing) whose force error is <=
        ``error_tolerance`` (fraction) and whose compute is <= ``step_budget_us`` (us per
        simulated ms) from the accuracy table (:mod:`surgsim_envs.tissue.resolution`), restricted
        to ``model`` unless it is "auto" and to ``options["integrator"]`` if one is given (else
        the chosen integrator is set). No row meets both: ConfigError naming the closest.
    error_tolerance, step_budget_us: the two limits of ``resolution="auto"``.
    accuracy_scene: benchmark scene of the table rows to choose from ("indent").
    accuracy_table: path of a measured table JSON (None = the shipped one).
    anchors: fixed nodes (organ bed, ligaments): a list of selectors, each one of
        "bottom"/"top"/"x_min"/"x_max"/"y_min"/"y_max" (nodes within ``anchor_tolerance`` of that
        face of the bounding box, after placement) or an explicit sequence of node indices.
    anchor_tolerance: m, thickness of the face layer an anchor selector picks.
    position: (3,) m, where the centre of the volume's bounding box goes (bottom face at
        ``position[2] - height / 2``).
    euler: (3,) rad, XYZ Euler rotation applied about the box centre before translation.
    region_materials: {region label: material} for inclusions/layers.
    options: extra keyword options for the model constructor (integrator, ...).
    volume_options: extra keyword options for make_volume (size, ...).
    rgba: colour of the rendered surface.
    render_field: None (plain ``rgba``) or a per-node field of the model to colour the surface by
        (``model.field_names()``: "displacement" m, "stress" Pa, ...), viridis from low to high.
    render_range: (lo, hi) of that colour scale in the field's unit; None: 0 .. largest value seen.
    """

    name: str = "tissue"
    organ: Any = "slab"
    model: str = "mass_spring"
    material: Any = "liver"
    spacing: float | None = 0.005
    resolution: float | str | None = None
    error_tolerance: float = 0.1
    step_budget_us: float = 5_000.0
    accuracy_scene: str = "indent"
    accuracy_table: str | None = None
    anchors: Sequence[Any] = ("bottom",)
    anchor_tolerance: float = 1e-4
    position: Sequence[float] = (0.0, 0.0, 0.01)
    euler: Sequence[float] = (0.0, 0.0, 0.0)
    region_materials: Mapping[int, Any] | None = None
    gravity: Sequence[float] = (0.0, 0.0, 0.0)
    options: Mapping[str, Any] = field(default_factory=dict)
    volume_options: Mapping[str, Any] = field(default_factory=dict)
    rgba: Sequence[float] = (0.78, 0.33, 0.30, 1.0)
    render_field: str | None = None
    render_range: Sequence[float] | None = None


@dataclass
class ProbeConfig:
    """A rigid rod with a spherical tip (indenter).

    tip_radius: m, radius of the spherical tip (its centre is the body origin).
    rod_radius, rod_length: m, the capsule shaft above the tip along the probe axis.
    position: (3,) m, initial tip-centre position (the "home" pose).
    drive: "position" (slide joints + position actuators), "proxy" (driven through a
        :class:`HapticProxyConfig` weld by a mocap body; no actuators) or "free" (slide joints
        only, nothing drives it: for conservation tests and scripted initial velocities).
    orientation: add two hinge joints (tilt about world x and y, rad) with position actuators.
    kp: N/m, position actuator stiffness; damping ratio ``dampratio`` (critical = 1).
    speed: m/s, default rate limit of target changes (inf = jump).
    travel: m, half range of each slide joint about home.
    mass: kg, tool mass.
    friction: Coulomb coefficient tool-tissue (None = the tissue material's friction).
    """

    name: str = "probe"
    tip_radius: float = 0.005
    rod_radius: float = 0.003
    rod_length: float = 0.10
    position: Sequence[float] = (0.0, 0.0, 0.06)
    drive: str = "position"
    orientation: bool = False
    kp: float = 20_000.0
    dampratio: float = 1.0
    speed: float = math.inf
    travel: float = 0.2
    mass: float = 0.05
    friction: float | None = None
    rgba: Sequence[float] = (0.75, 0.75, 0.80, 1.0)


@dataclass
class GrasperConfig:
    """The three-jaw large-organ grasper of the grasping simulation paper.

    Three rigid box jaws at 120 degrees about the tool axis move in parallel and close radially.
    One slide joint (jaw 1) is actuated; jaws 2 and 3 follow through joint-coupling equalities.
    The wrist translates along and across the axis (three slide joints + position actuators).

    position: (3,) m, wrist origin (where the jaws start) at home.
    axis: (3,) unit direction the tool points (from handle towards the jaw tips), world frame.
    open_radius: m, distance from the axis to each jaw's inner face when fully open.
    min_radius: m, the closest the jaws may get to the axis.
    jaw_length, jaw_width, jaw_thickness: m, box jaw dimensions (along the axis, tangential,
        radial).
    roll: rad, angle of jaw 1 about the axis, measured from the wrist frame's x axis (for a
        horizontal axis pi/2 puts jaw 1 on top and the other two below at +-120 degrees).
    closing_speed: m/s, default rate of the jaw opening changes (the grasping simulation paper closes in 4 s).
    jaw_edges: "sharp" (default: the tissue meets the jaws as boxes) or "round": the tissue contact
        rounds every jaw edge to half the jaw's thickness (MuJoCo keeps the box); a sharp edge presses
        like a flat punch, whose force depends on how the lattice's contact points meet it
        (docs/contact.md).
    kp, jaw_kp: N/m, wrist and jaw position actuator stiffness.
    """

    name: str = "grasper"
    position: Sequence[float] = (0.1, 0.0, 0.05)
    axis: Sequence[float] = (-1.0, 0.0, 0.0)
    open_radius: float = 0.03
    min_radius: float = 0.004
    roll: float = math.pi / 2
    jaw_length: float = 0.04
    jaw_width: float = 0.012
    jaw_thickness: float = 0.003
    shaft_radius: float = 0.005
    shaft_length: float = 0.12
    drive: str = "position"
    closing_speed: float = 0.005
    jaw_edges: str = "sharp"
    speed: float = math.inf
    travel: float = 0.2
    kp: float = 20_000.0
    jaw_kp: float = 20_000.0
    dampratio: float = 1.0
    mass: float = 0.1
    jaw_mass: float = 0.02
    friction: float | None = None
    rgba: Sequence[float] = (0.6, 0.62, 0.68, 1.0)


@dataclass
class HapticProxyConfig:
    """A mocap body a device or script moves, coupled to a tool by a weld (virtual coupling).

    tool: name of the probe or grasper it drives (that tool must have ``drive="proxy"``).
    timeconst, dampratio: the weld's soft-constraint spring (``solref``): time constant s and
        damping ratio; a smaller time constant is a stiffer coupling.
    """

    name: str = "proxy"
    tool: str = "probe"
    timeconst: float = 0.01
    dampratio: float = 1.0


@dataclass
class CameraConfig:
    """A named fixed camera looking at ``target`` from ``position`` (m)."""

    name: str = "overview"
    position: Sequence[float] = (0.0, -0.30, 0.22)
    target: Sequence[float] = (0.0, 0.0, 0.01)
    fovy: float = 45.0


@dataclass
class ContactConfig:
    """Tool-tissue contact penalty parameters (see surgsim_envs.contact.ContactParams).

    stiffness: N/m per node (or "auto"); damping: N s/m per node; tangential_stiffness: N/m per
    node (None = stiffness).
    surface_samples: contact points embedded in the surface triangles between the nodes
    (surgsim_envs.contact.surface_points): "auto" = on when a probe tip radius is below the
    tissue's median surface edge (subdivisions ceil(edge / tip_radius), at most 8), an int n =
    edge subdivisions (1 = nodes only), None = nodes only. Each contact point then carries
    1/n^2 of the per-node stiffness and damping (same stiffness per surface area).
    stiffness_per_area: None (default: ``stiffness`` per node), a stiffness per unit surface area
        in N/m^3 (each node gets it x h^2, h the tissue's median surface edge) or "auto" (1e8 N/m^3
        for quasi-static tissue models, whose equilibrium solve takes any stiffness; ``stiffness``
        for the others); :mod:`surgsim_envs.scene.contact_options`.
    static_friction_ratio: mu_s / mu >= 1, the static friction coefficient of every tool as a
        multiple of its (kinetic) friction (1 = one coefficient; surgsim_envs.contact.friction).
        Tasks that draw mu per episode keep the ratio.
    law: how a quasi-static tissue step takes the contact (ContactModel.set_contact_law):
        "linearised" (the force at the step's start linearised with one isotropic stiffness per
        node), "plane" (each contact pair's penalty and Coulomb friction solved with the step on its
        tangent plane; tissue models with the capability ``plane_contact_law``, contact at the nodes
        only) or "auto" ("plane" where it applies, else "linearised");
        :mod:`surgsim_envs.scene.contact_options`.
    implicit_damping: "auto" (on for tissue models with the capabilities ``quasi_static``, whose
        velocities are finite differences, where explicit contact damping diverges, and
        ``implicit_contact``, whose solve takes the stiffness), True or
        False (ContactParams.implicit_damping: the damping enters the tissue's solve as c_n / dt).
    """

    stiffness: Any = 200.0
    damping: float = 0.02
    tangential_stiffness: float | None = None
    surface_samples: Any = "auto"
    stiffness_per_area: Any = None
    static_friction_ratio: float = 1.0
    implicit_damping: Any = "auto"
    law: Any = "linearised"


def _default_cameras() -> list[CameraConfig]:
    return [CameraConfig("overview", (0.0, -0.30, 0.22), (0.0, 0.0, 0.01)),
            CameraConfig("top", (0.0, -0.001, 0.35), (0.0, 0.0, 0.0)),
            CameraConfig("side", (0.35, 0.0, 0.06), (0.0, 0.0, 0.02))]


@dataclass
class SceneConfig:
    """A whole scene: tissues, tools, haptic proxies, cameras and the step loop.

    tools: a list of tool configs of any registered kind (:class:`ProbeConfig`,
    :class:`GrasperConfig`, or a plugin's; :mod:`surgsim_envs.scene.tools`), built in order.
    dt: s, physics step (validated against :data:`DT_RANGE`); substeps: physics steps per
    control step (:meth:`Simulation.step`). gravity: m/s^2 for the MuJoCo (tool) world; tools are
    gravity-compensated. seed: seeds ``Simulation.rng``. rigid_contacts: False turns MuJoCo's
    collision detection off (``mjDSBL_CONTACT``) for a scene whose tools can never touch a rigid geom
    (the floor, each other); the tissue contact is ours and is unaffected. It saves ~1.6 us per physics
    step (~4 % of a Palpation-v0 env step); with it off a tool would pass through the floor.
    """

    name: str = "scene"
    tissues: list[TissueConfig] = field(default_factory=list)
    tools: list[Any] = field(default_factory=list)
    proxies: list[HapticProxyConfig] = field(default_factory=list)
    cameras: list[CameraConfig] = field(default_factory=_default_cameras)
    contact: ContactConfig = field(default_factory=ContactConfig)
    dt: float = 1e-3
    substeps: int = 1
    gravity: Sequence[float] = (0.0, 0.0, -9.81)
    floor: bool = True
    rigid_contacts: bool = True
    seed: int = 0
    render_width: int = 640
    render_height: int = 480

    def tool(self, name: str):
        """The tool config called ``name`` (ConfigError listing the tools if there is none)."""
        for t in self.tools:
            if t.name == name:
                return t
        raise ConfigError(f"scene '{self.name}' has no tool {name!r}; tools: {[t.name for t in self.tools]}")

    def replace_tool(self, name: str, new) -> None:
        """Put tool config ``new`` in the place of the tool called ``name``."""
        for i, t in enumerate(self.tools):
            if t.name == name:
                self.tools[i] = new
                return
        raise ConfigError(f"scene '{self.name}' has no tool {name!r}")


# ----------------------------------------------------------------------------------------------
def vec(value, n: int, what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except TypeError:
        raise ConfigError(f"{what} must be a sequence of {n} numbers, got {value!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ConfigError(f"{what} must be {n} finite numbers, got {value!r}")
    return out


def rate_limit(value, name: str) -> float:
    """A tool's default rate limit of target changes in m/s: > 0, or inf for none."""
    if validate.is_real_number(value) and value == math.inf:
        return math.inf
    return validate.positive(value, name, unit="m/s", fix="give a speed in m/s, or inf for no limit")



def validate_step(dt: float, substeps: int) -> None:
    """Raise ConfigError unless dt (s) and substeps lie in their allowed ranges."""
    lo, hi = DT_RANGE
    if not isinstance(dt, (int, float)) or not math.isfinite(dt) or not (lo <= dt <= hi):
        raise ConfigError(f"dt={dt!r} s is out of range [{lo:g}, {hi:g}] s; the default is 1e-3 s (1 ms)")
    slo, shi = SUBSTEPS_RANGE
    if isinstance(substeps, bool) or not isinstance(substeps, int) or not (slo <= substeps <= shi):
        raise ConfigError(f"substeps={substeps!r} is out of range: give an integer in [{slo}, {shi}] "
                          "(physics steps per control step; default 1)")
