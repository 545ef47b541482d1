"""The oracle (``bench oracle``): CMA-ES on the simulator, scoring designs exactly as the evaluation does.

A small slice of the shipped suite (two in-domain objects, two poses each) at a short paper-scale grasp.
"""

import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mjcodesign.design.stiffness import Stiffness, read_design_file
from mjcodesign.errors import DesignError
from mjcodesign.evaluation import SuiteRun, load_suite, parse_design_groups, run_suite
from mjcodesign.evaluation.analysis import per_object_cells, select_policy
from mjcodesign.evaluation.oracle import OracleConfig, oracle_search, score_designs
from mjcodesign.outputs import MARKER
from mjcodesign.scenarios.grasp import GraspScenario

pytest.importorskip("cmaes")

_OBJECTS = ("013_apple", "025_mug")
_SHORT = GraspScenario(tighten_s=0.1, lift_s=0.2, hold_s=0.1, post_hold_s=0.05)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One cache of the objects' convex decompositions for the module (each costs tens of seconds).

    It is laid out as the CLI's (``$XDG_CACHE_HOME/mjcodesign``), so that the command's test reads it too.
    """
    path = tmp_path_factory.mktemp("xdg") / "mjcodesign"
    path.mkdir()
    return path


@pytest.fixture(scope="module")
def suite():
    full = load_suite("default")
    objects = tuple(
        dataclasses.replace(o, poses=o.poses[:2], source_index=o.source_index[:2])
        for o in full.objects
        if o.name in _OBJECTS
    )
    return dataclasses.replace(full, objects=objects)


def _run(designs: str, draws: int = 2) -> SuiteRun:
    return SuiteRun(designs=parse_design_groups(designs), perturbations=draws, scenario=_SHORT)


@pytest.mark.parametrize("policy", ["all", "oracle"])
def test_designs_are_scored_as_the_evaluation_scores_them(suite, cache, policy):
    run = _run("soft,semi-rigid")
    rows = run_suite(suite, run, cache_dir=cache)["rows"]
    cells = per_object_cells(select_policy(rows, policy))
    expected = {(c["design"], c["object"]): c["successes"] / c["valid"] for c in cells.values() if c["valid"]}
    presets = [Stiffness.preset("soft"), Stiffness.preset("semi-rigid")]
    got = score_designs(suite, run, presets, policy=policy, cache_dir=cache)
    for label, rates in zip(("soft", "semi-rigid"), got, strict=True):
        assert set(rates) == set(_OBJECTS)
        for name, p in rates.items():
            assert p == expected[(label, name)]


def test_search_keeps_its_budget_and_never_ends_below_its_start(suite, cache):
    run = _run("soft", draws=1)
    per_design = 2 * 2  # objects x poses x draws
    budget = per_design * (1 + 2 * 4)  # the start, then two generations of four
    (start,) = parse_design_groups("soft")
    res = oracle_search(
        suite, run, OracleConfig(budget=budget, population=4, sigma=1.5), start=start, cache_dir=cache
    )
    assert res.generations == 2 and res.rollouts == budget
    assert res.success >= res.start_success
    best = [c["best_so_far"] for c in res.curve]
    assert best == sorted(best) and best[-1] == res.success
    assert np.all((res.design >= 13.5) & (res.design <= 17.0))
    (again,) = score_designs(
        suite, run, [Stiffness(res.design)], cache_dir=cache
    )  # the same draws give the same score
    assert float(np.mean(list(again.values()))) == res.success
    assert again == res.per_object


def test_proposals_are_scored_first_and_the_search_starts_from_the_best(suite, cache):
    # The surrogate-then-simulator loop: proposals (here two presets) are scored on the search's own
    # rollouts, CMA-ES starts from the best, and the proposals' rollouts count against the budget.
    run = _run("soft", draws=1)
    per_design = 2 * 2  # objects x poses x draws
    starts = parse_design_groups("soft,semi-rigid")
    budget = per_design * (2 + 4)  # the two proposals, then one generation of four
    res = oracle_search(suite, run, OracleConfig(budget=budget, population=4), start=starts, cache_dir=cache)
    expected = score_designs(suite, run, [g.design for g in starts], cache_dir=cache)
    assert [p["label"] for p in res.proposals] == ["soft", "semi-rigid"]
    assert [p["per_object"] for p in res.proposals] == expected
    means = [float(np.mean(list(r.values()))) for r in expected]
    k = int(np.argmax(means))
    assert res.start == starts[k].label and res.start_success == means[k]
    assert res.proposal_rollouts == 2 * per_design and res.rollouts == budget and res.generations == 1
    assert res.evaluations == 2 + 4 and res.success >= max(means)
    with pytest.raises(DesignError, match="the 2 proposals"):  # covers one start and a generation only
        oracle_search(suite, run, OracleConfig(budget=per_design * 5, population=4), start=starts)


def test_refusals(suite):
    run = _run("soft", draws=1)
    (start,) = parse_design_groups("soft")
    with pytest.raises(DesignError, match="does not cover"):
        oracle_search(suite, run, OracleConfig(budget=8, population=4), start=start)
    with pytest.raises(DesignError, match="oracle policy"):
        OracleConfig(budget=10, policy="fixed")
    with pytest.raises(DesignError, match="population"):
        OracleConfig(budget=10, population=3)


def _cli(*args, cwd, cache=None):
    env = os.environ | ({"XDG_CACHE_HOME": str(cache.parent)} if cache is not None else {})
    return subprocess.run(
        [sys.executable, "-m", "mjcodesign.cli.main", "bench", "oracle", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=600,
    )


def test_cli_writes_a_design_every_command_reads(tmp_path, cache):
    out = tmp_path / "oracle"
    p = _cli(
        "--only", ",".join(_OBJECTS), "--candidates", "1", "--perturbations", "1", "--start", "soft,semi-rigid",
        "--budget", "12", "--population", "4", "--out", str(out), "--json", cwd=tmp_path, cache=cache,
    )  # fmt: skip
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert summary["regime"] == "real" and summary["suite"]["objects"] == 2
    # the two proposals (2 rollouts each), then one generation of four
    assert summary["rollouts"] == 12 and summary["generations"] == 1 and summary["proposal_rollouts"] == 4
    assert [q["label"] for q in summary["proposals"]] == ["soft", "semi-rigid"]
    assert summary["start"] in ("soft", "semi-rigid")
    assert read_design_file(out / "design.json") == Stiffness(summary["design"])
    assert {f.name for f in out.iterdir()} == {"design.json", "oracle.json", "curve.png", MARKER}


@pytest.mark.parametrize(
    "args, says",
    [
        (("--only", "013_apple,nosuch"), "not in the suite"),
        (("--split", "out-of-domain", "--only", "013_apple"), "not in the suite"),
        (("--start", "individual:x"), "individual"),
        (("--only", "013_apple", "--budget", "1"), "does not cover"),
        (("--policy", "fixed"), "invalid choice"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_no_folder(tmp_path, args, says):
    out = tmp_path / "o"
    p = _cli(*args, "--out", str(out), cwd=tmp_path)
    assert p.returncode == 2
    assert says in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert p.stdout == "" and not out.exists()


def test_only_takes_a_list_longer_than_a_file_name_and_a_file(tmp_path):
    # 36 names joined by commas are longer than a path component may be: a list, not an OSError
    from mjcodesign.cli.oracle import _only

    names = [f"{i:03d}_an_object_with_a_long_name" for i in range(36)]
    assert len(",".join(names)) > 255
    assert _only(",".join(names)) == set(names)
    listed = tmp_path / "train_objects.txt"
    listed.write_text("\n".join(names) + "\n")
    assert _only(str(listed)) == set(names)
