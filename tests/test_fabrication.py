"""Fabrication export: calibration tables, stiffness -> print settings, 3MF/STL files, a real slicer."""

from __future__ import annotations

import collections
import json
import math
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.design.finger import BlockKind, FingerDesign
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, Stiffness
from mjcodesign.errors import CalibrationError
from mjcodesign.fabrication.plan import INFILL_PATTERNS, SETTINGS, Calibration, plan_print
from mjcodesign.fabrication.print3mf import (
    block_mesh,
    placements,
    write_bambu_3mf,
    write_prusa_3mf,
    write_stls,
)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TOML = ROOT / "mjcodesign" / "fabrication" / "calibration_tpu95a.toml"
AUTHORS_3MF = Path("/work/shared/reference/codesign-soft-gripper/hardware/sim_finger.3mf")
CORE = "{http://schemas.microsoft.com/3dmanufacturing/core/2015/02}"
_ROUND_TRIP_TOL = 1e-12  # exp(log(E)) round-off only
_MM = 1e3


def _toml(**replace: str) -> str:
    """The default table with whole lines replaced: key -> new line (matched on 'key =' at line start)."""
    text = DEFAULT_TOML.read_text()
    for key, line in replace.items():
        text, n = re.subn(rf"(?m)^{key} =.*$", line, text, count=1)
        assert n == 1, key
    return text


# -- calibration ----------------------------------------------------------------------------------


def test_default_calibration_is_a_labelled_monotone_example_spanning_the_paper_range():
    cal = Calibration.default()
    assert cal.example and "example" in cal.name.lower()
    for curve in (cal.segment, cal.flexure):
        assert np.all(np.diff(curve.settings) > 0)
        assert np.all(np.diff(curve.young) > 0)
        # 0.7-24 MPa: the printable range of log E 13.5-17 (to the table's two digits).
        assert curve.young[0] <= math.exp(LOG_E_MIN) and curve.young[-1] >= 0.99 * math.exp(LOG_E_MAX)
    assert cal.segment.parameter == "fill_density" and cal.segment.unit == "%"
    assert cal.flexure.parameter == "bottom_solid_layers" and cal.flexure.unit == "layers"
    assert Calibration.load(DEFAULT_TOML).segment.young.tolist() == cal.segment.young.tolist()


@pytest.mark.parametrize(
    ("replace", "message"),
    [
        (
            {
                "young_mpa": "young_mpa = [0.70, 0.74, 0.84, 0.96, 1.11, 1.29, 1.82, 2.47, 4.09, 3.00, 8.39, "
                "10.99, 17.00, 24.00]"
            },
            "not monotone",
        ),
        ({"young_mpa": "# young_mpa removed"}, "missing 'young_mpa'"),
        ({"setting": "# setting removed"}, "missing 'setting'"),
        ({"setting": "setting = [0, 2, 4]"}, "3 rows but young_mpa has 14"),
        ({"setting": "setting = [0, 2, 4, 6, 8, 10, 15, 20, 30, 40, 50, 60, 80, 80]"}, "strictly increasing"),
        ({"setting": "setting = [0, 2, 4, 6, 8, 10, 15, 20, 30, 40, 50, 60, 80, 99.5]"}, "step grid"),
        ({"unit": 'unit = "mm"'}, "does not match fill_density"),
        ({"parameter": 'parameter = "nozzle_temperature"'}, "is not one of"),
        ({"fixed": 'fixed = { fill_pattern = "hexagons" }'}, "not a known pattern"),
        ({"fixed": "fixed = { ironing = 1 }"}, "fixed setting 'ironing'"),
        ({"layer_height_mm": "layer_height_mm = 200"}, "layer_height_mm"),
    ],
)
def test_bad_calibration_tables_raise_a_calibration_error(replace, message):
    with pytest.raises(CalibrationError, match=re.escape(message)):
        Calibration.from_toml(_toml(**replace))


def test_calibration_file_that_is_not_toml_or_missing_raises(tmp_path):
    with pytest.raises(CalibrationError, match="not valid TOML"):
        Calibration.from_toml("[segment\n")
    with pytest.raises(CalibrationError, match="cannot read"):
        Calibration.load(tmp_path / "absent.toml")


