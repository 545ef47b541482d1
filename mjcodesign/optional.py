"""Import and initialise Warp (an optional, lazily imported dependency).

The library only imports and initialises it; it never touches logging levels or file descriptors. The
CLI quiets Warp's banner and its CUDA-driver notice before a command that can reach Warp
(:func:`mjcodesign.cli.common.quiet_warp`); ``wp.init()`` is idempotent, so this call then prints nothing.
"""

from __future__ import annotations

__all__ = ["import_warp"]


def import_warp():
    """``warp``, initialised; raises ImportError if warp-lang is missing."""
    import warp as wp

    wp.init()
    return wp
