"""LayeredPalpation-v0's settings: :class:`LayeredPalpationConfig` (SI units) and its checks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from surgsim_envs import validate
from surgsim_envs.errors import ConfigError


#: wall thickness of the default abdominal wall (m): presses stay well inside it
MAX_DEPTH_LIMIT = 0.02
#: largest lattice the task builds (nodes): a direct solve per press must stay interactive
MAX_NODES = 60_000
#: lattice spacing range (m)
SPACING_RANGE = (0.002, 0.01)
#: patch side range (m)
SIZE_RANGE = (0.02, 0.3)
CAMERAS = ("overview", "top", "side")


def _finite_number(value, what: str, lo: float, hi: float, hint: str) -> float:
    return validate.real(value, f"LayeredPalpationConfig.{what}", lo=lo, hi=hi,
                         fix=f"give a finite number in [{lo:g}, {hi:g}]: {hint}")


def _integer(value, what: str, lo: int, hi: int, hint: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= int(value) <= hi:
        raise ConfigError(f"LayeredPalpationConfig.{what}={validate.short_repr(value)} must be an integer in "
                          f"[{lo}, {hi}]; {hint}")
    return int(value)


@dataclass
class LayeredPalpationConfig:
    """model: the tissue model of the wall (``"fem_hex"``, the continuum in hexahedra with incompatible
    modes, the default: the cheapest setting within the task's 20 % force tolerance,
    docs/task_accuracy.md; ``"fem_static"``, the continuum in tets; ``"layered"``, the paper's
    springs; :mod:`.wall`); size (x, y) m of the wall patch; spacing m of its lattice; max_depth m; nodule radius m and
    Young's modulus factor; press_cost per press; size_scale m of the commit reward; max_presses;
    probe_radius m; control_hz presses per second of the nominal clock (render fps, dm_control
    timestep); render_width/height px and camera ("overview", "top", "side") of rgb_array frames."""

    model: str = "fem_hex"
    size: tuple = (0.08, 0.06)
    spacing: float = 0.004            # the cheapest fem_hex lattice within the tolerance (docs/task_accuracy.md)
    max_depth: float = 0.008
    nodule_radius: float = 0.008
    nodule_factor: float = 30.0
    press_cost: float = 0.01
    size_scale: float = 0.03
    max_presses: int = 30
    probe_radius: float = 0.005
    control_hz: float = 1.0
    render_width: int = 480
    render_height: int = 480
    camera: str = "overview"

    @property
    def episode_seconds(self) -> float:
        """s of the nominal clock in a full episode (``max_presses / control_hz``)."""
        return self.max_presses / self.control_hz

    def validate(self) -> None:
        """ConfigError naming the field, its bound and the fix."""
        from surgsim_envs.envs.layered_palpation.wall import WALL_MODELS, wall_nodes

        if not isinstance(self.model, str) or self.model not in WALL_MODELS:
            raise ConfigError(f"LayeredPalpationConfig.model={validate.short_repr(self.model)}; choose one of "
                              f"{list(WALL_MODELS)}: the task builds its layered wall with these only (the "
                              "paper's springs, or the continuum on a layer-conforming lattice)")
        size = self.size
        if not validate.has_length(size, 2):
            raise ConfigError(f"LayeredPalpationConfig.size={size!r} must be a pair (x, y) of lengths in m, "
                              "e.g. (0.08, 0.06)")
        for k, v in enumerate(size):
            _finite_number(v, f"size[{k}]", *SIZE_RANGE, "a patch side in m, e.g. 0.08")
        spacing = _finite_number(self.spacing, "spacing", *SPACING_RANGE, "the lattice spacing in m, e.g. 0.005")
        _finite_number(self.max_depth, "max_depth", 1e-4, MAX_DEPTH_LIMIT,
                       "the deepest press in m (the wall is 29 mm thick), e.g. 0.008")
        nod = _finite_number(self.nodule_radius, "nodule_radius", 1e-3, 0.05, "a radius in m, e.g. 0.008")
        if min(size) <= 2 * nod:
            raise ConfigError(f"LayeredPalpationConfig.nodule_radius={nod!r} m does not fit the patch {tuple(size)!r} "
                              "m: every side must exceed 2 x nodule_radius; enlarge size or shrink the nodule")
        _finite_number(self.nodule_factor, "nodule_factor", 1e-3, 1e4,
                       "the nodule's Young's modulus factor, e.g. 30 (stiffer) or 0.2 (softer)")
        _finite_number(self.press_cost, "press_cost", 0.0, 1e3, "a reward cost >= 0 per press, e.g. 0.01")
        _finite_number(self.size_scale, "size_scale", 1e-3, 1.0, "the commit reward's length scale in m, e.g. 0.03")
        _integer(self.max_presses, "max_presses", 1, 10_000, "presses per episode, e.g. 30")
        _finite_number(self.probe_radius, "probe_radius", 1e-3, 0.05, "the probe tip radius in m, e.g. 0.005")
        _finite_number(self.control_hz, "control_hz", 1e-3, 1e3, "nominal presses per second, e.g. 1")
        _integer(self.render_width, "render_width", 16, 4096, "pixels, e.g. 480")
        _integer(self.render_height, "render_height", 16, 4096, "pixels, e.g. 480")
        if self.camera not in CAMERAS:
            raise ConfigError(f"LayeredPalpationConfig.camera={self.camera!r}; choose one of {list(CAMERAS)}")
        nodes = wall_nodes(self.model, size, spacing)
        if nodes > MAX_NODES:
            raise ConfigError(f"LayeredPalpationConfig: size {tuple(size)!r} m at spacing {spacing:g} m gives about "
                              f"{nodes:,.0f} lattice nodes (limit {MAX_NODES:,}): each press solves them all; "
                              "coarsen spacing or shrink size")

