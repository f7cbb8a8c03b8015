"""Scene composition in code: tissue + anchors + tools + cameras + lights + floor.

:func:`build_scene` turns a :class:`SceneConfig` into a :class:`Scene` (compiled MuJoCo model,
tissue models, tool records). One function per ready-made scene returns its default config or
builds it: :func:`palpation_scene` (probe over a slab with a stiff inclusion),
:func:`grasp_scene` (three-jaw grasper around the tip of a spleen anchored at its hilum end),
:func:`demo_scene` (both tools, both organs). ``make_scene(name)`` looks scenes up by name.

>>> from surgsim_envs.scene import palpation_scene, Simulation
>>> sim = Simulation(palpation_scene())          # doctest: +SKIP
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Callable

import mujoco
import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.config import CameraConfig, GrasperConfig, ProbeConfig, SceneConfig, TissueConfig
from surgsim_envs.scene.config_check import validate_scene_config
from surgsim_envs.scene.tissue_binding import TissueBinding
from surgsim_envs.scene.visual import VisualTwin
from surgsim_envs.scene.tools import ToolSpec, add_haptic_proxy, build_tool

ANCHOR_FACES = {"bottom": (2, 0), "top": (2, 1), "x_min": (0, 0), "x_max": (0, 1), "y_min": (1, 0), "y_max": (1, 1)}


@dataclass
class Scene:
    """A built scene: the MuJoCo spec/model, tissue models and tool records (by name)."""

    config: SceneConfig
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    tissues: dict = field(default_factory=dict)         # name -> TissueModel
    bindings: dict = field(default_factory=dict)        # name -> TissueBinding
    tissue_configs: dict = field(default_factory=dict)  # name -> TissueConfig
    tools: dict = field(default_factory=dict)           # name -> ToolSpec
    proxies: dict = field(default_factory=dict)         # proxy name -> ToolSpec it drives
    resolutions: dict = field(default_factory=dict)     # tissue name -> tissue.resolution.Choice ("auto" only)
    visual: VisualTwin | None = None                    # render-only twin with the tissue flexes


# ----------------------------------------------------------------------------------------------
# Tissue placement and anchors
def _euler_matrix(euler) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_euler2Quat(q, np.asarray(euler, dtype=float), "XYZ")
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, q)
    return mat.reshape(3, 3)


def resolve_tissue(cfg: TissueConfig):
    """``(resolved copy of cfg, Choice or None)``: ``cfg.resolution`` turned into a concrete model,
    spacing and integrator (see :class:`TissueConfig`); ``cfg`` itself is returned when
    ``resolution`` is None. The copy has ``resolution=None``, so resolving twice changes nothing.

    ``"auto"`` uses :func:`surgsim_envs.tissue.resolution.choose` (the tissue layer, not bench:
    bench sits above scene); a ConfigError from it is re-raised naming the tissue.
    """
    from surgsim_envs.tissue.resolution import check_resolution, choose

    check_resolution(cfg.resolution, f"tissue '{cfg.name}' resolution")
    if cfg.resolution is None:
        return cfg, None
    out = copy.deepcopy(cfg)
    out.resolution = None
    if cfg.resolution != "auto":
        out.spacing = float(cfg.resolution)
        return out, None
    options = dict(cfg.options)
    integrator = options.get("integrator")
    fixed_integrator = integrator not in (None, "auto")
    try:
        pick = choose(cfg.error_tolerance, cfg.step_budget_us, cfg.accuracy_scene, table=cfg.accuracy_table,
                      models=None if cfg.model == "auto" else [cfg.model],
                      integrators=[integrator] if fixed_integrator else None)
    except ConfigError as exc:
        raise ConfigError(f"tissue '{cfg.name}' resolution='auto': {exc}") from None
    out.model, out.spacing = pick.model, pick.spacing
    if not fixed_integrator:
        options["integrator"] = pick.integrator
    out.options = options
    return out, pick


def resolve_scene_config(cfg: SceneConfig):
    """``(copy of cfg with every tissue resolved, {tissue name: Choice})`` (see :func:`resolve_tissue`)."""
    out = copy.deepcopy(cfg)
    choices = {}
    for i, t in enumerate(cfg.tissues):
        out.tissues[i], pick = resolve_tissue(t)
        if pick is not None:
            choices[t.name] = pick
    return out, choices


def placed_volume(cfg: TissueConfig):
    """The tissue's volume, rotated by ``cfg.euler`` and with its bounding-box centre at ``cfg.position``."""
    from surgsim_envs.geometry import Volume, organ_volume

    cfg, _ = resolve_tissue(cfg)
    # a registered name, a mesh file (STL/OBJ/PLY/VTK, set on its bed) or a Volume (contract v2)
    vol = organ_volume(cfg.organ, spacing=cfg.spacing, **dict(cfg.volume_options))
    lo, hi = vol.bounds()
    centre = (lo + hi) / 2.0
    nodes = vol.nodes - centre
    rot, shift = np.eye(3), np.zeros(3)
    if any(float(a) != 0.0 for a in cfg.euler):
        rot = _euler_matrix(cfg.euler)
        nodes = nodes @ rot.T
        lo2, hi2 = nodes.min(axis=0), nodes.max(axis=0)
        shift = (lo2 + hi2) / 2.0
        nodes = nodes - shift
    nodes = nodes + np.asarray(cfg.position, dtype=float)
    if hasattr(vol, "with_nodes"):  # volumes carrying more structure (layered lattices) keep it
        if any(float(a) != 0.0 for a in cfg.euler):
            raise ConfigError(f"tissue '{cfg.name}': a layered volume cannot be rotated (its neighbouring bounding "
                              "boxes are axis-aligned); use euler=(0, 0, 0)")
        out = vol.with_nodes(nodes)
    else:
        out = Volume(nodes, vol.tets.copy(), vol.surface.copy(), vol.labels.copy(), vol.name, vol.node_labels.copy())
        index = getattr(vol, "lattice_index", None)
        if index is not None and not any(float(a) != 0.0 for a in cfg.euler):   # lattice axes = world axes
            out.lattice_index = index
    src = getattr(vol, "source_surface", None)
    if src is not None:  # the smooth organ surface, placed like the nodes (rendered by TissueBinding)
        out.source_surface = ((src[0] - centre) @ rot.T - shift + np.asarray(cfg.position, dtype=float), src[1].copy())
    return out


