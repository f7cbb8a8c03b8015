"""ExamplePress-v0's settings (SI units) and their checks: every field is validated by name, value,
bound and fix (ConfigError), with the shared checks of :mod:`surgsim_envs.envs.checks`."""

from __future__ import annotations

from dataclasses import dataclass

from surgsim_envs.envs.checks import (check_control_rate, check_on_unstable, check_positive, check_render_size,
                                     check_weights)


@dataclass
class ExamplePressConfig:
    """Press a liver slab with a probe to a target force (newtons) and hold it."""

    control_hz: float = 50.0           # Hz
    dt: float = 1e-3                   # s, physics step
    episode_seconds: float = 1.0       # s
    spacing: float = 0.02              # m, tissue lattice spacing (coarse: a fast example)
    slab_size: tuple = (0.1, 0.1, 0.02)   # m
    model: str = "mass_spring"
    integrator: str = "symplectic"
    tip_radius: float = 0.01           # m
    probe_speed: float = 0.05          # m/s, rate limit of the probe target
    hover: float = 0.002               # m above the rest surface at press = -1
    max_depth: float = 0.008           # m below the rest surface at press = +1
    target_force: float = 0.5          # N, the force to hold
    force_weight: float = 1.0          # per unit of relative force error per step
    on_unstable: str = "raise"
    camera: str = "overview"
    render_width: int = 240
    render_height: int = 240

    def validate(self) -> None:
        what = "ExamplePressConfig"
        for key in ("spacing", "tip_radius", "probe_speed", "hover", "max_depth", "target_force"):
            check_positive(getattr(self, key), f"{what}.{key}")
        check_control_rate(self, what)
        check_weights(self, ("force_weight",), what)
        check_on_unstable(self.on_unstable, what)
        check_render_size(self, what)
