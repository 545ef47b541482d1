"""Slicer-ready files of a :class:`~mjcodesign.fabrication.PrintPlan`: 3MF for two slicer families, STL.

Layout. Each finger is **one object** whose **parts are its blocks**, one named part per block
(``A00_segment`` ... ``A10_segment``), each at its place in the finger. The finger lies as in its own
frame: x along the bed, the 2 mm flexure spine flat on the bed (z = 0), segments rising above it, which
is how the authors printed it (their ``sim_finger.3mf``). Why one object with parts and not one object
per block: the flexures are 2 mm plates that must fuse with the segments' spine into one piece, and a
slicer fuses the parts of one object into the same layer islands, whereas separate objects are sliced
and walled each on its own and only touch. Lying flat, a flexure is a stack of layers, so "solid layers
over a hollow core" is a meaningful stiffness setting; standing up it would be a few loops of a wall.
Both fingers go into one file, side by side along y.

Files:

* PrusaSlicer (tested with PrusaSlicer 2.5 ``--export-gcode``): ``3D/3dmodel.model`` holds one mesh
  per finger, and ``Metadata/Slic3r_PE_model.config`` splits it into named volumes by triangle range,
  each with its settings (``fill_density``, ``bottom_solid_layers``...), plus ``layer_height`` per object.
* Bambu Studio / OrcaSlicer (written to the layout of the authors' file, not loaded by either here):
  the blocks are mesh objects in ``3D/Objects/object_1.model``, each finger an object of components,
  and ``Metadata/model_settings.config`` gives every block a ``normal_part`` with its settings
  (``sparse_infill_density``, ``sparse_infill_pattern``, ``infill_direction``, ``bottom_shell_layers``...).
  The authors put such settings on modifier parts over a one-piece finger mesh; since our blocks are
  separate meshes, the settings sit on the parts themselves, which gives the slicer the same regions.
* STL: one binary STL per block, millimetres, in the finger frame (import one finger's STLs as parts of
  one object to rebuild it).

All XML is built with ElementTree. Lengths in the files are millimetres; in the API, metres.
"""

from __future__ import annotations

import uuid
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import Block
from mjcodesign.errors import OutputError
from mjcodesign.fabrication.plan import INFILL_PATTERNS, SETTINGS, BlockPrint, PrintPlan

__all__ = ["Placement", "block_mesh", "placements", "write_prusa_3mf", "write_bambu_3mf", "write_stls"]

_MM_PER_M = 1000.0
_CORE_NS = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
_PROD_NS = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06"
_BAMBU_NS = "http://schemas.bambulab.com/package/2021"
_SLIC3R_NS = "http://schemas.slic3r.org/3mf/2017/06"
_REL_NS = "http://schemas.openxmlformats.org/package/2006/relationships"
_CT_NS = "http://schemas.openxmlformats.org/package/2006/content-types"
_REL_MODEL = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"
# PrusaSlicer's own 3MF version; 1 is what 2.5 writes and reads without transforming volumes back.
_PRUSA_3MF_VERSION = "1"
# Bambu Studio and OrcaSlicer read model_settings.config only from files whose Application starts with
# "BambuStudio-" (their bbs_3mf.cpp, as documented by third-party writers; not checked here). This is
# the version the authors' sim_finger.3mf was saved with.
_BAMBU_APPLICATION = "BambuStudio-02.00.02.57"
_BAMBU_SUBMODEL = "3D/Objects/object_1.model"
# Gap between the two fingers on the bed [m]: clear of each other's skirt and brim.
_FINGER_GAP = 0.010
# Where the pair is centred on the bed [m]: the middle of a 250 x 210 mm bed, inside most beds.
_BED_CENTRE = (0.125, 0.105)
# A fixed namespace makes the UUIDs the production extension asks for reproducible.
_UUID_NS = uuid.UUID("5b7c3f1e-9a7d-4c1e-8f0a-6d2b1c3e4f50")
_IDENTITY_4X4 = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"


@dataclass(frozen=True)
class Placement:
    """Where a finger's frame origin sits on the bed [m] (the finger is only translated)."""

    finger: int
    offset: tuple[float, float, float]


