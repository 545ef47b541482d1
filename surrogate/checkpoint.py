"""A surrogate checkpoint: a folder with the weights (safetensors) and a JSON record.

Layout::

    DIR/model.safetensors   the network's state (weights and BatchNorm statistics)
    DIR/config.json         format and version, the architecture, the normalisation statistics, the
                            scenario's success constants, the dataset's manifest hash, the split, the
                            training settings and the metrics

:func:`load_surrogate` needs only the model and these two files (no training code runs). The record
holds each input's training range (``input_range``), outside which predictions are refused; a record
without one gets the rule of ``InputRange.recorded``. A normalisation with NaN, a zero spread or a
vector of the wrong length is refused at load. Saving
removes the JSON record first and writes it last (by a rename), so a folder whose weights were
being replaced reads as no checkpoint rather than as a record with the wrong weights.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mjcodesign.data.config import DatagenConfig
from mjcodesign.design.stiffness import N_LOG_E
from mjcodesign.errors import MjcodesignError, OutputError
from mjcodesign.outputs import read_versioned_json, write_atomic
from mjcodesign.surrogate.data import N_REGRESSION, OUTPUT_NAMES, Normalizer
from mjcodesign.surrogate.inference import InputRange, Surrogate
from mjcodesign.surrogate.model import GraspNet, ModelConfig

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "CONFIG",
    "WEIGHTS",
    "dataset_config",
    "load_surrogate",
    "read_record",
    "save_checkpoint",
]

CHECKPOINT_FORMAT = "mjcodesign-surrogate"
CHECKPOINT_VERSION = 1
"""Bumped when a reader must change (inputs, outputs, file layout)."""
CONFIG = "config.json"
WEIGHTS = "model.safetensors"


def save_checkpoint(out: str | Path, surrogate: Surrogate) -> Path:
    """Write ``surrogate`` (its model, normalisation and :attr:`Surrogate.meta`) into folder ``out``."""
    from safetensors.torch import save_file

    root = Path(out)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot write {root}: {exc.strerror or exc}") from exc
    state = {k: v.detach().contiguous().cpu() for k, v in surrogate.model.state_dict().items()}
    record = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "model": surrogate.config.as_dict(),
        "normalizer": surrogate.normalizer.as_dict(),
        "outputs": list(OUTPUT_NAMES),
        "scenario": {"lift": surrogate.lift, "lifted_fraction": surrogate.lifted_fraction},
        **({"input_range": r.as_dict()} if (r := surrogate.trained_range) is not None else {}),
        **surrogate.meta,
    }
    try:
        (root / CONFIG).unlink(missing_ok=True)
        save_file(state, str(root / WEIGHTS))
    except OSError as exc:
        raise OutputError(f"cannot write {root / WEIGHTS}: {exc.strerror or exc}") from exc
    write_atomic(root / CONFIG, json.dumps(record, indent=1))
    return root


def read_record(path: str | Path) -> dict:
    """The checkpoint's JSON record; :class:`OutputError` if ``path`` holds no checkpoint of this version."""
    root = Path(path)
    what = "a surrogate checkpoint"
    record = read_versioned_json(
        root / CONFIG, fmt=CHECKPOINT_FORMAT, version=CHECKPOINT_VERSION, what=what, where=root
    )
    if record.get("outputs") != list(OUTPUT_NAMES):
        raise OutputError(
            f"{root}: {what} of another schema (outputs {record.get('outputs')!r}; "
            f"this mjcodesign reads {list(OUTPUT_NAMES)!r})"
        )
    return record


def dataset_config(surrogate: Surrogate) -> DatagenConfig | None:
    """The config of the dataset ``surrogate`` was trained on; None for a record without one.

    Read from the record's ``dataset.config`` (:meth:`DatagenConfig.from_dict`): the grasp scenario,
    the tendon drive, the finger model and geometry the dataset's rows were simulated under.

    Raises :class:`OutputError` for a config that does not read back.
    """
    recorded = (surrogate.meta.get("dataset") or {}).get("config")
    if recorded is None:
        return None
    try:
        return DatagenConfig.from_dict(recorded)
    except MjcodesignError as exc:
        raise OutputError(f"the checkpoint's dataset config does not read back: {exc}") from exc


def load_surrogate(path: str | Path) -> Surrogate:
    """The :class:`Surrogate` saved in folder ``path`` (eval mode, float32).

    Raises :class:`OutputError` for a missing, unreadable or other-schema checkpoint.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    root = Path(path)
    record = read_record(root)
    weights = root / WEIGHTS
    if not weights.is_file():
        raise OutputError(f"{root}: checkpoint without weights ({WEIGHTS} missing)")
    try:
        model = GraspNet(ModelConfig.from_dict(record["model"]))
        model.load_state_dict(load_file(str(weights)), strict=True)
        norm = Normalizer.from_dict(record["normalizer"])
        _check_normalizer(norm)
        scenario = record["scenario"]
        input_range = InputRange.from_dict(record["input_range"]) if "input_range" in record else None
    except (KeyError, TypeError, ValueError, RuntimeError, SafetensorError, MjcodesignError) as exc:
        raise OutputError(
            f"{root}: broken checkpoint ({type(exc).__name__}: {str(exc).splitlines()[0]})"
        ) from exc
    meta = {
        k: v
        for k, v in record.items()
        if k not in ("format", "version", "model", "normalizer", "outputs", "scenario", "input_range")
    }
    return Surrogate(
        model,
        norm,
        lift=scenario["lift"],
        lifted_fraction=scenario["lifted_fraction"],
        meta=meta,
        input_range=input_range,
    )


# Lengths of the normalisation's vectors: 22 ln E, 9 regressed outputs, 7 frame inputs.
_NORM_SHAPES = {"log_e": N_LOG_E, "out": N_REGRESSION, "frame": 7}  # frame: frame_inputs' columns


def _check_normalizer(norm: Normalizer) -> None:
    """Raise :class:`OutputError` unless every statistic is finite, every spread > 0, every length right."""
    for name, n in _NORM_SHAPES.items():
        for kind in ("mean", "std"):
            v = np.asarray(getattr(norm, f"{name}_{kind}"), dtype=float)
            if v.shape != (n,):
                raise OutputError(f"normalizer {name}_{kind} has {v.size} values, not {n}")
            if not np.all(np.isfinite(v)) or (kind == "std" and np.any(v <= 0)):
                raise OutputError(f"normalizer {name}_{kind} holds NaN, inf or a spread <= 0")
    if not (np.isfinite(norm.density_mean) and np.isfinite(norm.density_std) and norm.density_std > 0):
        raise OutputError("normalizer density holds NaN, inf or a spread <= 0")