def anchor_nodes(nodes: np.ndarray, anchors, tolerance: float, what: str = "tissue") -> np.ndarray:
    """Indices of anchored (fixed) nodes from selectors (see :class:`TissueConfig`).

    A selector is a face name ("bottom", "top", "x_min", "x_max", "y_min", "y_max"), optionally
    with a layer thickness in m after a colon ("x_min:0.03"), or a sequence of node indices.
    """
    n = len(nodes)
    lo, hi = nodes.min(axis=0), nodes.max(axis=0)
    picked = np.zeros(n, dtype=bool)
    for sel in anchors or ():
        if isinstance(sel, str):
            face, _, thick = sel.partition(":")
            if face not in ANCHOR_FACES:
                raise ConfigError(f"{what}: unknown anchor {sel!r}; use one of {sorted(ANCHOR_FACES)} "
                                  "(optionally 'face:thickness_m', e.g. 'x_min:0.03') or a list of node indices")
            try:
                tol = float(thick) if thick else tolerance
            except ValueError:
                raise ConfigError(f"{what}: anchor {sel!r} has a bad thickness; write e.g. 'x_min:0.03' (m)") from None
            axis, side = ANCHOR_FACES[face]
            if side == 0:
                picked |= nodes[:, axis] <= lo[axis] + tol
            else:
                picked |= nodes[:, axis] >= hi[axis] - tol
        else:
            idx = np.asarray(sel, dtype=np.int64).reshape(-1)
            if len(idx) and (idx.min() < 0 or idx.max() >= n):
                raise ConfigError(f"{what}: anchor node indices must lie in [0, {n}), got [{idx.min()}, {idx.max()}]")
            picked[idx] = True
    return np.flatnonzero(picked)


def build_tissue(cfg: TissueConfig):
    """Build the TissueModel of ``cfg`` (placed, anchored)."""
    from surgsim_envs import tissue

    cfg, _ = resolve_tissue(cfg)
    vol = placed_volume(cfg)
    fixed = anchor_nodes(vol.nodes, cfg.anchors, cfg.anchor_tolerance, what=f"tissue '{cfg.name}'")
    options = dict(cfg.options)
    if cfg.region_materials:
        labels = set(np.unique(vol.labels).tolist())
        options["region_materials"] = {k: v for k, v in dict(cfg.region_materials).items() if int(k) in labels}
    return tissue.make(cfg.model, vol, cfg.material, fixed=fixed if len(fixed) else None,
                       gravity=tuple(cfg.gravity), **options)


