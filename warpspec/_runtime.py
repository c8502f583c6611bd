"""Warp initialisation and device selection, shared by every module."""

from __future__ import annotations

import ctypes.util
import os
import sys

import warp as wp

__all__ = ["init", "resolve_device"]

_initialised = False


def init() -> None:
    """Initialise Warp once, quietly, honouring ``WARP_CACHE_PATH``."""
    global _initialised
    if _initialised:
        return
    cache = os.environ.get("WARP_CACHE_PATH")
    if cache:
        wp.config.kernel_cache_dir = cache
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING  # no start-up banner, no per-module load lines
    if ctypes.util.find_library("cuda") is None:
        # No CUDA driver on this machine: Warp's native code would say so on stderr at every
        # start; the CPU backend is all there is, which `warpspec info` reports.
        with _quiet_stderr():
            wp.init()
    else:
        wp.init()
    _initialised = True


class _quiet_stderr:
    """Point file descriptor 2 at /dev/null for the duration of a ``with`` block."""

    def __enter__(self) -> None:
        sys.stderr.flush()
        self.saved = os.dup(2)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)

    def __exit__(self, *exc: object) -> None:
        os.dup2(self.saved, 2)
        os.close(self.saved)


def resolve_device(device: str | wp.Device | None) -> wp.Device:
    """Return the Warp device to run on.

    Args:
        device: A Warp device or its name (``"cpu"``, ``"cuda"``, ``"cuda:0"``); ``None`` means
            CUDA when Warp sees a GPU, else the CPU.

    Raises:
        InputError: If the named device does not exist here.
    """
    from .errors import InputError

    init()
    if device is None:
        return wp.get_device("cuda") if wp.is_cuda_available() else wp.get_device("cpu")
    if isinstance(device, wp.Device):
        return device
    name = str(device)
    if name.startswith("cuda") and not wp.is_cuda_available():
        raise InputError(
            f"device: {name!r} was asked for but Warp sees no CUDA GPU here; use 'cpu'"
        )
    try:
        return wp.get_device(name)
    except Exception:
        names = ", ".join(d.alias for d in wp.get_devices())
        raise InputError(f"device: unknown device {name!r}; available: {names}") from None
