import os
from pathlib import Path

import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
REFERENCE = SHARED / "reference" / "codesign-soft-gripper"


@pytest.fixture
def reference_dir():
    if not REFERENCE.is_dir():
        pytest.skip("shared/reference/codesign-soft-gripper is absent")
    return REFERENCE


@pytest.fixture(scope="session")
def tiny_checkpoint(tmp_path_factory):
    """A tiny surrogate trained here on a small generated dataset (two shapes, 2 poses x 6 designs)."""
    torch = pytest.importorskip("torch")
    import trimesh

    from mjcodesign.data import DatagenConfig, generate, parse_density_spec
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.surrogate import (
        ModelConfig,
        OptimizerConfig,
        Surrogate,
        TrainConfig,
        load_grasp_data,
        save_checkpoint,
        split,
        train,
    )

    work = tmp_path_factory.mktemp("tiny_surrogate")
    files = []
    for name, mesh in {"box": trimesh.creation.box(extents=(0.05, 0.04, 0.06)), "ball": trimesh.creation.icosphere(radius=0.03)}.items():
        mesh.export(work / f"{name}.stl")
        files.append(str(work / f"{name}.stl"))
    scenario = GraspScenario(impulse=0.0, tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.02)
    cfg = DatagenConfig(
        objects=tuple(files),
        poses_per_object=2,
        designs_per_pose=6,
        density=parse_density_spec("uniform:100,400"),
        scenario=scenario,
        tension=scenario.tension,
    )
    generate(cfg, work / "ds", workers=1, cache_dir=work / "cache")
    data = load_grasp_data(work / "ds")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        result = train(
            data,
            split(data, "random", seed=0),
            TrainConfig(epochs=5, batch_size=16, optimizer=OptimizerConfig(lr=1e-2), early_stop_patience=5, seed=0),
            ModelConfig(point_widths=(8, 16), hidden=16, depth=2, penultimate=8, dropout=0.0),
        )
    finally:
        torch.set_num_threads(n)
    meta = {"dataset": {"density": {"low_kg_m3": 100.0, "high_kg_m3": 400.0}, "object_seed": 0, "cloud_points": 256}}
    sur = Surrogate(result.model, result.normalizer, lift=data.lift, lifted_fraction=data.lifted_fraction, meta=meta)
    return save_checkpoint(work / "ckpt", sur)