# -- mapping --------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", list(BlockKind))
def test_every_table_row_maps_back_to_itself_with_zero_error(kind):
    curve = Calibration.default().curve(kind)
    for setting, young in zip(curve.settings, curve.young, strict=True):
        chosen, achieved, clamped = curve.nearest(float(young))
        assert chosen == setting and not clamped
        assert abs(achieved / young - 1) < _ROUND_TRIP_TOL


def test_plan_round_trip_through_stiffness_on_table_rows():
    cal = Calibration.default()
    seg = [float(np.log(e)) for e in cal.segment.young if LOG_E_MIN <= np.log(e) <= LOG_E_MAX]
    flex = [float(np.log(e)) for e in cal.flexure.young if LOG_E_MIN <= np.log(e) <= LOG_E_MAX]
    log_e = [seg[i % len(seg)] if i % 2 == 0 else flex[i % len(flex)] for i in range(11)]
    plan = plan_print(Stiffness(log_e), cal)
    for b in plan:
        curve = cal.curve(b.block.kind)
        row = int(np.argmin(np.abs(np.log(curve.young) - b.log_e)))
        assert b.setting == curve.settings[row]
        assert abs(b.rel_error) < _ROUND_TRIP_TOL


def test_nearest_setting_is_the_best_on_the_grid_and_clamps_outside():
    curve = Calibration.default().segment
    grid = np.arange(curve.settings[0], curve.settings[-1] + 1, curve.step)
    for log_e in np.linspace(13.5, 17.0, 37):
        chosen, achieved, _ = curve.nearest(math.exp(log_e))
        errors = np.abs(np.log(curve.young_at(grid)) - log_e)
        assert abs(math.log(achieved) - log_e) <= errors.min() + 1e-12
        assert chosen in grid
    chosen, _, clamped = curve.nearest(1e9)
    assert chosen == curve.settings[-1] and clamped


def test_stiffer_design_gets_denser_settings():
    cal = Calibration.default()
    soft = plan_print(Stiffness.parse("soft"), cal)
    stiff = plan_print(Stiffness.parse("semi-rigid"), cal)
    for a, b in zip(soft, stiff, strict=True):
        assert b.setting > a.setting
    assert soft.max_abs_rel_error < 0.25 and stiff.max_abs_rel_error < 0.25


# -- files ----------------------------------------------------------------------------------------


