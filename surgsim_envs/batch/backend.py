"""The optional Warp stack of the batched backend: ``warp`` (NVIDIA Warp) and ``mujoco_warp``.

Both come with the ``[batch]`` extra. :func:`require` imports them or raises
:class:`BatchUnavailableError` naming the missing package and the install command;
:func:`device_name` checks a device argument ("cpu", "cuda", "cuda:0", ...).
"""

from __future__ import annotations

from surgsim_envs.errors import ConfigError


class BatchUnavailableError(ConfigError):
    """The batched backend needs a package or device this host does not have."""


INSTALL_HINT = "pip install 'surgsim_envs[batch]'"


def require():
    """(warp, mujoco_warp) modules, Warp initialised quietly; BatchUnavailableError if missing."""
    try:
        import warp as wp
    except ImportError as exc:
        raise BatchUnavailableError(f"the batched backend needs NVIDIA Warp (warp-lang): {exc}; {INSTALL_HINT}") from None
    try:
        import mujoco_warp as mjw
    except ImportError as exc:
        raise BatchUnavailableError(f"the batched backend needs MuJoCo Warp (mujoco-warp): {exc}; {INSTALL_HINT}") from None
    wp.config.quiet = True
    wp.init()
    return wp, mjw


def available() -> bool:
    """True if warp and mujoco_warp import."""
    try:
        require()
    except BatchUnavailableError:
        return False
    return True


def cuda_available() -> bool:
    """True if Warp sees a CUDA device."""
    if not available():
        return False
    import warp as wp

    return wp.get_cuda_device_count() > 0


def device_name(device) -> str:
    """A checked Warp device name: "cpu", "cuda" or "cuda:<n>" (BatchUnavailableError if Warp has no
    such device, ConfigError for anything else)."""
    if not isinstance(device, str) or not (device == "cpu" or device == "cuda" or
                                           (device.startswith("cuda:") and device[5:].isdigit())):
        raise ConfigError(f"device={device!r} must be 'cpu', 'cuda' or 'cuda:<index>' (a Warp device)")
    wp, _ = require()
    if device != "cpu":
        n = wp.get_cuda_device_count()
        index = 0 if device == "cuda" else int(device[5:])
        if index >= n:
            raise BatchUnavailableError(f"device={device!r}: Warp sees {n} CUDA device(s) on this host; "
                                        "use device='cpu' (Warp's CPU device runs everywhere)")
    return device
