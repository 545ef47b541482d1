"""The surrogate refuses inputs outside its training range and a checkpoint whose normalisation is broken."""

import json
import shutil

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("safetensors")

from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E, Stiffness  # noqa: E402
from mjcodesign.errors import DesignError, OutputError  # noqa: E402


def _edited(tiny_checkpoint, tmp_path, edit):
    """A copy of the tiny checkpoint with its JSON record passed through ``edit``."""
    ckpt = tmp_path / "ckpt"
    shutil.copytree(tiny_checkpoint, ckpt)
    record = json.loads((ckpt / "config.json").read_text())
    edit(record)
    (ckpt / "config.json").write_text(json.dumps(record))
    return ckpt


@pytest.fixture
def box(tmp_path):
    import trimesh

    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(path)
    return str(path)


def test_a_density_outside_the_training_range_is_refused(tiny_checkpoint, tmp_path, box):
    # Trained at one density (100 kg/m³): a prediction at 400 extrapolates, so it is refused.
    from mjcodesign.surrogate.grasp import predict_grasp

    def one_density(r):
        r["dataset"]["density"] = {"low_kg_m3": 100.0, "high_kg_m3": 100.0}

    ckpt = _edited(tiny_checkpoint, tmp_path, one_density)
    design = Stiffness.preset("paper-optimized")
    ok = predict_grasp(ckpt, box, "auto", design, 100.0)
    assert np.all(np.isfinite(ok["body_force"]))
    with pytest.raises(DesignError, match="density 400 kg/m³ is outside"):
        predict_grasp(ckpt, box, "auto", design, 400.0)


def test_a_measured_range_round_trips_and_bounds_each_block(tiny_checkpoint, tmp_path):
    from mjcodesign.surrogate import load_surrogate, save_checkpoint
    from mjcodesign.surrogate.inference import InputRange

    sur = load_surrogate(tiny_checkpoint)
    assert sur.input_range.density_low == 100.0 and sur.input_range.density_high == 400.0
    assert np.all(sur.input_range.log_e_low == LOG_E_MIN) and np.all(sur.input_range.log_e_high == LOG_E_MAX)
    low = np.full(N_LOG_E, 14.0)
    sur.trained_range = InputRange(low, np.full(N_LOG_E, 16.0), 150.0, 300.0)
    back = load_surrogate(save_checkpoint(tmp_path / "measured", sur))
    assert np.array_equal(back.input_range.log_e_low, low) and back.input_range.density_high == 300.0
    design = np.full((1, N_LOG_E), 15.0)
    back.input_range.check(design, [200.0])
    design[0, 7] = 16.5
    with pytest.raises(DesignError, match=r"ln E\[7\] = 16.5 is outside"):
        back.input_range.check(design, [200.0])


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("log_e_std", "nan", "log_e_std holds nan"),
        ("density_std", 0.0, "density holds nan"),
        ("out_mean", [0.0] * 8, "out_mean has 8 values"),
    ],
)
def test_a_broken_normalisation_is_refused_at_load(tiny_checkpoint, tmp_path, field, value, words):
    from mjcodesign.surrogate import load_surrogate

    def broken(r):
        if value == "nan":
            r["normalizer"][field][0] = float("nan")
        else:
            r["normalizer"][field] = value

    with pytest.raises(OutputError, match=words.replace("nan", "(?i:nan)")):
        load_surrogate(_edited(tiny_checkpoint, tmp_path, broken))


def test_a_dataset_at_published_masses_is_trained_over_its_rows_densities():
    from mjcodesign.surrogate.inference import InputRange

    # A real-regime dataset: configured at ycb-median (680) for objects without a published mass, its
    # rows at each object's own density (the apple 276, the potted-meat can 1045).
    r = InputRange.of_dataset(np.array([276.0, 680.0, 1045.0]), (680.0, 680.0))
    assert (r.density_low, r.density_high) == (276.0, 1045.0)
    # A uniform:100,400 dataset whose draws fell inside the range keeps the configured ends.
    r = InputRange.of_dataset(np.array([131.0, 377.0]), (100.0, 400.0))
    assert (r.density_low, r.density_high) == (100.0, 400.0)