# ----------------------------------------------------------------------------------------------
def _add_environment(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    spec.option.timestep = float(cfg.dt)
    spec.option.gravity = [float(g) for g in cfg.gravity]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    if not cfg.rigid_contacts:
        spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    spec.visual.global_.offwidth = max(int(cfg.render_width), 640)
    spec.visual.global_.offheight = max(int(cfg.render_height), 480)
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    wb = spec.worldbody
    wb.add_light(name="key", pos=[0.3, -0.3, 0.8], dir=[-0.3, 0.3, -0.8], diffuse=[0.7, 0.7, 0.7], castshadow=True)
    wb.add_light(name="fill", pos=[-0.3, 0.2, 0.6], dir=[0.3, -0.2, -0.6], diffuse=[0.3, 0.3, 0.3], castshadow=False)
    # a soft gradient sky, so views above the horizon are not black
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     rgb1=[0.55, 0.62, 0.70], rgb2=[0.12, 0.14, 0.17], width=256, height=256)
    if cfg.floor:
        tex = spec.add_texture(name="floor_tex", type=mujoco.mjtTexture.mjTEXTURE_2D,
                               builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.32, 0.36, 0.40],
                               rgb2=[0.26, 0.29, 0.32], width=256, height=256)
        mat = spec.add_material(name="floor_mat", texrepeat=[8, 8], reflectance=0.0)
        mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
        wb.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.5, 0.5, 0.01], material="floor_mat",
                    contype=1, conaffinity=1)
    for cam in cfg.cameras:
        _add_camera(spec, cam)


def _add_camera(spec: mujoco.MjSpec, cam: CameraConfig) -> None:
    pos = np.asarray(cam.position, dtype=float)
    fwd = np.asarray(cam.target, dtype=float) - pos
    if np.linalg.norm(fwd) < 1e-9:
        raise ConfigError(f"camera '{cam.name}': position and target coincide ({cam.position})")
    fwd /= np.linalg.norm(fwd)
    up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.99 else np.array([0.0, 1.0, 0.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, fwd)
    # MuJoCo cameras look along their local -z with +y up: xyaxes = (right, up)
    spec.worldbody.add_camera(name=cam.name, pos=pos.tolist(), xyaxes=[*right.tolist(), *cam_up.tolist()],
                              fovy=float(cam.fovy))


def build_scene(cfg: SceneConfig) -> Scene:
    """Compile ``cfg`` into a :class:`Scene` (validates it first; ConfigError on bad input).

    Tissue ``resolution`` settings are resolved first (:func:`resolve_scene_config`):
    ``scene.config`` holds the resolved copy and ``scene.resolutions`` the table rows chosen for
    ``resolution="auto"``.
    """
    validate_scene_config(cfg)
    cfg, choices = resolve_scene_config(cfg)
    spec = mujoco.MjSpec()
    spec.modelname = cfg.name
    _add_environment(spec, cfg)
    scene = Scene(config=cfg, spec=spec, model=None, resolutions=choices)  # type: ignore[arg-type]
    for tcfg in cfg.tissues:
        model = build_tissue(tcfg)
        scene.tissues[tcfg.name] = model
        scene.tissue_configs[tcfg.name] = tcfg
        # the surface flex goes only into the render twin (scene/visual.py): never into the physics model
        scene.bindings[tcfg.name] = TissueBinding(tcfg.name, model, rgba=tcfg.rgba, render_field=tcfg.render_field,
                                                  render_range=tcfg.render_range)
    for tcfg in cfg.tools:
        scene.tools[tcfg.name] = build_tool(spec, tcfg)
    for hcfg in cfg.proxies:
        tool = scene.tools[hcfg.tool]
        add_haptic_proxy(spec, hcfg, tool)
        scene.proxies[hcfg.name] = tool
    try:
        scene.model = spec.compile()
    except Exception as exc:  # MuJoCo compiler errors are ValueError subclasses with the XML-ish message
        raise ConfigError(f"scene '{cfg.name}' does not compile in MuJoCo: {exc}") from exc
    for tool in scene.tools.values():
        tool.bind(scene.model)
    check_tools_clear(scene)
    scene.visual = VisualTwin(spec, scene.bindings)
    return scene


def check_tools_clear(scene: Scene) -> None:
    """Raise ConfigError if a tool starts touching rigid geometry (floor) at its home pose: a tool
    pressed into the floor at rest pushes back on its drive (and on a haptic user's hand)."""
    m = scene.model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    tool_bodies = {}
    for tool in scene.tools.values():
        for b in range(m.nbody):
            root = b
            while root and m.body_parentid[root] != 0:
                root = m.body_parentid[root]
            if root == tool.body_id:
                tool_bodies[b] = tool.name
    for c in d.contact[:d.ncon]:
        for g, other in ((c.geom1, c.geom2), (c.geom2, c.geom1)):
            name = tool_bodies.get(int(m.geom_bodyid[g]))
            if name is not None and c.dist < 0:
                gname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, int(g))
                oname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, int(other))
                raise ConfigError(f"tool '{name}' starts inside {oname!r}: geom {gname!r} penetrates it by "
                                  f"{-c.dist * 1e3:.2f} mm at the home pose; move the tool (or the tissue it is "
                                  "placed around) up, or make its jaws/tip smaller")


