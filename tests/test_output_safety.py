"""Nothing of the user's is lost, and a damaged dataset is never read silently.

Output folders (:mod:`mjcodesign.outputs`): every command that writes a folder refuses one holding files
it did not write (a hidden file included) unless ``--overwrite``, which keeps them; refuses another
kind's output and its own inputs always; replaces its own earlier output whole, so a process killed with
SIGKILL at any moment leaves the old output or the new one.

Datasets (:mod:`mjcodesign.data.integrity`): a truncated, missing or swapped file (a copy of another
shard) is named by ``data info``, ``data verify`` and ``train``, and recomputed by ``datagen --resume``;
a dataset written before files carried hashes still reads.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from mjcodesign.cli import main as cli_main
from mjcodesign.errors import OutputError
from mjcodesign.outputs import MARKER, OutputKind, check_output, folder_kind, read_versioned_json, staged

ROOT = Path(__file__).resolve().parents[1]
_SCENARIO = '{"impulse": 0, "tighten_s": 0.1, "lift_s": 0.2, "hold_s": 0.1, "post_hold_s": 0.02}'
_DATAGEN = ("--poses-per-object", "2", "--designs-per-pose", "3", "--density", "uniform:100,400",
            "--scenario", _SCENARIO)  # fmt: skip
# The smallest network and run that train writes a whole checkpoint and report for (seconds here).
_TRAIN = ("--epochs", "2", "--batch-size", "8", "--hidden", "8", "--depth", "1", "--penultimate", "8",
          "--point-widths", "8,8", "--efficiency", "0", "--smoothness-poses", "0", "--split", "random",
          "--threads", "1")  # fmt: skip
_OPTIMIZE = ("--objects", "box", "--no-ground-truth", "--max-iterations", "3", "--patience", "2",
             "--top-b", "1", "--poses-per-object", "2")  # fmt: skip
_DESIGN = (
    "box.stl",
    "--poses-per-object",
    "2",
    "--budget",
    "12",
    "--max-iterations",
    "5",
)  # 1 object x 4 x 3
_KILL_WAIT_S = 120  # a train run here takes ~15 s; a kill point not reached by then fails the test


def _cli(capsys, *argv) -> tuple[int, str, list[str]]:
    try:
        code = cli_main.main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, [ln for ln in out.err.splitlines() if ln.strip()]


def _tree(folder: Path) -> dict[str, bytes | str]:
    """Every file, link and folder under ``folder`` with its content (a link: its target)."""
    out: dict[str, bytes | str] = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        out[rel] = os.readlink(p) if p.is_symlink() else (p.read_bytes() if p.is_file() else "<dir>")
    return out


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """Two meshes, a small dataset (2 objects x 2 poses x 3 designs) and a tiny checkpoint, by the CLI."""
    import trimesh

    d = tmp_path_factory.mktemp("output_safety")
    trimesh.creation.box(extents=(0.05, 0.04, 0.06)).export(d / "box.stl")
    trimesh.creation.icosphere(radius=0.03).export(d / "ball.stl")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CACHE_HOME", str(d / "cache"))
        mp.chdir(d)
        code = cli_main.main(["datagen", "--objects", "box.stl,ball.stl", *_DATAGEN, "--out", "ds"])
        assert code == 0
        assert cli_main.main(["train", "--data", "ds", "--out", "ck", *_TRAIN]) == 0
    return d


@pytest.fixture
def here(work, tmp_path, monkeypatch):
    """A fresh working folder with the meshes; the dataset and checkpoint are ``work``'s."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(work / "cache"))
    for name in ("box.stl", "ball.stl"):
        shutil.copy(work / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _commands(work: Path) -> dict[str, list[str]]:
    """One real command line per folder-writing command, without ``--out`` (tiny settings)."""
    return {
        "finger export": ["finger", "export", "--design", "soft"],
        "export-print": ["export-print", "--design", "soft"],
        "datagen": ["datagen", "--objects", "box.stl", *_DATAGEN],
        "train": ["train", "--data", work / "ds", *_TRAIN],
        "optimize": ["optimize", "--ckpt", work / "ck", "--poses", work / "ds", *_OPTIMIZE],
        "evaluate": ["evaluate", "--designs", "soft", "--objects", "012_strawberry", "--density", "light",
                     "--pose-sampling", "fixed", "--impulse", "0.1", "--candidates", "2"],
        "design": ["design", *_DESIGN, "--ckpt", work / "ck"],
    }  # fmt: skip


# -- folders it did not write --------------------------------------------------------------------------

_FOREIGN = {
    "hidden": {".notes": b"mine"},
    "hidden-tmp": {".draft.tmp": b"mine", ".lock": b""},  # names datagen once took for its own leftovers
    "same-names": {"notes.txt": b"mine", "poses/keep.json": b"{}", "design.txt": b"13.5",
                   "config.json": b"{}", "results.json": b"{}", "model.xml": b"<mine/>", "manifest.json": b"{}"},
}  # fmt: skip


@pytest.mark.parametrize("contents", sorted(_FOREIGN))
@pytest.mark.parametrize(
    "command", ["finger export", "export-print", "datagen", "train", "optimize", "evaluate", "design"]
)
def test_a_folder_it_did_not_write_is_refused_and_left_alone(command, contents, work, here, capsys):
    out = here / "user"
    for rel, data in _FOREIGN[contents].items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_bytes(data)
    before = _tree(out)
    code, stdout, err = _cli(capsys, *_commands(work)[command], "--out", out)
    assert code == 2 and len(err) == 1 and err[0].startswith("error: --out"), err
    assert "Traceback" not in err[0] and stdout == ""
    assert _tree(out) == before
    assert sorted(p.name for p in here.iterdir()) == ["ball.stl", "box.stl", "user"]  # no sibling left


def test_overwrite_writes_beside_the_users_files_and_a_rerun_keeps_them(work, here, capsys):
    out = here / "mine"
    (out / "poses" / "sub").mkdir(parents=True)
    out.chmod(0o750)
    (out / "poses" / "keep.txt").write_text("mine")
    (out / "poses" / "sub" / "x").write_text("mine too")
    (out / "design.txt").write_text("13.5")
    (out / "link").symlink_to("/nonexistent")
    argv = ["optimize", "--ckpt", work / "ck", "--poses", work / "ds", *_OPTIMIZE, "--out", out]
    assert _cli(capsys, *argv, "--overwrite")[0] == 0
    tree = _tree(out)
    assert tree["poses/keep.txt"] == b"mine" and tree["poses/sub/x"] == b"mine too"
    assert tree["link"] == "/nonexistent" and "poses/box.json" in tree
    assert tree["design.txt"] != b"13.5"  # the one same-named file: replaced, as --overwrite says
    marker = json.loads(tree[MARKER])
    assert marker["kind"] == "codesign" and "poses/keep.txt" not in marker["files"]
    # Its own output now: a rerun (another object) needs no flag, drops its own old file, keeps the user's.
    (out / "poses" / "late.txt").write_text("added later")
    argv[argv.index("box")] = "ball"
    assert _cli(capsys, *argv)[0] == 0
    tree = _tree(out)
    assert "poses/box.json" not in tree and "poses/ball.json" in tree
    assert tree["poses/keep.txt"] == b"mine" and tree["poses/late.txt"] == b"added later"
    assert tree["poses/sub/x"] == b"mine too" and tree["link"] == "/nonexistent"
    assert out.stat().st_mode & 0o777 == 0o750  # the folder replaced whole keeps its permissions


def test_design_overwrite_keeps_the_users_files_and_an_interrupted_rerun_the_old_output(
    work, here, capsys, monkeypatch
):
    from mjcodesign.pipeline import run as design_run

    out = here / "g"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    argv = ["design", *_DESIGN, "--ckpt", work / "ck", "--out", out]
    code, _, err = _cli(capsys, *argv, "--overwrite")
    assert code == 0, err
    first = _tree(out)
    assert first["notes.txt"] == b"mine" and "design.txt" in first and "report.html" in first
    assert (
        json.loads(first[MARKER])["kind"] == "design"
        and "notes.txt" not in json.loads(first[MARKER])["files"]
    )

    def interrupted(*_a, **_k):  # a Ctrl-C while the files are written
        raise KeyboardInterrupt

    # Its own output now: a rerun needs no flag (it gets as far as writing), and one interrupted while
    # writing leaves the first run's output whole, with no sibling folder.
    with monkeypatch.context() as mp:
        mp.setattr(design_run, "write_report", interrupted)
        code, _, err = _cli(capsys, *argv, "--seed", "1")
    assert code == 130 and err[-1] == "error: interrupted" and "verifying" in " ".join(err), err
    assert _tree(out) == first and sorted(p.name for p in here.iterdir()) == ["ball.stl", "box.stl", "g"]


def test_another_kind_and_an_input_are_refused_even_with_overwrite(work, here, capsys):
    ds, ck = work / "ds", work / "ck"
    before = _tree(ds), _tree(ck)
    cases = [
        ["train", "--data", ds, *_TRAIN, "--out", ds],  # the dataset it reads
        ["train", "--data", ds, *_TRAIN, "--out", ds / "ckpt"],  # inside it
        ["optimize", "--ckpt", ck, "--poses", ds, *_OPTIMIZE, "--out", ds],
        ["optimize", "--ckpt", ck, "--poses", ds, *_OPTIMIZE, "--out", ck],
        ["export-print", "--design", "soft", "--out", ck],  # a checkpoint is not a print
        ["finger", "export", "--out", ds],
        ["finger", "export", "--out", "."],  # the working folder: replacing it would strand the shell
        ["finger", "export", "--out", here.parent],
    ]
    for argv in cases:
        for extra in ([], ["--overwrite"]):
            code, stdout, err = _cli(capsys, *argv, *extra)
            assert code == 2 and len(err) == 1 and err[0].startswith("error: --out"), (argv, err)
    assert (_tree(ds), _tree(ck)) == before
    assert _cli(capsys, "data", "verify", ds)[0] == 0


# -- whole or nothing -----------------------------------------------------------------------------------


def test_a_failure_while_writing_leaves_the_old_output_whole(tmp_path):
    out = tmp_path / "out"
    with staged(check_output(out, OutputKind.FINGER)) as tmp:
        (tmp / "a.txt").write_text("old")
    before = _tree(out)
    with pytest.raises(KeyboardInterrupt), staged(check_output(out, OutputKind.FINGER)) as tmp:
        (tmp / "a.txt").write_text("new")
        raise KeyboardInterrupt
    assert _tree(out) == before and sorted(os.listdir(tmp_path)) == ["out"]
    with (
        pytest.raises(OutputError, match="No space"),
        staged(check_output(tmp_path / "n" / "o", OutputKind.FINGER)),
    ):
        raise OSError(28, "No space left on device")
    assert sorted(os.listdir(tmp_path)) == ["out"]  # the folders it made are gone again


_CHILD = textwrap.dedent("""
    import os, signal, sys, time
    from pathlib import Path
    from mjcodesign import outputs
    out, where = Path(sys.argv[1]), sys.argv[2]
    if where == "between-renames":  # the kernel without RENAME_EXCHANGE: two renames, killed between
        outputs._exchange = lambda a, b: False
        real_rename = os.rename
        def rename(src, dst):
            real_rename(src, dst)
            if Path(dst).name.startswith(f".{out.name}.mjcodesign-old"):
                os.kill(os.getpid(), signal.SIGKILL)
        os.rename = rename
    with outputs.staged(outputs.check_output(out, outputs.OutputKind.FINGER)) as tmp:
        for k in range(5):
            (tmp / f"f{k}.txt").write_text("new")
            if where == "writing" and k == 2:
                os.kill(os.getpid(), signal.SIGKILL)
""")


@pytest.mark.parametrize("where", ["writing", "between-renames"])
def test_killed_while_replacing_leaves_the_old_output_and_the_next_run_clears_up(tmp_path, where):
    out = tmp_path / "out"
    with staged(check_output(out, OutputKind.FINGER)) as tmp:
        for k in range(5):
            (tmp / f"f{k}.txt").write_text("old")
    before = _tree(out)
    r = subprocess.run([sys.executable, "-c", _CHILD, str(out), where], capture_output=True, timeout=120)
    assert r.returncode == -signal.SIGKILL, r.stderr
    if where == "between-renames":
        assert not out.exists()  # the old output is beside it, under a hidden name
    check_output(out, OutputKind.FINGER)  # what the next run does first
    assert _tree(out) == before and sorted(os.listdir(tmp_path)) == ["out"]


def _consistent(ck: Path, old: dict) -> str:
    """'old' or 'new': a checkpoint folder must be one run's output, whole (else the assertion says why)."""
    tree = _tree(ck)
    if tree == old:
        return "old"
    # The weights, their record and the metrics come from one run: all the old run's, or none of them.
    key = ("model.safetensors", "config.json", "metrics.json", "summary.md")
    assert all(k in tree for k in key), f"a checkpoint without {[k for k in key if k not in tree]}"
    same = {k: tree[k] == old[k] for k in key[:3]}
    assert not any(same.values()), f"files of the old run beside the new: {same}"
    config, metrics = json.loads(tree["config.json"]), json.loads(tree["metrics.json"])
    assert config["metrics"]["test_loss"] == metrics["test"]["surrogate"]["loss"]
    marker = json.loads(tree[MARKER])
    assert sorted(marker["files"]) == sorted(k for k in tree if k != MARKER), tree.keys()
    return "new"


def _listing(folder: Path) -> list[str]:
    """The names in ``folder``; none once it is gone (a staging sibling is renamed into place or removed
    between the moment it is seen and the moment it is read)."""
    try:
        return os.listdir(folder)
    except FileNotFoundError:
        return []


def test_train_killed_while_retraining_leaves_the_old_checkpoint_or_the_new_one(work, tmp_path):
    ck = tmp_path / "ck"
    shutil.copytree(work / "ck", ck)
    old = _tree(ck)
    argv = [
        sys.executable,
        "-m",
        "mjcodesign.cli",
        "train",
        "--data",
        str(work / "ds"),
        *_TRAIN,
        "--out",
        str(ck),
    ]
    env = {**os.environ, "XDG_CACHE_HOME": str(work / "cache")}
    seen = []
    # Kill points: when the new output starts to appear (a staging sibling, or the folder changing), and
    # when its weights are written.
    for point in ("start", "weights"):
        proc = subprocess.Popen([*argv, "--seed", str(len(seen) + 1)], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)  # fmt: skip
        deadline = time.monotonic() + _KILL_WAIT_S
        try:
            while time.monotonic() < deadline and proc.poll() is None:
                staging = [p for p in tmp_path.iterdir() if p.name.startswith(".ck.")]
                changed = _tree(ck) != old if ck.is_dir() else True
                files = [f for s in staging for f in _listing(s)]
                if (point == "start" and (staging or changed)) or (
                    point == "weights" and "model.safetensors" in files
                ):
                    proc.send_signal(signal.SIGKILL)
                    break
                time.sleep(0.002)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        assert proc.returncode == -signal.SIGKILL, f"{point}: not reached (exit {proc.returncode})"
        seen.append(_consistent(ck, old))
    r = subprocess.run([*argv, "--seed", "9"], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert _consistent(ck, old) == "new" and [p.name for p in tmp_path.iterdir()] == ["ck"]


def test_the_marker_names_the_kind(tmp_path):
    out = tmp_path / "o"
    with staged(check_output(out, OutputKind.PRINT)) as tmp:
        (tmp / "x").write_text("1")
    assert folder_kind(out) is OutputKind.PRINT and folder_kind(tmp_path) is None
    with pytest.raises(OutputError, match="holds a print"):
        check_output(out, OutputKind.FINGER, overwrite=True)


def test_the_dataset_constants_are_the_stores():
    from mjcodesign import outputs
    from mjcodesign.data import store

    assert (outputs._DATASET_MANIFEST, outputs._DATASET_FORMAT) == (store.MANIFEST, store.FORMAT)


def test_a_versioned_record_reads_back_and_each_fault_is_one_line_of_the_callers_error(tmp_path):
    from mjcodesign.errors import MjcodesignError

    class Mine(MjcodesignError):
        pass

    def read(source, **kw):
        return read_versioned_json(source, fmt="mine", version=2, what="a record of mine", **kw)

    good = {"format": "mine", "version": 2, "x": [1.5]}
    (tmp_path / "r.json").write_text(json.dumps(good))
    assert read(tmp_path / "r.json") == good and read(json.dumps(good).encode()) == good
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00garbage")
    (tmp_path / "list.json").write_text("[1]")
    (tmp_path / "other.json").write_text(json.dumps({**good, "format": "theirs"}))
    (tmp_path / "v9.json").write_text(json.dumps({**good, "version": 9}))
    cases = {
        "gone.json": "folder: not a record of mine (gone.json missing)",
        "bin.json": "bin.json: unreadable, not JSON",
        "list.json": "folder: not a record of mine of mjcodesign",
        "other.json": "folder: not a record of mine of mjcodesign",
        "v9.json": "folder: a record of mine of another schema (version 9; this mjcodesign reads 2)",
        "r.json/inside": "folder: not a record of mine (inside missing)",  # a file where a folder should be
    }
    for name, words in cases.items():
        with pytest.raises(Mine) as info:
            read(tmp_path / name, where="folder", error=Mine)
        assert words in str(info.value) and "\n" not in str(info.value), (name, info.value)
    with pytest.raises(OutputError, match="^bytes: unreadable, not JSON"):  # the default error
        read(b"{", where="bytes")


# -- damaged datasets -----------------------------------------------------------------------------------


def _damage(ds: Path, how: str) -> str:
    """Damage one file of dataset ``ds`` as ``how`` says; the file's path relative to ``ds``."""
    victim = "samples/o0000-p001.parquet"
    if how == "truncated":
        with open(ds / victim, "r+b") as f:
            f.truncate((ds / victim).stat().st_size // 2)
    elif how == "missing":
        (ds / victim).unlink()
    elif how == "swapped":  # a copy of the same object's other shard: the same size, other rows
        shutil.copy(ds / "samples/o0000-p000.parquet", ds / victim)
    elif how == "swapped-object":  # another object's shard (more samples would be counted for it)
        shutil.copy(ds / "samples/o0001-p000.parquet", ds / victim)
    elif how == "poses-truncated":
        victim = "poses/o0001.parquet"
        with open(ds / victim, "r+b") as f:
            f.truncate(100)
    return victim


def _rows(ds: Path) -> dict:
    from mjcodesign.data import open_dataset

    d = open_dataset(ds)
    return {
        "poses": d.poses(),
        "samples": d.samples().drop_columns(["wall_time_s"]),
        "rejected": d.rejected().drop_columns(["wall_time_s"]),
    }


@pytest.mark.parametrize("how", ["truncated", "missing", "swapped", "swapped-object", "poses-truncated"])
def test_a_damaged_dataset_is_named_and_resume_repairs_it(how, work, here, capsys):
    ds = here / "ds"
    shutil.copytree(work / "ds", ds)
    victim = _damage(ds, how)
    for argv in (["data", "info", ds], ["data", "info", ds, "--json"], ["data", "verify", ds],
                 ["train", "--data", ds, *_TRAIN, "--out", here / "ck"]):  # fmt: skip
        code, _, err = _cli(capsys, *argv)
        assert code == 2 and len(err) == 1 and victim in err[0] and "Traceback" not in err[0], (argv, err)
    assert not (here / "ck").exists()
    code, stdout, err = _cli(capsys, "data", "verify", ds, "--json")
    report = json.loads(stdout)
    assert code == 2 and not report["ok"] and [d["file"] for d in report["damaged"]] == [victim]
    code, stdout, err = _cli(
        capsys, "datagen", "--objects", "box.stl,ball.stl", *_DATAGEN, "--out", ds, "--resume"
    )
    assert code == 0, err
    res = json.loads(stdout)
    assert res["complete"] and len(res["damaged_redone"]) == 1 and victim in res["damaged_redone"][0]
    assert res["computed"]["shards"] >= 1 or how == "poses-truncated"
    assert _cli(capsys, "data", "verify", ds)[0] == 0
    want, got = _rows(work / "ds"), _rows(ds)
    assert all(got[k].equals(want[k]) for k in want), how


def test_a_dataset_without_hashes_still_reads_and_says_so(work, here, capsys):
    ds = here / "ds"
    shutil.copytree(work / "ds", ds)
    manifest = json.loads((ds / "manifest.json").read_text())
    for o in manifest["objects"]:
        o.pop("poses_check")
    for s in manifest["shards"].values():
        s.pop("checks")
    (ds / "manifest.json").write_text(json.dumps(manifest))
    code, stdout, err = _cli(capsys, "data", "info", ds, "--json")
    info = json.loads(stdout)
    assert code == 0 and info["files_with_hash"] == "0/6" and "before file hashes" in info["integrity"], err
    assert info["samples"] == 12
    code, stdout, _ = _cli(capsys, "data", "verify", ds, "--json")
    assert code == 0 and json.loads(stdout)["hashes"] == "none"
    victim = _damage(ds, "swapped-object")  # caught by its rows' keys, without a hash
    code, _, err = _cli(capsys, "data", "info", ds)
    assert code == 2 and victim in err[0] and "another shard" in err[0], err
    code, stdout, err = _cli(
        capsys, "datagen", "--objects", "box.stl,ball.stl", *_DATAGEN, "--out", ds, "--resume"
    )
    assert code == 0 and victim in json.loads(stdout)["damaged_redone"][0], err
    code, stdout, _ = _cli(capsys, "data", "verify", ds, "--json")
    assert code == 0 and json.loads(stdout)["hashes"] == "all"  # recorded for the sound files too