def test_block_meshes_are_closed_and_have_the_block_volume():
    trimesh = pytest.importorskip("trimesh")
    for block in FingerDesign().blocks():
        v, f = block_mesh(block)
        mesh = trimesh.Trimesh(v, f, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume == pytest.approx(block.volume, rel=1e-12)  # volume > 0: outward winding


@pytest.fixture(scope="module")
def paper_plan():
    return plan_print(Stiffness.parse("paper-optimized"), Calibration.default())


def test_prusaslicer_3mf_has_named_block_volumes_in_millimetres_with_their_settings(tmp_path, paper_plan):
    path = write_prusa_3mf(paper_plan, tmp_path / "g.3mf")
    with zipfile.ZipFile(path) as z:
        assert {
            "[Content_Types].xml",
            "_rels/.rels",
            "3D/3dmodel.model",
            "Metadata/Slic3r_PE_model.config",
        } <= set(z.namelist())
        model = ET.fromstring(z.read("3D/3dmodel.model"))
        config = ET.fromstring(z.read("Metadata/Slic3r_PE_model.config"))
    assert model.get("unit") == "millimeter"
    objects = model.findall(f"{CORE}resources/{CORE}object")
    assert [o.get("name") for o in objects] == ["finger_A", "finger_B"]
    design = paper_plan.design
    for obj, cobj, finger in zip(objects, config.findall("object"), paper_plan.blocks, strict=True):
        xyz = np.array([[float(v.get(k)) for k in "xyz"] for v in obj.iter(f"{CORE}vertex")])
        np.testing.assert_allclose(xyz.min(0), [0, -design.width / 2 * _MM, 0], atol=1e-6)
        top = [design.length * _MM, design.width / 2 * _MM, design.height_base * _MM]
        np.testing.assert_allclose(xyz.max(0), top, atol=1e-6)
        n_tri = len(obj.findall(f"{CORE}mesh/{CORE}triangles/{CORE}triangle"))
        volumes = cobj.findall("volume")
        assert int(volumes[0].get("firstid")) == 0 and int(volumes[-1].get("lastid")) == n_tri - 1
        for vol, bp in zip(volumes, finger, strict=True):
            meta = {m.get("key"): m.get("value") for m in vol.findall("metadata")}
            assert meta["name"] == bp.name and meta["volume_type"] == "ModelPart"
            if bp.block.kind is BlockKind.SEGMENT:
                assert meta["fill_density"] == f"{bp.setting:g}%"
            else:
                assert meta["bottom_solid_layers"] == str(int(bp.setting))
                assert meta["fill_density"] == "0%"


def test_bambu_orca_3mf_puts_block_settings_on_parts_of_component_objects(tmp_path, paper_plan):
    path = write_bambu_3mf(paper_plan, tmp_path / "g.3mf")
    with zipfile.ZipFile(path) as z:
        model = ET.fromstring(z.read("3D/3dmodel.model"))
        sub = ET.fromstring(z.read("3D/Objects/object_1.model"))
        config = ET.fromstring(z.read("Metadata/model_settings.config"))
        assert "3D/_rels/3dmodel.model.rels" in z.namelist()
    meta = {m.get("name"): m.text for m in model.findall(f"{CORE}metadata")}
    assert meta["Application"].startswith("BambuStudio-")
    assert model.get("unit") == sub.get("unit") == "millimeter"
    meshes = {o.get("id") for o in sub.findall(f"{CORE}resources/{CORE}object")}
    for obj, cobj, finger in zip(
        model.findall(f"{CORE}resources/{CORE}object"),
        config.findall("object"),
        paper_plan.blocks,
        strict=True,
    ):
        assert obj.get("id") == cobj.get("id")
        comps = [c.get("objectid") for c in obj.iter(f"{CORE}component")]
        parts = cobj.findall("part")
        assert [p.get("id") for p in parts] == comps and set(comps) <= meshes
        for part, bp in zip(parts, finger, strict=True):
            m = {x.get("key"): x.get("value") for x in part.findall("metadata")}
            assert m["name"] == bp.name and part.get("subtype") == "normal_part"
            if bp.block.kind is BlockKind.SEGMENT:
                assert m["sparse_infill_density"] == f"{bp.setting:g}%"
                assert m["sparse_infill_pattern"] == "gyroid"
            else:
                assert m["bottom_shell_layers"] == str(int(bp.setting))


@pytest.mark.skipif(not AUTHORS_3MF.exists(), reason="authors' sim_finger.3mf is not on this machine")
def test_bambu_vocabulary_covers_the_authors_per_block_settings():
    with zipfile.ZipFile(AUTHORS_3MF) as z:
        config = ET.fromstring(z.read("Metadata/model_settings.config"))
    keys, patterns = set(), set()
    for part in config.iter("part"):
        if part.get("subtype") != "modifier_part":
            continue
        for m in part.findall("metadata"):
            keys.add(m.get("key"))
            if m.get("key") == "sparse_infill_pattern":
                patterns.add(m.get("value"))
    stiffness_keys = {k for k in keys if k not in {"name", "matrix"} and not k.endswith("line_width")}
    assert stiffness_keys <= {s.bambu for s in SETTINGS.values()}
    assert patterns <= set(INFILL_PATTERNS.values())


def test_stl_per_block_in_millimetres(tmp_path, paper_plan):
    paths = write_stls(paper_plan, tmp_path / "stl")
    assert len(paths) == 22 and paths[1].name == "A01_flexure.stl"
    v, f = block_mesh(paper_plan.blocks[0][1].block)
    data = paths[1].read_bytes()
    n = int(np.frombuffer(data[80:84], "<u4")[0])
    assert n == len(f) and len(data) == 84 + 50 * n
    tri = np.frombuffer(data[84:], dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])["v"]
    np.testing.assert_allclose(tri.reshape(-1, 3).max(0), v.max(0) * _MM, atol=1e-4)