# ----------------------------------------------------------------------------------------------
# Ready-made scenes
def palpation_config(organ: str = "slab_inclusion", model: str = "mass_spring") -> SceneConfig:
    """A probe above the middle of a 10 x 10 x 2 cm liver slab with a stiff inclusion, bed fixed."""
    # coloured by displacement (0-4 mm, viridis): the press shows as a colour change, not only a dent
    tissue = TissueConfig(name="slab", organ=organ, model=model, material="liver", spacing=0.005,
                          anchors=("bottom",), position=(0.0, 0.0, 0.01), render_field="displacement",
                          render_range=(0.0, 0.004),
                          region_materials={1: {"preset": "liver", "young": 20_000.0, "name": "tumour"}},
                          options={"integrator": "symplectic"})
    probe = ProbeConfig(name="probe", tip_radius=0.008, position=(0.0, 0.0, 0.031))
    cams = [CameraConfig("overview", (0.0, -0.17, 0.13), (0.0, 0.0, 0.01)),
            CameraConfig("top", (0.0, -0.001, 0.25), (0.0, 0.0, 0.0)),
            CameraConfig("side", (0.0, -0.16, 0.03), (0.0, 0.0, 0.015))]
    # explicit tissue + explicit penalty contact: 0.5 ms keeps k_n dt^2 / m well below the limit
    return SceneConfig(name="palpation", tissues=[tissue], tools=[probe], cameras=cams, dt=5e-4)


def palpation_scene(cfg: SceneConfig | None = None) -> Scene:
    """Build the palpation scene (``cfg`` defaults to :func:`palpation_config`)."""
    return build_scene(cfg if cfg is not None else palpation_config())


def place_grasper_around_tip(tissue_nodes: np.ndarray, grasper: GrasperConfig, margin: float = 0.004,
                             reach: float = 0.8) -> GrasperConfig:
    """Copy of ``grasper`` placed so its open jaws surround the +x tip of ``tissue_nodes``.

    The axis points along -x into the organ; the jaws cover the last ``reach * jaw_length`` of
    the organ; ``open_radius`` is the largest distance of those nodes from the axis plus ``margin``.
    """
    g = copy.deepcopy(grasper)
    xmax = tissue_nodes[:, 0].max()
    depth = reach * g.jaw_length
    tip = tissue_nodes[tissue_nodes[:, 0] >= xmax - depth]
    cy, cz = (tip[:, 1].min() + tip[:, 1].max()) / 2.0, (tip[:, 2].min() + tip[:, 2].max()) / 2.0
    radius = float(np.sqrt((tip[:, 1] - cy) ** 2 + (tip[:, 2] - cz) ** 2).max())
    g.axis = (-1.0, 0.0, 0.0)
    g.open_radius = radius + margin
    # the jaw tips end ``depth`` into the organ; the wrist origin sits at the start of the jaws
    g.position = (float(xmax - depth + g.jaw_length), float(cy), float(cz))
    return g


