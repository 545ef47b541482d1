"""``mjcodesign design``: objects and masses, bad input, and a whole run on generated meshes.

The whole run uses the tiny checkpoint of ``conftest.py`` on two generated meshes (two candidates each,
one perturbed draw per object, design and disturbance), headless: no display and no ``MUJOCO_GL``, so
the command must choose an offscreen OpenGL backend itself. Its report is parsed (one table row per
object, one inline image per grasp, no external address) and, where a Chromium binary exists,
screenshotted headless; PrusaSlicer slices its 3MF where it is installed.
"""

import base64
import json
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from mjcodesign.cli import main as cli_main
from mjcodesign.errors import DesignError, MeshError, UnsupportedError
from mjcodesign.pipeline import GraspImages, parse_mass_text, parse_objects, png_bytes, read_masses

pytest.importorskip("torch")

_BUDGET = 24  # 2 objects × 4 designs × 3 disturbances: one draw each
_ADAPT = 6  # rollouts per object of the whole run's --adapt
_CHROMIUM = next(
    (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None
)
_PRUSA = shutil.which("prusa-slicer")


def _cli(*args, cwd, env=None):
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli", "design", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=600,
    )


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    import trimesh

    d = tmp_path_factory.mktemp("design_meshes")
    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(d / "box.stl")
    trimesh.creation.icosphere(radius=0.03).export(d / "ball.stl")
    (d / "broken.stl").write_bytes(b"not a mesh at all")
    return d


def test_masses_and_objects_parse(meshes, tmp_path):
    specs = parse_objects([f"{meshes / 'box.stl'}@120g", str(meshes / "ball.stl")], {"ball": 0.05})
    assert [(s.name, s.mass_kg) for s in specs] == [("box", pytest.approx(0.12)), ("ball", 0.05)]
    assert Path(specs[0].source).is_absolute()
    assert parse_mass_text("0.197kg", "x") == pytest.approx(0.197)
    csv = tmp_path / "m.csv"
    csv.write_text("object,mass\nbox,120g\nball , 0.2kg\n")
    assert read_masses(csv) == {"box": pytest.approx(0.12), "ball": pytest.approx(0.2)}
    for bad in ("120", "-3g", "0g", "30kg", "lots"):
        with pytest.raises(MeshError):
            parse_mass_text(bad, "x")
    with pytest.raises(MeshError, match="twice"):
        parse_objects([str(meshes / "box.stl"), str(meshes / "box.stl")])
    with pytest.raises(MeshError, match="not one of the objects"):
        parse_objects([str(meshes / "box.stl")], {"mug": 0.3})


def test_png_bytes_decode_to_the_image():
    import io

    from matplotlib.image import imread

    rgb = np.random.default_rng(0).integers(0, 256, size=(7, 5, 3), dtype=np.uint8)
    back = imread(io.BytesIO(png_bytes(rgb)), format="png")
    np.testing.assert_array_equal(np.round(back[..., :3] * 255).astype(np.uint8), rgb)


def test_the_backend_of_the_images_comes_from_the_environment_or_egl_without_a_display():
    from mjcodesign.cli.design import offscreen_gl

    headless = "egl" if sys.platform.startswith("linux") else None
    assert offscreen_gl({}) == headless
    assert offscreen_gl({"MUJOCO_GL": "OSMesa "}) == "osmesa" and offscreen_gl({"MUJOCO_GL": "egl"}) == "egl"
    assert offscreen_gl({"MUJOCO_GL": "enable"}) is None  # MuJoCo's own choice
    assert offscreen_gl({"DISPLAY": ":0"}) is None and offscreen_gl({"WAYLAND_DISPLAY": "w"}) is None
    with pytest.raises(UnsupportedError, match="OpenGL backend"):
        GraspImages(gl="vulkan")


