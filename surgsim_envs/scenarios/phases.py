"""Phase types of a scenario and who drives them.

Every phase lasts ``duration`` seconds (times the scenario's duration scale) and, when driven by
the script, commands the tool every physics step through :meth:`Phase.command`: a tool offset
(3,) m from the tool's home position and a jaw opening (m, graspers; None keeps it). A phase
driven by a device or a policy takes its commands from that trainee instead; the phase type then
only labels the interval (for the report and the phase order checks).

==============  ==========  =====================================================================
type            tool        keys (SI units) — all optional except where noted
==============  ==========  =====================================================================
``approach``    any         ``offset`` (3,) m target from home, or ``above`` (2,) m x, y over
                            which a probe stops ``clearance`` m above the tissue
``close_jaws``  grasper     ``opening`` m: final distance axis-to-jaw (default 12 mm or the
                            grasper's min); the jaws close at constant speed over ``duration``
``hold``        any         nothing moves
``pull``        grasper     ``distance`` m along ``direction`` (default: out of the organ) at
                            constant speed, *or* ``force`` N: the pull force ramps linearly
                            from 0 to ``force`` over ``duration`` (closed loop, ``gain`` m/s/N)
``press``       probe       ``at`` (2,) m x, y; ``depth`` m below the tissue top; ``clearance``
``palpate``     probe       ``region`` [[x0, y0], [x1, y1]] m, ``grid`` [nx, ny] presses of
                            ``depth`` m each, ``duration`` shared among them
``release``     any         grasper: jaws open fully; probe: back to home
==============  ==========  =====================================================================

Per-phase ``driver`` / ``device`` / ``policy`` override the scenario's ``[trainee]`` table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from surgsim_envs.envs.registry import TASKS
from surgsim_envs.errors import ConfigError


@dataclass
class Phase:
    """Common keys: ``duration`` s (> 0), optional ``label``, and the driver override."""

    duration: float = 1.0
    label: str = ""
    driver: str = ""
    device: str = ""
    policy: str = ""
    type: str = field(default="", init=False)
    tool_kind = "any"  # "probe", "grasper" or "any"

    # -- execution ----------------------------------------------------------------------------
    def begin(self, ctx: "PhaseContext") -> None:
        """Called once when the phase starts; captures the start pose."""
        self._start = ctx.offset.copy()
        self._start_radius = ctx.radius

    def command(self, ctx: "PhaseContext", s: float) -> tuple[np.ndarray, float | None]:
        """(offset (3,) m from home, jaw opening m or None) at phase fraction ``s`` in [0, 1]."""
        return self._start, None

    def check(self, ctx: "PhaseContext") -> None:
        """Raise ConfigError when the phase cannot run in this scene (called before stepping)."""


def _lerp(a, b, s):
    return a + (b - a) * min(max(s, 0.0), 1.0)


@dataclass
class Approach(Phase):
    """Move the tool to ``offset`` (m from home) or above point ``above`` (x, y world, m)."""

    offset: tuple[float, float, float] | None = None
    above: tuple[float, float] | None = None
    clearance: float = 0.002

    def begin(self, ctx):
        super().begin(ctx)
        self._goal = ctx.above(self.above, self.clearance) if self.above is not None else (
            np.asarray(self.offset if self.offset is not None else (0.0, 0.0, 0.0), dtype=float))

    def command(self, ctx, s):
        return _lerp(self._start, self._goal, s), None


@dataclass
class CloseJaws(Phase):
    """Close the grasper's jaws to ``opening`` m at constant speed over the phase."""

    opening: float | None = None
    tool_kind = "grasper"

    def begin(self, ctx):
        super().begin(ctx)
        cfg = ctx.tool.config
        self._goal = float(self.opening) if self.opening is not None else max(cfg.min_radius, 0.012)

    def check(self, ctx):
        cfg = ctx.tool.config
        if self.opening is not None and not (cfg.min_radius <= self.opening < cfg.open_radius):
            raise ConfigError(f"close_jaws opening={self.opening} m must lie in [{cfg.min_radius}, "
                              f"{cfg.open_radius:.4f}) m (grasper min_radius .. open_radius)")

    def command(self, ctx, s):
        return self._start, _lerp(self._start_radius, self._goal, s)


@dataclass
class Hold(Phase):
    """Keep everything where it is (the grasping simulation paper: 7 s, the tissue relaxes)."""


