"""The device kinds a spec string may name ("scripted", "replay:FILE", "keyboard", "udp:PORT"),
as one registry: each kind says how to read its argument, how to build the device, and what
the callers (teleop, scenarios, the CLI) need to know about it, so none of them branches on the
kind's name. A new device is one module plus a :func:`register_device_kind` call.

Properties a caller may ask:

- ``remote``: the device lives outside this process (a network bridge), so the servo may own it
  in a process of its own (``surgsim teleop --servo auto`` picks the process servo for it);
- ``needs_viewer``: the device reads its input from the interactive viewer's window (keys);
- ``finite``: the device plays a trajectory or recording with a ``duration`` (s), which bounds
  a run that gives no ``--duration``;
- ``file_arg``: the argument names a file (scenario validation checks that it exists).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from surgsim_envs.errors import ConfigError
from surgsim_envs.haptics.device import DeviceLimits, HapticDevice


@dataclass(frozen=True)
class DeviceKind:
    """One kind of haptic device a spec string can name."""

    name: str
    form: str                                   # how a spec names it, e.g. "udp:PORT"
    build: Callable                             # (arg, limits, scripted, base_dir) -> HapticDevice
    parse_arg: Callable[[str, str], object] | None = None   # (arg, spec) -> value; None: no argument
    remote: bool = False
    needs_viewer: bool = False
    finite: bool = False
    file_arg: bool = False                      # the argument names a file (checked by validators)


DEVICE_KINDS: dict[str, DeviceKind] = {}


def register_device_kind(kind: DeviceKind) -> DeviceKind:
    """Add ``kind`` to the registry (its name must be new)."""
    if kind.name in DEVICE_KINDS:
        raise ConfigError(f"device kind {kind.name!r} is already registered")
    DEVICE_KINDS[kind.name] = kind
    return kind


def _forms() -> str:
    forms = [k.form for k in DEVICE_KINDS.values()]
    return ", ".join(forms[:-1]) + " or " + forms[-1]


def device_kind(spec: str) -> tuple[DeviceKind, object]:
    """``spec`` -> (its DeviceKind, its argument); ConfigError naming the spec and the accepted
    forms otherwise."""
    if not isinstance(spec, str):
        raise ConfigError(f"device spec must be a string ({_forms()}), got {spec!r}")
    name, sep, arg = spec.partition(":")
    kind = DEVICE_KINDS.get(name)
    if kind is not None:
        if kind.parse_arg is None and not sep:
            return kind, None
        if kind.parse_arg is not None and arg:
            return kind, kind.parse_arg(arg, spec)
    raise ConfigError(f"device {spec!r} not understood; use {_forms()}")


# ----------------------------------------------------------------------------------------------
# The built-in kinds
def _build_scripted(arg, limits, scripted, base_dir):
    if scripted is None:
        raise ConfigError("device 'scripted' needs a trajectory; give scripted=callable returning the device")
    return scripted()


def _build_replay(arg, limits, scripted, base_dir):
    from surgsim_envs.haptics.replay import ReplayDevice

    path = Path(arg)          # relative: in base_dir (a scenario's folder) if it is there, else the working directory
    if base_dir is not None and not path.is_absolute() and (Path(base_dir) / path).is_file():
        path = Path(base_dir) / path
    if not path.is_file():
        where = f"{base_dir} or the working directory" if base_dir is not None else "the working directory"
        raise ConfigError(f"device replay:{arg}: file not found (looked in {where}); "
                          "give a .csv or .json pose recording")
    return ReplayDevice(str(path), limits=limits)


def _build_keyboard(arg, limits, scripted, base_dir):
    from surgsim_envs.haptics.keyboard import KeyboardDevice

    return KeyboardDevice(limits=limits)


def _port(arg: str, spec: str) -> int:
    try:
        port = int(arg)
    except ValueError:
        port = -1
    if not 1024 <= port < 65536:
        raise ConfigError(f"device {spec!r}: PORT must be an integer in 1024..65535 (ports below 1024 are reserved "
                          "for system services), e.g. udp:9870")
    return port


def _build_udp(arg, limits, scripted, base_dir):
    from surgsim_envs.haptics.udp_bridge import UdpDevice

    return UdpDevice(port=int(arg), limits=limits)


register_device_kind(DeviceKind("scripted", "scripted", _build_scripted, finite=True))
register_device_kind(DeviceKind("replay", "replay:FILE", _build_replay, parse_arg=lambda arg, spec: arg, finite=True,
                                file_arg=True))
register_device_kind(DeviceKind("keyboard", "keyboard", _build_keyboard, needs_viewer=True))
register_device_kind(DeviceKind("udp", "udp:PORT", _build_udp, parse_arg=_port, remote=True))


# ----------------------------------------------------------------------------------------------
# One device-spec parser and factory for the CLI, scenarios and teleop
def parse_device_spec(spec: str) -> tuple[str, str | int | None]:
    """``"scripted"`` / ``"keyboard"`` / ``"replay:FILE"`` / ``"udp:PORT"`` -> ``(kind, argument)``;
    ConfigError naming the spec and the accepted forms otherwise (the file is checked by the
    factory, relative to its base folder). The kinds are registered above."""
    kind, arg = device_kind(spec)
    return kind.name, arg


def make_device(spec: str, *, limits: DeviceLimits | None = None, scripted=None, base_dir=None) -> HapticDevice:
    """THE device factory: a HapticDevice from ``spec`` (see :func:`parse_device_spec`).

    scripted: a callable returning the device for "scripted" (the caller knows its trajectory:
    teleop's demonstration, a scenario's phase plan); base_dir: folder a relative replay FILE is
    resolved against (a scenario's folder)."""
    kind, arg = device_kind(spec)
    return kind.build(arg, limits if limits is not None else DeviceLimits(), scripted, base_dir)
