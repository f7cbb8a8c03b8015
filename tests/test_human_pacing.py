"""render_mode="human" is paced to real time: the pacer's schedule on a fake clock, and the env's
period from its control rate (no timing asserts)."""

from __future__ import annotations

import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.scene.pacing import RealTimePacer, pace_period


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        assert s > 0
        self.t += s


def test_fast_steps_are_held_to_one_per_period():
    clock = FakeClock()
    pacer = RealTimePacer(0.01, clock=clock, sleep=clock.sleep)
    for _ in range(101):
        clock.t += 0.001            # a 1 ms step: ten times faster than real time
        pacer.wait()
    # 100 control periods after the first step, not 101 x 1 ms
    assert clock.t == pytest.approx(0.001 + 100 * 0.01, abs=1e-9)
    assert pacer.restarts == 0


def test_an_overrun_step_is_not_made_up_by_a_burst():
    clock = FakeClock()
    pacer = RealTimePacer(0.01, clock=clock, sleep=clock.sleep)
    pacer.wait()                     # schedule starts at t = 0
    clock.t += 0.5                   # a pause (breakpoint, slow reset): 50 periods late
    assert pacer.wait() == 0.0 and pacer.restarts == 1
    slept = []
    for _ in range(3):
        clock.t += 0.002
        slept.append(pacer.wait())
    assert slept == pytest.approx([0.008, 0.008, 0.008])   # paced again at once, no catch-up burst


def test_a_slightly_late_step_keeps_the_schedule():
    clock = FakeClock()
    pacer = RealTimePacer(0.01, clock=clock, sleep=clock.sleep)
    pacer.wait()
    clock.t += 0.013                 # 3 ms late: the next slot still ends at 0.02
    assert pacer.wait() == 0.0
    clock.t += 0.001
    assert pacer.wait() == pytest.approx(0.006)
    assert pacer.restarts == 0


def test_pace_period_and_bad_values():
    assert pace_period(100.0, 1.0) == pytest.approx(0.01)
    assert pace_period(100.0, 2.0) == pytest.approx(0.005)
    assert pace_period(100.0, None) is None
    for bad in (0, -1.0, float("nan"), float("inf"), True, "fast"):
        with pytest.raises(ConfigError, match="human_pace=.*1.0 = real time.*None to run unpaced"):
            pace_period(100.0, bad)
    with pytest.raises(ConfigError, match="period"):
        RealTimePacer(0.0)


def test_env_paces_human_rendering_to_its_control_period(monkeypatch):
    from surgsim_envs.envs.palpation_press import PalpationPressEnv
    from surgsim_envs.scene import display

    monkeypatch.setattr(display, "require_display", lambda what="": None)   # no window is opened here
    env = PalpationPressEnv(render_mode="human")
    assert env.human_pacer.period_s == pytest.approx(1.0 / env.config.control_hz)
    assert PalpationPressEnv(render_mode="human", human_pace=None).human_pacer is None
    assert PalpationPressEnv(render_mode=None).human_pacer is None
    with pytest.raises(ConfigError, match="human_pace"):
        PalpationPressEnv(render_mode="human", human_pace=0)