@dataclass
class Pull(Phase):
    """Retract the grasper: a displacement ``distance`` m or a force ramp to ``force`` N."""

    distance: float | None = None
    force: float | None = None
    direction: tuple[float, float, float] | None = None
    gain: float = 0.2
    max_speed: float = 0.05
    tool_kind = "grasper"

    def begin(self, ctx):
        super().begin(ctx)
        d = np.asarray(self.direction, dtype=float) if self.direction is not None else ctx.pull_direction
        self._dir = d / np.linalg.norm(d)
        self._dist = 0.0
        self._last_s = 0.0

    def command(self, ctx, s):
        if self.force is None:
            dist = 0.05 if self.distance is None else self.distance
            return self._start + self._dir * dist * min(max(s, 0.0), 1.0), None
        # force ramp: move along the pull direction at a speed proportional to the force error
        ds = max(s - self._last_s, 0.0)
        self._last_s = s
        error = self.force * min(s, 1.0) - ctx.pull_force()
        v = float(np.clip(self.gain * error, -self.max_speed, self.max_speed))
        self._dist = max(self._dist + v * ds * self.duration * ctx.scale, 0.0)
        return self._start + self._dir * self._dist, None

    def check(self, ctx):
        if self.distance is not None and self.force is not None:
            raise ConfigError("pull: give either distance (m, displacement) or force (N, force ramp), not both")
        for key in ("distance", "force", "gain", "max_speed"):
            v = getattr(self, key)
            if v is not None and v <= 0:
                raise ConfigError(f"pull {key}={v!r} must be > 0")
        if self.direction is not None and np.linalg.norm(self.direction) < 1e-9:
            raise ConfigError(f"pull direction {self.direction!r} must be a non-zero vector")


@dataclass
class Press(Phase):
    """Press the probe ``depth`` m into the tissue top at ``at`` (x, y) and come back up."""

    at: tuple[float, float] = (0.0, 0.0)
    depth: float = 0.004
    clearance: float = 0.002
    tool_kind = "probe"

    def begin(self, ctx):
        super().begin(ctx)
        self._points = [tuple(self.at)]
        self._k = -1

    def _press_path(self, ctx, xy, s):
        above = ctx.above(xy, self.clearance)
        bottom = ctx.above(xy, -self.depth)
        # 10 % move over, 45 % down, 45 % up
        if s < 0.1:
            return _lerp(self._from, above, s / 0.1)
        if s < 0.55:
            return _lerp(above, bottom, (s - 0.1) / 0.45)
        return _lerp(bottom, above, (s - 0.55) / 0.45)

    def command(self, ctx, s):
        n = len(self._points)
        k = min(int(s * n), n - 1)
        if k != getattr(self, "_k", -1):
            self._k = k
            self._from = ctx.offset.copy() if k == 0 else ctx.above(self._points[k - 1], self.clearance)
        return self._press_path(ctx, self._points[k], s * n - k), None

    def check(self, ctx):
        for key in ("depth", "clearance"):
            if getattr(self, key) <= 0:
                raise ConfigError(f"{self.type} {key}={getattr(self, key)!r} must be > 0 m")


@dataclass
class Palpate(Press):
    """A grid of presses over ``region`` (two corners, m); the stiffest spot locates the inclusion."""

    region: tuple[tuple[float, float], tuple[float, float]] = ((-0.02, -0.02), (0.02, 0.02))
    grid: tuple[int, int] = (3, 3)

    def begin(self, ctx):
        Phase.begin(self, ctx)
        (x0, y0), (x1, y1) = self.region
        nx, ny = self.grid
        xs = np.linspace(x0, x1, nx) if nx > 1 else [(x0 + x1) / 2]
        ys = np.linspace(y0, y1, ny) if ny > 1 else [(y0 + y1) / 2]
        # boustrophedon order keeps the moves between presses short
        self._points = [(float(x), float(y)) for j, y in enumerate(ys)
                        for x in (xs if j % 2 == 0 else list(xs)[::-1])]
        self._k = -1

    def check(self, ctx):
        super().check(ctx)
        if self.grid[0] < 1 or self.grid[1] < 1 or self.grid[0] * self.grid[1] > 400:
            raise ConfigError(f"palpate grid={list(self.grid)} must be two integers >= 1 with at most 400 presses")


@dataclass
class Release(Phase):
    """Grasper: open the jaws fully; probe: go back to the home pose."""

    def begin(self, ctx):
        super().begin(ctx)

    def command(self, ctx, s):
        if ctx.has_jaws:
            return self._start, _lerp(self._start_radius, ctx.tool.config.open_radius, s)
        return _lerp(self._start, np.zeros(3), s), None


PHASE_TYPES: dict[str, type[Phase]] = {"approach": Approach, "close_jaws": CloseJaws, "hold": Hold, "pull": Pull,
                                       "press": Press, "palpate": Palpate, "release": Release}
#: ready-made scene -> the tool a scenario drives in it, from the task registry (each task names its
#: scene and tool; the tasks sharing a scene drive the same tool there)
SCENE_TOOL = {spec.scene: spec.tool for spec in TASKS.values() if spec.scene is not None}


