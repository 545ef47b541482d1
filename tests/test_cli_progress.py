"""The CLI's shared parts: progress lines in a log, defaults in ``--help``, fewer poses than asked said."""

import io
import json
import types

import numpy as np
import pytest

from mjcodesign.cli.progress import StageProgress
from mjcodesign.data import Event


def test_stage_progress_writes_one_line_per_finished_unit_off_a_terminal():
    out = io.StringIO()
    with StageProgress("evaluate", stream=out, tty=False) as bar:
        bar("posing objects", 1, 2)
        bar.update("posing objects", 2, 2, unit="013_apple", detail="3.0 poses/s")
        bar.note("013_apple: 4 of 10 poses")
    lines = out.getvalue().splitlines()
    assert len(lines) == 3
    assert lines[0].startswith("evaluate: posing objects 1/2 (") and lines[0].endswith(" s)")
    assert lines[1].startswith("evaluate: posing objects 2/2 013_apple (") and lines[1].endswith(
        ", 3.0 poses/s)"
    )
    assert lines[2] == "evaluate: 013_apple: 4 of 10 poses"


def test_stage_progress_draws_no_lines_in_a_terminal():
    # In a terminal the bars are transient: nothing of a unit's plain line is left, notes stay.
    out = io.StringIO()
    with StageProgress("datagen", stream=out, tty=True) as bar:
        bar.update("shards", 1, 3, unit="o0000-p0000")
        bar.note("a note")
    text = out.getvalue()
    assert "a note" in text and "shards 1/3 o0000-p0000 (" not in text


def test_datagen_progress_counts_posing_and_shards():
    from mjcodesign.cli.data import _DatagenProgress

    out = io.StringIO()
    events = [
        Event("start", total=4, done=0, objects=2),
        Event("submit", keys=("013_apple",)),
        Event("object", keys=("013_apple",), total=3, message="1 of 2 poses: the sampler accepted 1"),
        Event("object_failed", keys=("bad.stl",), total=1, message="MeshError: cannot read"),
        Event("shard", keys=("o0000-p0000",), samples=2, rejected=1),
    ]
    with _DatagenProgress(stream=out, tty=False) as bar:
        for e in events:
            bar(e)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("datagen: posing objects 0/2 (")  # the bar starts with the posing
    assert lines[1].startswith("datagen: shards 0/4 (")
    assert lines[2].startswith("datagen: posing objects 1/2 013_apple (")
    assert lines[3] == "datagen: 013_apple: 1 of 2 poses: the sampler accepted 1"
    assert lines[4].startswith("datagen: posing objects 2/2 bad.stl (")
    assert lines[5] == "datagen: bad.stl: failed: MeshError: cannot read"
    # The shards' total follows the objects' poses (1 left after the failure), with the rate.
    assert lines[6].startswith("datagen: shards 1/1 o0000-p0000 (") and "samples/s)" in lines[6]
    assert len(lines) == 7  # submit events draw nothing


def test_help_shows_defaults():
    from mjcodesign.cli.main import build_parser

    parser = build_parser()
    sub = {a.dest: a for a in parser._actions if hasattr(a, "choices") and isinstance(a.choices, dict)}
    datagen = sub["command"].choices["datagen"].format_help()
    assert "(default: 50)" in " ".join(datagen.split())  # --poses-per-object
    assert "(default: None)" not in datagen and "(default: False)" not in datagen
    poses = " ".join(sub["command"].choices["poses"].format_help().split())
    assert "(default: 0)" in poses and "(default: source)" in poses  # --seed, --order


@pytest.mark.parametrize(
    ("rate", "samples", "warned"),
    [
        (0.96, 100, True),
        (0.95, 100, False),
        (0.5, 100, False),
        (0.05, 100, False),
        (0.04, 100, True),
        (0.0, 0, False),
    ],
)
def test_data_info_warns_on_one_sided_success(rate, samples, warned):
    from mjcodesign.cli.data import success_warning

    line = success_warning(rate, samples)
    assert (line is not None) == warned
    if warned:
        assert "\n" not in line and f"{rate:.1%}" in line


def test_poses_says_when_it_returns_fewer_than_asked(monkeypatch, capsys):
    from mjcodesign.cli import poses as cli_poses
    from mjcodesign.poses import Candidates

    c = Candidates(
        np.tile(np.eye(4), (2, 1, 1)),
        np.zeros((2, 2)),
        np.ones(2),
        np.zeros(2),
        np.zeros(2),
        {"friction cone": 40, "ground collision": 3},
    )
    obj = types.SimpleNamespace(name="box")
    monkeypatch.setattr(cli_poses, "poses", lambda *a, **k: (obj, c))
    args = types.SimpleNamespace(
        object="box.stl",
        n=5,
        seed=0,
        order="source",
        top_fraction=0.0,
        augment=0,
        import_file=None,
        point_cloud=None,
        allow_open=False,
        fit_depth=False,
        out=None,
        json=True,
    )
    assert cli_poses.run(args) == 0
    cap = capsys.readouterr()
    res = json.loads(cap.out)
    assert res["short"]["asked"] == 5 and res["short"]["returned"] == 2
    assert "friction cone 40" in res["short"]["reason"]
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: 2 of 5 poses for box:")
    # Asked for no more than it got: no warning and no key.
    args.n = 2
    assert cli_poses.run(args) == 0
    cap = capsys.readouterr()
    assert "short" not in json.loads(cap.out) and cap.err == ""
