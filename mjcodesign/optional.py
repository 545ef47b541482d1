"""Import and initialise Warp once, quietly (it is an optional, lazily imported dependency).

Warp logs its banner and every module load at INFO level on stdout, which would break ``--json``;
and on a machine without the NVIDIA driver its native library prints a one-line CUDA warning on stderr
during ``wp.init()``, which would make a refused command print two lines. The first is silenced by the
log level, the second is filtered out of the captured stderr; anything else Warp writes there is kept.
"""

from __future__ import annotations

import logging
import os
import sys
import tempfile

__all__ = ["import_warp"]

_NO_DRIVER = b"Could not find or load the NVIDIA CUDA driver"  # expected on CPU-only machines


def import_warp():
    """``warp``, initialised, with INFO logging off; raises ImportError if warp-lang is missing."""
    import warp as wp

    wp.config.log_level = logging.WARNING
    sys.stderr.flush()  # wp.init() is idempotent: a second call prints nothing
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        kept = [ln for ln in captured.read().splitlines(keepends=True) if _NO_DRIVER not in ln]
    if kept:
        sys.stderr.buffer.write(b"".join(kept))
        sys.stderr.flush()
    return wp
