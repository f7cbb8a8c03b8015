"""PalpationPress-v0's settings: :class:`PalpationPressConfig` (SI units) and its checks."""

from __future__ import annotations

from dataclasses import dataclass

from surgsim_envs import validate
from surgsim_envs.envs.checks import check_task_length, check_weights
from surgsim_envs.envs.palpation.config import PalpationConfig
from surgsim_envs.errors import ConfigError

#: physics steps of one phase of a press (settle, hold): 10^5 steps are 100 s of simulated time at
#: the default 1 ms step, and minutes of CPU for one env step
MAX_PRESS_STEPS = 100_000
#: presses per episode
MAX_PRESSES = 10_000


@dataclass
class PalpationPressConfig(PalpationConfig):
    """PalpationPress-v0 settings (SI units); slab, inclusion ranges and the localisation reward
    are those of :class:`PalpationConfig` (its continuous-control fields are unused)."""

    press_depth: float = 0.006       # m below the rest surface
    clearance: float = 0.004         # m above the rest surface while moving between sites
    move_speed: float = 1.0          # m/s, probe target rate while moving
    press_speed: float = 0.5         # m/s, probe target rate while pressing
    settle_steps: int = 8            # physics steps after the move before descending
    hold_steps: int = 30             # physics steps from the start of the descent to the reading
    average_steps: int = 10          # physics steps averaged for the stiffness sample
    max_presses: int = 25            # presses per episode (the time limit)
    min_presses: int = 1             # report is ignored before this many presses
    press_cost: float = 0.02         # per press
    cell_reward: float = 0.1         # first sample in each map cell
    map_cells: int = 5

    def validate(self) -> None:
        super().validate()
        what = "PalpationPressConfig"
        for key in ("press_depth", "clearance"):
            check_task_length(getattr(self, key), f"{what}.{key}")
        for key in ("move_speed", "press_speed"):
            # the moves between presses take travel / move_speed / dt physics steps in one env step
            validate.real(getattr(self, key), f"{what}.{key}", lo=1e-3, hi=100.0, unit="m/s",
                          fix="probe speeds lie in [0.001, 100] m/s (slower moves take hours per press)")
        fix = (f"a press runs settle_steps + hold_steps physics steps; at most {MAX_PRESS_STEPS:,} each "
               f"({MAX_PRESS_STEPS * self.dt:g} s at dt={self.dt:g} s) so one env step cannot run for hours")
        for key in ("settle_steps", "hold_steps", "average_steps"):
            validate.steps(getattr(self, key), f"{what}.{key}", hi=MAX_PRESS_STEPS, fix=fix)
        validate.integer(self.max_presses, f"{what}.max_presses", lo=1, hi=MAX_PRESSES,
                         fix=f"presses per episode in [1, {MAX_PRESSES:,}], e.g. 25")
        if self.average_steps > self.hold_steps:
            raise ConfigError(f"{what}.average_steps={self.average_steps} must be <= hold_steps={self.hold_steps}")
        validate.integer(self.min_presses, f"{what}.min_presses", lo=0, hi=self.max_presses,
                         fix=f"it must lie in [0, max_presses={self.max_presses}]")
        check_weights(self, ("press_cost",), what)
        if self.press_depth <= self.press_min_depth:
            raise ConfigError(f"press_depth={self.press_depth} m must exceed press_min_depth={self.press_min_depth} m "
                              "(shallower presses give no stiffness sample)")