# -- command line ---------------------------------------------------------------------------------


def _cli(*args: str) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
    }
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", "export-print", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )


def test_cli_writes_files_and_prints_per_block_json(tmp_path):
    out = tmp_path / "out"
    r = _cli("--design", "paper-optimized", "--calibration", str(DEFAULT_TOML), "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    report = json.loads(r.stdout)
    assert len(report["blocks"]) == 22
    for b in report["blocks"]:
        assert {"log_e", "setting", "achieved_e", "rel_error"} <= set(b)
        assert b["rel_error"] == pytest.approx(b["achieved_e"] / math.exp(b["log_e"]) - 1)
    for name in ("gripper_prusaslicer.3mf", "gripper_bambu_orca.3mf", "print_sheet.json", "print_sheet.md"):
        assert (out / name).is_file()
    assert len(list((out / "stl").glob("*.stl"))) == 22
    assert "EXAMPLE" in (out / "print_sheet.md").read_text()


def _bad_calibration(tmp_path: Path, **replace: str) -> str:
    path = tmp_path / "cal.toml"
    path.write_text(_toml(**replace))
    return str(path)


@pytest.mark.parametrize(
    "case",
    ["unknown-preset", "non-monotone", "missing-column", "unwritable-out", "missing-calibration-file"],
)
def test_cli_bad_input_exits_2_with_one_line(tmp_path, case):
    args = {"--design": "soft", "--out": str(tmp_path / "out")}
    if case == "unknown-preset":
        args["--design"] = "squishy"
    elif case == "non-monotone":
        reversed_e = (
            "young_mpa = [24, 17, 10.99, 8.39, 6.08, 4.09, 2.47, 1.82, 1.29, 1.11, 0.96, 0.84, 0.74, 0.7]"
        )
        args["--calibration"] = _bad_calibration(tmp_path, young_mpa=reversed_e)
    elif case == "missing-column":
        args["--calibration"] = _bad_calibration(tmp_path, setting="# no setting column")
    elif case == "unwritable-out":
        blocker = tmp_path / "file"
        blocker.write_text("")
        args["--out"] = str(blocker / "out")  # a directory under a regular file: fails even as root
    else:
        args["--calibration"] = str(tmp_path / "nope.toml")
    r = _cli(*[x for kv in args.items() for x in kv])
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert r.stdout == ""


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_export_failing_midway_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    from mjcodesign.errors import OutputError
    from mjcodesign.fabrication import export as export_module
    from mjcodesign.fabrication import export_print

    out = tmp_path / "out"
    export_print("soft", None, out)  # a complete earlier export in the folder
    before = _tree(out)

    def full_disk(plan, directory):  # the STLs fail once both 3MF files have been written
        raise OutputError(f"cannot write STL files to {directory}: No space left on device")

    monkeypatch.setattr(export_module, "write_stls", full_disk)
    with pytest.raises(OutputError, match="No space left"):
        export_print("paper-optimized", None, out)
    assert _tree(out) == before  # the old set, whole: no new 3MF beside old STLs
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".")] == []  # no staging folder left
    fresh = tmp_path / "new" / "out"
    with pytest.raises(OutputError):
        export_print("paper-optimized", None, fresh)
    assert not (tmp_path / "new").exists()  # the folders it made are gone again


def test_cli_module_imports_no_numpy():
    code = "import sys, mjcodesign.cli.fabrication; print('numpy' in sys.modules)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert r.stdout.strip() == "False", r.stderr


# -- a real slicer --------------------------------------------------------------------------------

PRUSA = shutil.which("prusa-slicer")
needs_prusa = pytest.mark.skipif(
    PRUSA is None,
    reason="prusa-slicer is not on PATH (apt-get install -y --no-install-recommends prusa-slicer)",
)


