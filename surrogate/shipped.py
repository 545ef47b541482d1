"""The pretrained surrogate that ships with the package, where one does.

The weights ship as package data in ``mjcodesign/surrogate/weights/`` (a checkpoint folder:
``config.json`` and ``model.safetensors``, :mod:`~mjcodesign.surrogate.checkpoint`). Every command that
takes ``--ckpt`` (``hw grasp``: ``--surrogate`` without a folder) falls back to it through
:func:`checkpoint_or_shipped`, which refuses in one line, saying how to train one, while none ships.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from mjcodesign.errors import DesignError

__all__ = ["SHIPPED_DIR", "TRAIN_HINT", "checkpoint_or_shipped", "shipped_checkpoint"]

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


def checkpoint_or_shipped(ckpt: str | Path | None, flag: str = "--ckpt") -> str | Path:
    """``ckpt`` when given, else the shipped checkpoint's folder.

    Raises :class:`~mjcodesign.errors.DesignError` (one line: no weights ship, the commands that train
    them, ``flag`` to pass) when ``ckpt`` is None and :func:`shipped_checkpoint` finds none.
    """
    if ckpt is not None:
        return ckpt
    folder = shipped_checkpoint()
    if folder is None:
        raise DesignError(
            f"no pretrained surrogate ships with this mjcodesign yet: train one ({TRAIN_HINT}) and pass {flag} ckpt"
        )
    return folder
