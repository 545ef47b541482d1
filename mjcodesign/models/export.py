"""Export a finger or gripper model: MJCF with its assets, the compiled MJB, and STL meshes of the blocks."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np

from mjcodesign.errors import OutputError
from mjcodesign.models.types import Built

__all__ = ["export_model", "block_meshes"]


def block_meshes(built: Built):
    """(name, trimesh.Trimesh) of every block of one finger, in the finger frame, metres."""
    import trimesh

    out = []
    for b in built.design.blocks():
        hull = trimesh.convex.convex_hull(b.vertices())
        out.append((f"block{b.index:02d}_{b.kind.value}", hull))
    return out


def export_model(built: Built, out_dir: str | Path) -> dict:
    """Write ``model.xml`` (self-contained MJCF), ``model.mjb``, ``blocks/*.stl`` and ``manifest.json``.

    The MJCF carries everything MuJoCo's viewer needs (mesh vertices inline, flex inline). For flex
    models the per-block stiffness lives in the compiled cell records, which MJCF cannot express: load
    ``model.mjb`` to see the design's stiffness; ``model.xml`` compiles with the reference modulus.
    """
    out = Path(out_dir)
    try:
        (out / "blocks").mkdir(parents=True, exist_ok=True)
        xml = built.spec.to_xml()
        (out / "model.xml").write_text(xml)
        mujoco.mj_saveModel(built.model, str(out / "model.mjb"), None)
        files = ["model.xml", "model.mjb"]
        for name, mesh in block_meshes(built):
            rel = f"blocks/{name}.stl"
            mesh.export(out / rel)
            files.append(rel)
        manifest = {
            "model": built.finger_model.value,
            "tendon_mode": built.tendon_mode.value,
            "log_e": built.stiffness.as_list(),
            "files": files,
            "flex_cell_young_pa": {
                h.prefix.rstrip("_"): np.asarray(h.cell_young).tolist()
                for h in built.fingers
                if h.cell_young is not None
            },
        }
        (out / "manifest.json").write_text(json.dumps(manifest, indent=2))
    except OSError as exc:
        raise OutputError(f"cannot write to {out}: {exc.strerror or exc}") from exc
    return manifest
