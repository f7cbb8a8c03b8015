"""One device-spec parser and factory (haptics.device) for the CLI, scenarios and teleop."""

import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceLimits
from surgsim_envs.haptics.device_kinds import make_device, parse_device_spec


def test_parse_device_spec_accepts_the_four_forms_and_names_bad_ones():
    assert parse_device_spec("scripted") == ("scripted", None)
    assert parse_device_spec("keyboard") == ("keyboard", None)
    assert parse_device_spec("replay:run.csv") == ("replay", "run.csv")
    assert parse_device_spec("udp:9870") == ("udp", 9870)
    for bad in ("joystick", "udp:0", "udp:x", "replay:", "keyboard:1", 5):
        with pytest.raises(ConfigError, match="device|PORT"):
            parse_device_spec(bad)


def test_make_device_builds_and_checks(tmp_path):
    from surgsim_envs.haptics.keyboard import KeyboardDevice

    assert isinstance(make_device("keyboard", limits=DeviceLimits(max_force=2.0)), KeyboardDevice)
    with pytest.raises(ConfigError, match="not found"):
        make_device("replay:missing.csv", base_dir=tmp_path)
    with pytest.raises(ConfigError, match="needs a trajectory"):
        make_device("scripted")
    sentinel = object()
    assert make_device("scripted", scripted=lambda: sentinel) is sentinel