class PhaseContext:
    """What a phase sees of the running simulation: the tool, its home, and measurements.

    offset: (3,) m current tool target relative to home; radius: m current jaw opening target.
    """

    def __init__(self, sim, tool_name: str, scale: float = 1.0):
        self.sim = sim
        self.tool = sim.tool(tool_name)
        self.kind = self.tool.kind
        self.has_jaws = self.tool.has_grip      # a tool with jaws (a grip command); never a kind-name branch
        self.home = np.asarray(self.tool.home, dtype=float)
        self.scale = float(scale)
        self.offset = np.zeros(3)
        self.radius = float(self.tool.config.open_radius) if self.has_jaws else None
        tissue = sim.tissue()
        self.surface_z = float(tissue.positions[:, 2].max())
        if self.has_jaws:
            axis = np.asarray(self.tool.config.axis, dtype=float)
            self.pull_direction = -axis / np.linalg.norm(axis)
        else:
            self.pull_direction = np.array([0.0, 0.0, 1.0])

    def above(self, xy, clearance: float) -> np.ndarray:
        """Offset (m from home) that puts a probe tip ``clearance`` m above the tissue top at ``xy``."""
        r = float(getattr(self.tool.config, "tip_radius", 0.0))
        world = np.array([float(xy[0]), float(xy[1]), self.surface_z + r + float(clearance)])
        return world - self.home

    def pull_force(self) -> float:
        """N, the tissue's force on the tool against the pull direction (what the hand pulls with)."""
        return float(-self.sim.tool_force(self.tool.name) @ self.pull_direction)

    def apply(self, offset, radius) -> None:
        """Send a command to the simulation (jumps the position targets; actuators follow)."""
        offset = np.asarray(offset, dtype=float)
        if not np.array_equal(offset, self.offset):
            self.sim.set_tool_target(self.tool.name, self.home + offset, speed=math.inf)
            self.offset = offset.copy()
        if radius is not None and self.has_jaws:
            cfg = self.tool.config
            radius = float(min(max(radius, cfg.min_radius), cfg.open_radius))
            if radius != self.radius:
                self.sim.set_jaw_opening(self.tool.name, radius, speed=math.inf)
                self.radius = radius


def build_phase(table, path: tuple, ctx, trainee) -> Phase:
    """A :class:`Phase` from its TOML table (``ctx`` is the schema's error context)."""
    from surgsim_envs.scenarios.schema import build_dataclass, validate_driver

    if not isinstance(table, dict):
        raise ctx.error(path, f"a phase must be a table, got {table!r}")
    kind = table.get("type")
    if kind not in PHASE_TYPES:
        raise ctx.error(path + ("type",), f"unknown phase type {kind!r}; choose one of {', '.join(PHASE_TYPES)}")
    phase = build_dataclass(PHASE_TYPES[kind], table, path, ctx, skip=("type",))
    phase.type = kind
    if phase.duration <= 0:
        raise ctx.error(path + ("duration",), f"must be > 0 s, got {phase.duration!r}")
    phase.driver = phase.driver or trainee.driver
    phase.device = phase.device or trainee.device
    phase.policy = phase.policy or trainee.policy
    validate_driver(ctx, path, phase.driver, phase.device, phase.policy)
    if isinstance(phase, Pull) and phase.distance is not None and phase.force is not None:
        raise ctx.error(path + ("force",), f"give either distance ({phase.distance} m) or force ({phase.force} N), "
                                           "not both")
    return phase


def check_phase_order(phases: list[Phase], scene: str, ctx) -> None:
    """Raise (via ``ctx.error``) for phases the scene's tool cannot do or an impossible order:
    pulling or holding a grasp before the jaws closed, closing jaws twice, releasing nothing."""
    tool = SCENE_TOOL.get(scene, "any")
    closed = False
    for i, ph in enumerate(phases):
        path = ("phases", i, "type")
        if ph.tool_kind != "any" and ph.tool_kind != tool:
            raise ctx.error(path, f"phase {i} ({ph.type!r}) needs a {ph.tool_kind}, but scene {scene!r} has a {tool}; "
                                  f"use scene = \"{'grasp' if ph.tool_kind == 'grasper' else 'palpation'}\"")
        if ph.driver != "script":
            if ph.type == "close_jaws":
                closed = True
            elif ph.type == "release":
                closed = False
            continue
        if ph.type == "close_jaws":
            if closed:
                raise ctx.error(path, f"phase {i} closes the jaws again without a release in between")
            closed = True
        elif ph.type == "pull" and not closed:
            raise ctx.error(path, f"phase {i} (pull) comes before the jaws have closed: nothing is grasped; "
                                  "put a close_jaws phase before it")
        elif ph.type == "release":
            if tool == "grasper" and not closed:
                raise ctx.error(path, f"phase {i} (release) opens jaws that were never closed; "
                                      "put a close_jaws phase before it or remove the release")
            closed = False