# A process that imported MuJoCo with no display and no MUJOCO_GL (MuJoCo then chose GLFW, once) before
# the design runs, as pytest does when an earlier test module imports the pipeline: the images are still
# drawn, in the context the caller names, and MuJoCo's own choice fails in one line.
_RENDER_AFTER_IMPORT = """
import os, sys, types
import numpy as np
import mujoco
from mujoco.rendering.classic import gl_context
assert gl_context.GLContext.__module__ == "mujoco.glfw", gl_context.GLContext
from mjcodesign.cli.design import offscreen_gl
from mjcodesign.errors import UnsupportedError
from mjcodesign.pipeline import GraspImages
m = mujoco.MjModel.from_xml_string(
    '<mujoco><worldbody><light pos="0 0 1"/><body name="o"><freejoint/>'
    '<geom size=".03" rgba="1 0 0 1"/></body></worldbody></mujoco>')
d = mujoco.MjData(m)
state = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS))
mujoco.mj_getState(m, d, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
rollout = types.SimpleNamespace(label="optimised/ball", model=m, states=state[None], starts={"hold": 1},
                                x0=state, scene=types.SimpleNamespace(object_body=1))
images = GraspImages(gl=None if sys.argv[1] == "default" else offscreen_gl(os.environ))
try:
    images.rollout(rollout)
    print("png:", len(images.images["ball"]))
except UnsupportedError as exc:  # (MuJoCo aborts on a second context after a failed one: one try each)
    print("error:", str(exc).count("\\n"), exc)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="EGL and GLFW's no-display case are Linux's")
def test_grasp_images_render_in_a_process_that_imported_mujoco_first(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    out = {}
    for backend in ("default", "chosen"):
        r = subprocess.run(
            [sys.executable, "-c", _RENDER_AFTER_IMPORT, backend],
            capture_output=True,
            text=True,
            env=env,
            cwd=tmp_path,  # any MUJOCO_LOG.TXT of the failing backend lands here
            timeout=120,
        )
        assert r.returncode == 0, r.stderr[-3000:]
        out[backend] = r.stdout.strip().splitlines()[-1]
    assert out["default"].startswith("error: 0 MuJoCo cannot render off screen"), out  # one line
    assert out["chosen"].startswith("png: ") and int(out["chosen"][5:]) > 1000, out  # a 640 x 480 drawing


@pytest.mark.parametrize(
    "case, expect",
    [
        ("unknown object", "unknown object"),
        ("bad mass", "bad mass"),
        ("mass out of range", "must be in"),
        ("missing mesh", "not found"),
        ("unreadable mesh", "broken"),
        ("unwritable out", "not a writable folder"),
        ("out where no folder can be made", "not a writable folder"),
        ("no weights", "no pretrained surrogate ships"),
        ("budget below one draw", "--budget"),
        ("folder of other files", "not empty"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_no_folder(
    case, expect, meshes, tiny_checkpoint, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "out"
    box = str(meshes / "box.stl")
    args = {
        "unknown object": ["no_such_object_xyz", "--ckpt", tiny_checkpoint],
        "bad mass": [f"{box}@12apples", "--ckpt", tiny_checkpoint],
        "mass out of range": [f"{box}@25kg", "--ckpt", tiny_checkpoint],
        "missing mesh": [str(meshes / "nothing.stl"), "--ckpt", tiny_checkpoint],
        "unreadable mesh": [str(meshes / "broken.stl"), "--ckpt", tiny_checkpoint],
        "unwritable out": [box, "--ckpt", tiny_checkpoint],
        "out where no folder can be made": [box, "--ckpt", tiny_checkpoint],
        "no weights": [box],
        "budget below one draw": [box, "--ckpt", tiny_checkpoint, "--budget", "5"],
        "folder of other files": [box, "--ckpt", tiny_checkpoint],
    }[case]
    if case == "unwritable out":
        (tmp_path / "file").write_text("x")
        out = tmp_path / "file" / "out"
    if case == "out where no folder can be made":  # /proc: permission bits say writable to root
        out = Path("/proc/mjcodesign-no-such-folder/out")
    if case == "folder of other files":
        out.mkdir()
        (out / "notes.txt").write_text("mine")
    if case == "no weights":  # as in an installation that ships none
        from mjcodesign.surrogate import shipped

        monkeypatch.setattr(shipped, "shipped_checkpoint", lambda: None)
    monkeypatch.chdir(tmp_path)
    code = cli_main.main(["design", *map(str, args), "--out", str(out)])  # in process: no interpreter start
    r = capsys.readouterr()
    assert code == 2, r.err[-3000:]
    assert r.err.startswith("error: ") and r.err.count("\n") == 1 and expect in r.err, r.err
    assert r.out == ""
    if case == "folder of other files":  # left as it was
        assert [p.name for p in out.iterdir()] == ["notes.txt"] and (out / "notes.txt").read_text() == "mine"
        out = tmp_path / "nothing"
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) in ([], ["file"], ["out"])


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows, self.imgs, self.urls = 0, [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "tr" and a.get("class") == "object":
            self.rows += 1
        if tag == "img":
            self.imgs.append(a)
        for key in ("src", "href"):
            if key in a and not str(a[key]).startswith("data:image/png;base64,"):
                self.urls.append(a[key])


@pytest.fixture(scope="module")
def design_run(meshes, tiny_checkpoint, tmp_path_factory):
    """One whole run, headless, on the two generated meshes at 300 kg/m³ (inside the tiny surrogate's range),
    adapted first (``--adapt``) under a weak tendon pull, so that the adaptation rollouts hold some grasps
    and drop others."""
    work = tmp_path_factory.mktemp("design_run")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    env["XDG_CACHE_HOME"] = str(work / "cache")
    args = [
        f"{meshes / 'box.stl'}@36g",
        f"{meshes / 'ball.stl'}@34g",
        "--ckpt",
        tiny_checkpoint,
        "--out",
        work / "g",
    ]
    args += ["--poses-per-object", "2", "--budget", str(_BUDGET), "--max-iterations", "30", "--json"]
    args += [
        "--adapt",
        str(_ADAPT),
        "--tendon",
        "force:3",
    ]  # a weak pull: the adaptation rollouts both hold and drop
    r = _cli(*args, cwd=work, env=env)
    assert r.returncode == 0, r.stderr[-4000:]
    return work / "g", json.loads(r.stdout)


def test_design_writes_every_file(design_run):
    from mjcodesign.design.stiffness import Stiffness

    out, record = design_run
    design = Stiffness.parse((out / "design.txt").read_text().strip())
    np.testing.assert_allclose(design.log_e.ravel(), record["designs"]["box"], atol=1e-6)
    for name in ("box", "ball"):
        pose = json.loads((out / "poses" / f"{name}.json").read_text())
        assert np.shape(pose["pose"]) == (4, 4) and len(pose["openings"]) == 2
    for rel in ("print/gripper_prusaslicer.3mf", "print/gripper_bambu_orca.3mf", "print/print_sheet.md",
                "report.md", "report.html", "result.json", "figures/sweep.png", "figures/fingers.png",
                "figures/grasp_box.png", "figures/grasp_ball.png"):  # fmt: skip
        assert (out / rel).is_file() and (out / rel).stat().st_size > 0, rel
    assert list((out / "print" / "stl").glob("*.stl"))
    if record["rrd"] is not None:
        assert (out / "run.rrd").stat().st_size > 0
    box = next(o for o in record["objects"] if o["name"] == "box")
    assert box["mass_kg"] == pytest.approx(0.036) and box["mass_given"]


def test_the_run_says_whether_it_adapted(design_run):
    out, record = design_run
    a = record["adapt"]
    assert a["rollouts_per_object"] == _ADAPT and a["rollouts"] == 2 * _ADAPT
    assert a["samples"] + a["sample_errors"] == a["rollouts"]
    assert a["adapted"] and 0 < a["successes"] < a["samples"]  # both outcomes: something to learn
    assert a["split"]["mode"] == "pose" and set(a["held_out"]) == {"before", "after"}
    from mjcodesign.surrogate import load_surrogate

    adapted = load_surrogate(out / "surrogate")  # the network the design went through, a --ckpt folder
    assert a["checkpoint"] == str(out / "surrogate") and adapted.meta["adapt"]["samples"] == a["samples"]
    assert record["simulation"]["tendon"] == "force:3"
    assert a["summary"] in (out / "report.md").read_text(encoding="utf-8") and a["checkpoint"] in (
        out / "report.md"
    ).read_text(encoding="utf-8")
    assert a["summary"] in (out / "report.html").read_text(encoding="utf-8")


def test_verification_counts_every_rollout(design_run):
    _, record = design_run
    v = record["verification"]
    assert v["designs"] == ["optimised", "soft", "semi-rigid", "paper-optimized"]
    assert v["draws"] == 1 and v["rollouts"] == _BUDGET
    assert len(v["cells"]) == 2 * 4 * 3
    for c in v["cells"]:
        assert c["successes"] <= c["valid"] <= 1 and c["valid"] + c["sample_errors"] == 1
        assert 0.0 <= c["p"]["low"] <= c["p"]["value"] <= c["p"]["high"] <= 1.0
    # the sweep pools the objects: its counts are the cells' sums
    for s in v["sweep"]:
        cells = [
            c
            for c in v["cells"]
            if (c["design"], c["impulse_paper_ns"]) == (s["design"], s["impulse_paper_ns"])
        ]
        assert (s["successes"], s["valid"]) == (
            sum(c["successes"] for c in cells),
            sum(c["valid"] for c in cells),
        )


def test_report_html_is_self_contained_with_a_row_and_an_image_per_object(design_run):
    out, record = design_run
    page = _Page()
    page.feed((out / "report.html").read_text(encoding="utf-8"))
    assert page.rows == len(record["objects"]) == 2
    grasps = [a for a in page.imgs if a.get("class") == "grasp"]
    assert len(grasps) == 2 and page.urls == []
    for a in grasps:  # a real rendering: a PNG of the stated size, not one flat colour
        import io

        from matplotlib.image import imread

        img = imread(io.BytesIO(base64.b64decode(a["src"].split(",", 1)[1])), format="png")
        assert img.shape[:2] == (480, 640) and img[..., :3].std() > 0.02
    assert not re.search(r"https?://", (out / "report.html").read_text(encoding="utf-8"))


@pytest.mark.skipif(
    _CHROMIUM is None, reason="no chromium binary (setup.sh installs it: apt-get install -y chromium)"
)
def test_report_html_opens_in_headless_chromium(design_run, tmp_path):
    out, record = design_run
    shot = tmp_path / "shot.png"
    cmd = [
        _CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        f"--screenshot={shot}",
        "--window-size=1200,2400",
    ]
    r = subprocess.run(
        [*cmd, (out / "report.html").resolve().as_uri()], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0 and shot.stat().st_size > 10_000, r.stderr[-2000:]
    dump = subprocess.run([_CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom",
                           (out / "report.html").resolve().as_uri()], capture_output=True, text=True, timeout=120)  # fmt: skip
    page = _Page()
    page.feed(dump.stdout)
    assert page.rows == len(record["objects"]) and sum(a.get("class") == "grasp" for a in page.imgs) == 2


@pytest.mark.skipif(_PRUSA is None, reason="prusa-slicer is not on PATH")
def test_prusaslicer_slices_the_design_s_3mf(design_run, tmp_path):
    out, _ = design_run
    sheet = json.loads((out / "print" / "print_sheet.json").read_text())
    first = sheet["calibration"]["first_layer_height_mm"]
    cmd = [
        _PRUSA,
        "--export-gcode",
        "--dont-arrange",
        "--loglevel",
        "1",
        "--first-layer-height",
        f"{first:g}",
    ]
    r = subprocess.run([*cmd, "--output", str(tmp_path / "g.gcode"), str(out / "print" / "gripper_prusaslicer.3mf")],
                       capture_output=True, text=True, timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert re.search(r"^; filament used \[mm\] = [\d.]+", (tmp_path / "g.gcode").read_text(), re.M)


_NO_CKPT = {  # every command that reads a surrogate, without --ckpt (hw grasp: a bare --surrogate)
    "predict": ["predict", "--object", "box.stl", "--pose", "auto", "--design", "soft"],
    "optimize": ["optimize", "--objects", "box.stl", "--poses", "cands.npz", "--no-ground-truth", "--out", "o"],
    "evaluate": ["evaluate", "--designs", "soft", "--objects", "box.stl", "--pose-sampling", "surrogate",
                 "--out", "o"],
    "hw grasp": ["hw", "grasp", "--dry-run", "--surrogate", "--design", "soft", "--cloud", "cloud.npy"],
    "design": ["design", "box.stl", "--out", "o"],
}  # fmt: skip


@pytest.mark.parametrize("command", sorted(_NO_CKPT))
def test_without_a_checkpoint_every_command_says_no_weights_ship(
    command, meshes, tmp_path, capsys, monkeypatch
):
    from mjcodesign.surrogate import shipped

    monkeypatch.setattr(shipped, "shipped_checkpoint", lambda: None)  # as while no weights ship
    shutil.copy(meshes / "box.stl", tmp_path / "box.stl")
    np.save(tmp_path / "cloud.npy", np.random.default_rng(0).random((64, 3)))
    monkeypatch.chdir(tmp_path)
    code = cli_main.main(_NO_CKPT[command])
    r = capsys.readouterr()
    assert code == 2 and r.err.count("\n") == 1 and r.out == "", r.err[-2000:]
    flag = "--surrogate" if command == "hw grasp" else "--ckpt"
    assert r.err.startswith("error: no pretrained surrogate ships") and f"pass {flag} ckpt" in r.err
    assert "mjcodesign train" in r.err and sorted(p.name for p in tmp_path.iterdir()) == [
        "box.stl",
        "cloud.npy",
    ]


def test_without_ckpt_predict_reads_the_shipped_weights(
    meshes, tiny_checkpoint, tmp_path, capsys, monkeypatch
):
    from mjcodesign.surrogate import shipped

    monkeypatch.setattr(shipped, "shipped_checkpoint", lambda: Path(tiny_checkpoint))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    argv = ["predict", "--object", str(meshes / "box.stl"), "--pose", "auto", "--design", "soft", "--json"]
    assert cli_main.main(argv) == 0
    without = json.loads(capsys.readouterr().out)
    assert cli_main.main([*argv, "--ckpt", str(tiny_checkpoint)]) == 0
    assert json.loads(capsys.readouterr().out) == without


def _adapt_inputs(n_poses: int):
    """Two objects' poses (random clouds of the tiny checkpoint's 256 points) and a rollout stand-in."""
    from types import SimpleNamespace

    from mjcodesign.codesign import PoseSet

    rng = np.random.default_rng(0)
    p = 2 * n_poses
    poses = PoseSet(
        ("a", "b"),
        np.repeat([0, 1], n_poses),
        (0.03 * rng.standard_normal((p, 256, 3))).astype(np.float32),
        np.zeros((p, 3)),
        np.tile(np.eye(4), (p, 1, 1)),
        np.full((p, 2), 0.05),
        np.full(p, 1.2e-4),
    )

    def rollouts(poses, objs, rho, scenario, model, n, seed, say, succeed=None):
        rows = np.repeat(np.arange(len(poses)), n // n_poses)
        log_e = np.random.default_rng(seed).uniform(13.5, 17.0, (len(rows), 22))
        ok = log_e.mean(axis=1) > 15.25 if succeed is None else np.full(len(rows), succeed)
        outs = [
            SimpleNamespace(body_force=(0, 0, 0, 0, 0, 0.3 * s), displacement=(0, 0, 0.002 * (1 - s)),
                            ground_contact=not s, success=bool(s))
            for s in ok
        ]  # fmt: skip
        return rows, log_e, outs, 0

    return poses, rollouts


def test_adapt_fine_tunes_on_held_out_poses_and_keeps_the_checkpoint(tiny_checkpoint, monkeypatch):
    import torch

    from mjcodesign.pipeline import adapt
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.surrogate import load_surrogate

    base = load_surrogate(tiny_checkpoint)
    before = {k: v.clone() for k, v in base.model.state_dict().items()}
    poses, rollouts = _adapt_inputs(4)
    monkeypatch.setattr(adapt, "_rollouts", rollouts)
    monkeypatch.setattr(adapt, "ADAPT_EPOCHS", 5)  # seconds: the test checks the path, not convergence
    rho = {"a": 300.0, "b": 300.0}
    net, rec = adapt.adapt_surrogate(base, poses, {}, rho, GraspScenario(), None, 40, seed=1)
    assert rec["adapted"] and rec["lr"] == adapt.ADAPT_LR == 1e-4 and rec["samples"] == 80
    split = rec["split"]
    assert split["mode"] == "pose" and split["train"] + split["val"] + split["test"] == 80
    assert sum(split["poses"].values()) == 8 and min(split["poses"].values()) >= 1  # whole poses
    for part in ("before", "after"):
        assert np.isfinite(rec["held_out"][part]["loss"])
    assert rec["held_out"]["after"]["loss"] != rec["held_out"]["before"]["loss"]
    assert net is not base and net.meta["adapt"] is rec and net.normalizer is base.normalizer
    assert any(not torch.equal(v, net.model.state_dict()[k]) for k, v in before.items())
    assert all(torch.equal(v, base.model.state_dict()[k]) for k, v in before.items())  # the base untouched
    assert "adapted on 40 rollouts per object" in adapt.summary_line(rec)


@pytest.mark.parametrize("succeed", [True, False])
def test_adapt_with_one_outcome_only_keeps_the_checkpoint_and_says_why(succeed, tiny_checkpoint, monkeypatch):
    import functools

    from mjcodesign.pipeline import adapt
    from mjcodesign.scenarios.grasp import GraspScenario
    from mjcodesign.surrogate import load_surrogate

    base = load_surrogate(tiny_checkpoint)
    poses, rollouts = _adapt_inputs(3)
    monkeypatch.setattr(adapt, "_rollouts", functools.partial(rollouts, succeed=succeed))
    net, rec = adapt.adapt_surrogate(base, poses, {}, {"a": 300.0, "b": 300.0}, GraspScenario(), None, 6)
    assert net is base and not rec["adapted"] and "nothing to learn" in rec["reason"]
    assert ("every one succeeded" if succeed else "none succeeded") in rec["reason"]
    with pytest.raises(DesignError, match="3 or more"):
        adapt.adapt_surrogate(base, _adapt_inputs(1)[0], {}, {}, GraspScenario(), None, 6)
    calls = []
    monkeypatch.setattr(adapt, "_rollouts", lambda *a: calls.append(a))
    with pytest.raises(DesignError, match="training range"):  # before any rollout, as the co-design would
        adapt.adapt_surrogate(base, poses, {}, {"a": 300.0, "b": 2000.0}, GraspScenario(), None, 6)
    assert calls == []


def test_adapt_below_zero_is_refused_in_one_line(meshes, tiny_checkpoint, tmp_path, capsys, monkeypatch):
    from mjcodesign.pipeline import DesignOptions

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        cli_main.main(["design", str(meshes / "box.stl"), "--ckpt", str(tiny_checkpoint), "--adapt", "-1",
                       "--out", "o"])  # fmt: skip
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.startswith("error: argument --adapt") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(DesignError, match="--adapt"):
        DesignOptions(adapt=-1)