def grasp_config(organ: str = "spleen", model: str = "mass_spring") -> SceneConfig:
    """Three-jaw grasper (the grasping simulation paper) around the tip of a spleen held at its other end (ligaments)."""
    # grasp_scene lifts organ and grasper together if the open jaws would reach into the floor
    tissue = TissueConfig(name="spleen", organ=organ, model=model, material="spleen", spacing=None,
                          anchors=("x_min:0.03",), position=(0.0, 0.0, 0.025),
                          options={"integrator": "implicit"}, rgba=(0.55, 0.18, 0.25, 1.0))
    cams = [CameraConfig("overview", (0.05, -0.22, 0.16), (0.03, 0.0, 0.02)),
            CameraConfig("top", (0.03, -0.001, 0.30), (0.03, 0.0, 0.0)),
            CameraConfig("side", (0.03, -0.25, 0.03), (0.03, 0.0, 0.025))]
    return SceneConfig(name="grasp", tissues=[tissue], tools=[GrasperConfig(name="grasper")], cameras=cams)


def grasp_scene(cfg: SceneConfig | None = None, auto_place: bool = True) -> Scene:
    """Build the grasp scene (``cfg`` defaults to :func:`grasp_config`).

    With ``auto_place`` the first grasper is placed around the +x tip of the first tissue
    (:func:`place_grasper_around_tip`), so any organ can be grasped.
    """
    cfg = copy.deepcopy(cfg if cfg is not None else grasp_config())
    grasper = next((t for t in cfg.tools if isinstance(t, GrasperConfig)), None)
    if auto_place and grasper is not None and cfg.tissues:
        validate_scene_config(cfg)
        nodes = placed_volume(cfg.tissues[0]).nodes
        g = place_grasper_around_tip(nodes, grasper)
        cfg.replace_tool(grasper.name, g)
        lift = FLOOR_CLEARANCE - lowest_jaw_point(g) if cfg.floor else 0.0
        if lift > 0:  # an organ whose tip sits low: raise organ and grasper together, clear of the floor
            t = cfg.tissues[0]
            t.position = (t.position[0], t.position[1], float(t.position[2]) + lift)
            g.position = (g.position[0], g.position[1], float(g.position[2]) + lift)
    return build_scene(cfg)


#: m, the least gap between an auto-placed grasper's open jaws and the floor
FLOOR_CLEARANCE = 0.001


def lowest_jaw_point(g: GrasperConfig) -> float:
    """World z (m) of the lowest corner of the open jaws of grasper ``g`` at its home pose."""
    from surgsim_envs.scene.tools.base import _rotation_to

    rot = _rotation_to(-np.asarray(g.axis, dtype=float))
    t, half = g.jaw_thickness, np.array([g.jaw_thickness, g.jaw_width, g.jaw_length]) / 2.0
    signs = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], dtype=float)
    low = math.inf
    for i in range(3):
        theta = float(g.roll) + 2.0 * math.pi * i / 3.0
        c, s = math.cos(theta), math.sin(theta)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        centre = np.array([c, s, 0.0]) * (g.open_radius + t / 2.0) + [0.0, 0.0, -g.jaw_length / 2.0]
        corners = centre + (signs * half) @ rz.T
        low = min(low, float((np.asarray(g.position, dtype=float) + corners @ rot.T)[:, 2].min()))
    return low


@dataclass(frozen=True)
class SceneEntry:
    """A ready-made scene: ``config(**kw) -> SceneConfig`` (organ=, model=) and ``build(cfg) -> Scene``."""

    config: Callable[..., SceneConfig]
    build: Callable[..., Scene]


#: THE registry of ready-made scenes, used by envs, scenarios, haptics and the CLI
SCENES: dict[str, SceneEntry] = {"palpation": SceneEntry(palpation_config, palpation_scene),
                                 "grasp": SceneEntry(grasp_config, grasp_scene)}


def register_scene(name: str, config: Callable[..., SceneConfig], build: Callable[..., Scene] = build_scene) -> None:
    """Add a ready-made scene ``name`` (a config factory and a builder) to :data:`SCENES`."""
    SCENES[name] = SceneEntry(config, build)


def _entry(name: str) -> SceneEntry:
    try:
        return SCENES[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown scene {name!r}; available scenes: {sorted(SCENES)}") from None


def scene_config(name: str, **kw) -> SceneConfig:
    """The default SceneConfig of ready-made scene ``name`` (keywords: organ=, model=)."""
    return _entry(name).config(**kw)


def make_scene(name: str, cfg: SceneConfig | None = None) -> Scene:
    """Build the ready-made scene ``name`` ("palpation", "grasp"), from ``cfg`` if given."""
    return _entry(name).build(cfg)