def _slice(plan, tmp_path: Path, name: str) -> str:
    src = write_prusa_3mf(plan, tmp_path / f"{name}.3mf")
    gcode = tmp_path / f"{name}.gcode"
    cal = plan.calibration
    # The 3MF sets layer_height per object; the first layer height is a printer setting (print sheet).
    first = ["--first-layer-height", f"{cal.first_layer_height * _MM:g}"]
    cmd = [PRUSA, "--export-gcode", "--dont-arrange", "--gcode-comments", "--loglevel", "1", *first]
    cmd += ["--output", str(gcode), str(src)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return gcode.read_text()


def _filament_mm(gcode: str) -> float:
    return float(re.search(r"^; filament used \[mm\] = ([\d.]+)", gcode, re.M).group(1))


def _extrusions(gcode: str):
    """(z [mm], ;TYPE, x_mid, y_mid, filament [mm]) of every extruding move."""
    rel, x, y, z, e, kind, out = False, 0.0, 0.0, 0.0, 0.0, None, []
    for line in gcode.splitlines():
        if line.startswith(";TYPE:"):
            kind = line[6:].strip()
        elif line.startswith(";Z:"):
            z = float(line[3:])
        words = line.split(";")[0].split()
        if not words:
            continue
        if words[0] in ("M82", "M83"):
            rel = words[0] == "M83"
        elif words[0] == "G92":
            e = next((float(w[1:]) for w in words[1:] if w[0] == "E"), e)
        elif words[0] in ("G0", "G1"):
            val = {w[0]: float(w[1:]) for w in words[1:] if w[0] in "XYE"}
            nx, ny = val.get("X", x), val.get("Y", y)
            if "E" in val:
                de = val["E"] if rel else val["E"] - e
                e = e if rel else val["E"]
                if de > 0 and (nx, ny) != (x, y):
                    out.append((z, kind, 0.5 * (x + nx), 0.5 * (y + ny), de))
            x, y = nx, ny
    return out


@needs_prusa
def test_prusaslicer_stiffer_design_uses_more_filament(tmp_path):
    cal = Calibration.default()
    soft = _filament_mm(_slice(plan_print(Stiffness.parse("soft"), cal), tmp_path, "soft"))
    stiff = _filament_mm(_slice(plan_print(Stiffness.parse("semi-rigid"), cal), tmp_path, "semi"))
    assert stiff > 1.5 * soft, (soft, stiff)


@needs_prusa
def test_prusaslicer_gcode_shows_each_blocks_settings(tmp_path, paper_plan):
    moves = _extrusions(_slice(paper_plan, tmp_path, "paper"))
    d = paper_plan.design
    density, infill_per_volume = [], []
    for place, finger in zip(placements(paper_plan), paper_plan.blocks, strict=True):
        ox, oy, _ = (o * _MM for o in place.offset)
        for bp in finger:
            x0, x1 = ox + bp.block.x0 * _MM, ox + bp.block.x1 * _MM
            mine = [m for m in moves if x0 <= m[2] < x1 and abs(m[3] - oy) <= d.width / 2 * _MM]
            per_type = collections.Counter()
            solid_layers = set()
            for z, kind, _, _, de in mine:
                per_type[kind] += de
                if kind == "Solid infill" and z <= d.flexure_thickness * _MM + 1e-6:
                    solid_layers.add(z)
            if bp.block.kind is BlockKind.FLEXURE:
                # A flexure plate on the bed: N solid bottom layers over a hollow core (no sparse infill).
                assert len(solid_layers) == bp.setting, bp.name
                assert per_type["Internal infill"] == 0, bp.name
            else:
                density.append(bp.setting)
                infill_per_volume.append(per_type["Internal infill"] / (bp.block.volume * 1e9))
    # Sparse infill per block volume follows each block's own fill_density (gyroid: about linear).
    density, infill_per_volume = np.array(density), np.array(infill_per_volume)
    assert np.corrcoef(density, infill_per_volume)[0, 1] > 0.95
    for i in range(len(density)):
        for j in range(len(density)):
            if density[i] >= density[j] + 5:
                assert infill_per_volume[i] > infill_per_volume[j], (density[i], density[j])
