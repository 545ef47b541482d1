"""Import and initialise Warp (an optional, lazily imported dependency).

The library only imports and initialises it; it never touches logging levels or file descriptors. The
CLI quiets Warp's banner and its CUDA-driver notice before a command that can reach Warp
(:func:`mjcodesign.cli.common.quiet_warp`); ``wp.init()`` is idempotent, so this call then prints nothing.
"""

from __future__ import annotations

from mjcodesign.errors import UnsupportedError

__all__ = ["WARP_DEVICES", "import_warp", "warp_device"]

WARP_DEVICES = ("auto", "cpu", "cuda")
"""Choices of a Warp device: ``auto`` is CUDA when Warp finds a CUDA device, else the CPU."""


def import_warp():
    """``warp``, initialised; raises ImportError if warp-lang is missing."""
    import warp as wp

    wp.init()
    return wp


def warp_device(choice: str) -> str:
    """The Warp device (``cpu`` or ``cuda``) for ``choice``, one of :data:`WARP_DEVICES`.

    Imports Warp (:func:`import_warp`; ImportError if warp-lang is missing). Raises
    :class:`UnsupportedError` for ``cuda`` where Warp finds no CUDA device, and for another choice.
    """
    if choice not in WARP_DEVICES:
        raise UnsupportedError(f"unknown Warp device {choice!r}: choose from {', '.join(WARP_DEVICES)}")
    has_cuda = import_warp().get_cuda_device_count() > 0
    if choice == "cuda" and not has_cuda:
        raise UnsupportedError("--device cuda: Warp finds no CUDA device here")
    return "cuda" if choice == "cuda" or (choice == "auto" and has_cuda) else "cpu"