def block_mesh(block: Block) -> tuple[np.ndarray, np.ndarray]:
    """Closed, outward-wound triangle mesh of a block's prism in the finger frame.

    Returns vertices [m], shape (2n, 3), and triangles (vertex indices), shape (4n - 4, 3), for an
    n-sided side profile: two fan caps and two triangles per side.
    """
    v = block.vertices()
    n = len(v) // 2
    tris = []
    for i in range(1, n - 1):
        tris.append((0, i, i + 1))
        tris.append((n, n + i + 1, n + i))
    for i in range(n):
        j = (i + 1) % n
        tris.append((i, n + j, j))
        tris.append((i, n + i, n + j))
    f = np.array(tris, dtype=np.int64)
    if _signed_volume(v, f) < 0:
        f = f[:, ::-1].copy()
    return v, f


def placements(plan: PrintPlan) -> list[Placement]:
    """Bed position of each finger's frame origin [m]: side by side along y, centred on the bed."""
    d = plan.design
    n = len(plan.blocks)
    pitch = d.width + _FINGER_GAP
    y0 = _BED_CENTRE[1] - 0.5 * (n - 1) * pitch
    x0 = _BED_CENTRE[0] - 0.5 * d.length
    return [Placement(f, (x0, y0 + f * pitch, 0.0)) for f in range(n)]


def write_prusa_3mf(plan: PrintPlan, path: str | Path) -> Path:
    """Write the PrusaSlicer 3MF: one object per finger, one named volume with settings per block."""
    model = _model_root({"slic3rpe": _SLIC3R_NS})
    _meta(model, "slic3rpe:Version3mf", _PRUSA_3MF_VERSION)
    _meta(model, "Application", "mjcodesign")
    resources = ET.SubElement(model, _q("resources"))
    build = ET.SubElement(model, _q("build"))
    config = ET.Element("config")
    for place, finger in zip(placements(plan), plan.blocks, strict=True):
        oid = str(place.finger + 1)
        obj = ET.SubElement(resources, _q("object"), id=oid, name=_finger_name(finger), type="model")
        meshes = [block_mesh(b.block) for b in finger]
        _mesh(obj, meshes)
        ET.SubElement(build, _q("item"), objectid=oid, transform=_transform(place.offset), printable="1")
        cobj = ET.SubElement(config, "object", id=oid, instances_count="1")
        _cmeta(cobj, "object", "name", _finger_name(finger))
        _cmeta(cobj, "object", "layer_height", f"{plan.calibration.layer_height * _MM_PER_M:g}")
        first = 0
        for bp, (_, f) in zip(finger, meshes, strict=True):
            vol = ET.SubElement(cobj, "volume", firstid=str(first), lastid=str(first + len(f) - 1))
            first += len(f)
            _cmeta(vol, "volume", "name", bp.name)
            _cmeta(vol, "volume", "volume_type", "ModelPart")
            _cmeta(vol, "volume", "matrix", _IDENTITY_4X4)
            for key, value in bp.settings.items():
                _cmeta(vol, "volume", SETTINGS[key].prusa, SETTINGS[key].format(value))
            ET.SubElement(
                vol,
                "mesh",
                edges_fixed="0",
                degenerate_facets="0",
                facets_removed="0",
                facets_reversed="0",
                backwards_edges="0",
            )
    return _zip(
        path,
        {
            "3D/3dmodel.model": model,
            "Metadata/Slic3r_PE_model.config": config,
        },
    )


