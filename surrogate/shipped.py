"""The pretrained surrogate that ships with the package, where one does.

The weights ship as package data in ``mjcodesign/surrogate/weights/`` (a checkpoint folder:
``config.json`` and ``model.safetensors``, :mod:`~mjcodesign.surrogate.checkpoint`). Every command that
takes ``--ckpt`` falls back to :func:`shipped_checkpoint` when none is given.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["SHIPPED_DIR", "TRAIN_HINT", "shipped_checkpoint"]

SHIPPED_DIR = "weights"
"""The shipped checkpoint's folder inside the ``mjcodesign.surrogate`` package."""
TRAIN_HINT = (
    "mjcodesign datagen --objects ycb-in-domain --out data && mjcodesign train --data data --out ckpt"
)
"""The commands that make a checkpoint of one's own (``--ckpt ckpt``)."""


def shipped_checkpoint() -> Path | None:
    """The shipped checkpoint's folder, or None when this installation ships no weights."""
    root = resources.files("mjcodesign.surrogate").joinpath(SHIPPED_DIR)
    folder = Path(str(root))
    if (folder / "config.json").is_file() and (folder / "model.safetensors").is_file():
        return folder
    return None