def write_bambu_3mf(plan: PrintPlan, path: str | Path) -> Path:
    """Write the Bambu Studio / OrcaSlicer 3MF: finger objects of block parts, ``model_settings.config``."""
    sub = _model_root({"BambuStudio": _BAMBU_NS, "p": _PROD_NS}, production=True)
    _meta(sub, "BambuStudio:3mfVersion", "1")
    sub_res = ET.SubElement(sub, _q("resources"))
    ET.SubElement(sub, _q("build"))
    model = _model_root({"BambuStudio": _BAMBU_NS, "p": _PROD_NS}, production=True)
    _meta(model, "Application", _BAMBU_APPLICATION)
    _meta(model, "BambuStudio:3mfVersion", "1")
    resources = ET.SubElement(model, _q("resources"))
    build = ET.SubElement(model, _q("build"), {_p("UUID"): _uuid("build")})
    config = ET.Element("config")
    n_blocks = sum(len(f) for f in plan.blocks)
    parents = []
    for place, finger in zip(placements(plan), plan.blocks, strict=True):
        pid = str(n_blocks + place.finger + 1)
        name = _finger_name(finger)
        parent = ET.SubElement(resources, _q("object"), {"id": pid, _p("UUID"): _uuid(name), "type": "model"})
        comps = ET.SubElement(parent, _q("components"))
        cobj = ET.SubElement(config, "object", id=pid)
        _bmeta(cobj, "name", name)
        _bmeta(cobj, "extruder", "1")
        _bmeta(cobj, "layer_height", f"{plan.calibration.layer_height * _MM_PER_M:g}")
        for bp in finger:
            _bambu_block(bp, str(place.finger * len(finger) + bp.block.index + 1), sub_res, comps, cobj)
        ET.SubElement(
            build,
            _q("item"),
            {
                "objectid": pid,
                _p("UUID"): _uuid(name + "/item"),
                "transform": _transform(place.offset),
                "printable": "1",
            },
        )
        parents.append(pid)
    plate = ET.SubElement(config, "plate")
    _bmeta(plate, "plater_id", "1")
    _bmeta(plate, "plater_name", "")
    _bmeta(plate, "locked", "false")
    for pid in parents:
        inst = ET.SubElement(plate, "model_instance")
        _bmeta(inst, "object_id", pid)
        _bmeta(inst, "instance_id", "0")
    rels = ET.Element("Relationships", {"xmlns": _REL_NS})
    ET.SubElement(rels, "Relationship", Target="/" + _BAMBU_SUBMODEL, Id="rel-1", Type=_REL_MODEL)
    return _zip(
        path,
        {
            "3D/3dmodel.model": model,
            _BAMBU_SUBMODEL: sub,
            "3D/_rels/3dmodel.model.rels": rels,
            "Metadata/model_settings.config": config,
        },
    )


def write_stls(plan: PrintPlan, directory: str | Path) -> list[Path]:
    """One binary STL per block [mm], in its finger's frame; returns the paths."""
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        out = []
        for bp in plan:
            v, f = block_mesh(bp.block)
            path = directory / f"{bp.name}.stl"
            path.write_bytes(_stl_bytes(v * _MM_PER_M, f, bp.name))
            out.append(path)
    except OSError as exc:
        raise OutputError(f"cannot write STL files to {directory}: {exc.strerror or exc}") from exc
    return out


# -- helpers ------------------------------------------------------------------------------------


def _bambu_block(bp: BlockPrint, bid: str, sub_res: ET.Element, comps: ET.Element, cobj: ET.Element) -> None:
    """One block of the Bambu 3MF: its mesh object, its finger's component and its settings part."""
    v, f = block_mesh(bp.block)
    mobj = ET.SubElement(sub_res, _q("object"), {"id": bid, _p("UUID"): _uuid(bp.name), "type": "model"})
    _mesh(mobj, [(v, f)])
    ET.SubElement(
        comps,
        _q("component"),
        {
            _p("path"): "/" + _BAMBU_SUBMODEL,
            "objectid": bid,
            _p("UUID"): _uuid(bp.name + "/component"),
            "transform": _transform((0.0, 0.0, 0.0)),
        },
    )
    part = ET.SubElement(cobj, "part", id=bid, subtype="normal_part")
    _bmeta(part, "name", bp.name)
    _bmeta(part, "matrix", _IDENTITY_4X4)
    for key, value in _bambu_settings(bp).items():
        _bmeta(part, key, value)
    ET.SubElement(
        part,
        "mesh_stat",
        face_count=str(len(f)),
        edges_fixed="0",
        degenerate_facets="0",
        facets_removed="0",
        facets_reversed="0",
        backwards_edges="0",
    )


def _bambu_settings(bp: BlockPrint) -> dict[str, str]:
    out = {}
    for key, value in bp.settings.items():
        spec = SETTINGS[key]
        text = spec.format(value)
        if key == "fill_pattern":
            text = INFILL_PATTERNS[str(value)]
        out[spec.bambu] = text
    return out


def _finger_name(finger: tuple[BlockPrint, ...]) -> str:
    return f"finger_{finger[0].name[0]}"


def _signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _q(tag: str) -> str:
    # Core-namespace elements are written unprefixed under a default xmlns (as the slicers write them).
    return tag


def _p(attr: str) -> str:
    return f"p:{attr}"


def _uuid(name: str) -> str:
    return str(uuid.uuid5(_UUID_NS, name))


def _model_root(namespaces: dict[str, str], production: bool = False) -> ET.Element:
    attrs = {"unit": "millimeter", "xml:lang": "en-US"}
    for prefix, uri in namespaces.items():
        attrs[f"xmlns:{prefix}"] = uri
    if production:
        attrs["requiredextensions"] = "p"
    return ET.Element("model", {"xmlns": _CORE_NS, **attrs})


def _meta(model: ET.Element, name: str, text: str) -> None:
    ET.SubElement(model, "metadata", name=name).text = text


def _cmeta(parent: ET.Element, type_: str, key: str, value: str) -> None:
    ET.SubElement(parent, "metadata", type=type_, key=key, value=value)


def _bmeta(parent: ET.Element, key: str, value: str) -> None:
    ET.SubElement(parent, "metadata", key=key, value=value)


def _mesh(obj: ET.Element, meshes: list[tuple[np.ndarray, np.ndarray]]) -> None:
    mesh = ET.SubElement(obj, _q("mesh"))
    verts = ET.SubElement(mesh, _q("vertices"))
    tris = ET.SubElement(mesh, _q("triangles"))
    base = 0
    for v, f in meshes:
        for x, y, z in v * _MM_PER_M:
            ET.SubElement(verts, _q("vertex"), x=f"{x:.6f}", y=f"{y:.6f}", z=f"{z:.6f}")
        for a, b, c in f + base:
            ET.SubElement(tris, _q("triangle"), v1=str(a), v2=str(b), v3=str(c))
        base += len(v)


def _transform(offset: tuple[float, float, float]) -> str:
    x, y, z = (o * _MM_PER_M for o in offset)
    return f"1 0 0 0 1 0 0 0 1 {x:.6f} {y:.6f} {z:.6f}"


def _xml_bytes(root: ET.Element) -> bytes:
    # Names are plain or literally prefixed ("p:UUID") and xmlns are attributes, so ElementTree writes
    # them as they are, in the form the slicers' own files use.
    ET.indent(root, space=" ")
    text = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode("utf-8")


def _content_types() -> ET.Element:
    types = ET.Element("Types", {"xmlns": _CT_NS})
    ET.SubElement(
        types,
        "Default",
        Extension="rels",
        ContentType="application/vnd.openxmlformats-package.relationships+xml",
    )
    ET.SubElement(
        types,
        "Default",
        Extension="model",
        ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml",
    )
    return types


def _root_rels() -> ET.Element:
    rels = ET.Element("Relationships", {"xmlns": _REL_NS})
    ET.SubElement(rels, "Relationship", Target="/3D/3dmodel.model", Id="rel-1", Type=_REL_MODEL)
    return rels


def _zip(path: str | Path, parts: dict[str, ET.Element]) -> Path:
    path = Path(path)
    entries = {"[Content_Types].xml": _content_types(), "_rels/.rels": _root_rels(), **parts}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for name, root in entries.items():
                zf.writestr(name, _xml_bytes(root))
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path


def _stl_bytes(v: np.ndarray, f: np.ndarray, name: str) -> bytes:
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    rec = np.zeros(len(f), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = n
    rec["v"] = tri
    header = f"mjcodesign block {name} [mm]".encode("ascii")[:80].ljust(80, b" ")
    return header + np.uint32(len(f)).tobytes() + rec.tobytes()
