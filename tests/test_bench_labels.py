"""``bench labels``: agreement of perturbed rollouts, draws a label needs, and the adaptive scheme."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mjcodesign.bench.labels import analyse_cells, bench_labels, draws_needed
from mjcodesign.cli.main import main


def _cells(*outcomes: str) -> list[dict]:
    return [
        {"object": f"o{i % 2}", "pose": 0, "design": "soft", "outcomes": s} for i, s in enumerate(outcomes)
    ]


@pytest.mark.parametrize(
    ("k", "n", "need"),
    [
        (0, 16, 1),  # p = 0: any one draw has SE 0
        (16, 16, 1),
        (8, 16, 25),  # p = 0.5: 0.25 / 0.1² = 25 exactly, not 26 by rounding
        (1, 5, 16),  # p = 0.2: 0.16 / 0.01 = 16 exactly
        (4, 16, 19),  # p = 0.25: 0.1875 / 0.01 = 18.75
    ],
)
def test_draws_needed_is_ceil_p_q_over_se_squared(k, n, need):
    # n ≥ p(1 − p) / SE², SE = 0.1
    assert draws_needed(k, n) == need


def test_analyse_cells_counts_agreement_the_adaptive_scheme_and_its_error_by_hand():
    # 8 draws; adaptive first stages 2 and 4 (below 8); agreement at 2, 4, 8.
    cells = _cells("11111111", "1111....", "........", "1.1.1.1.", "11x11111", "1111111.")
    a = analyse_cells(cells, 8)
    assert a["cells"] == 6 and a["unusable_rollouts"] == 1
    agree = {k: v["cells"]["value"] for k, v in a["agreement"].items()}
    assert agree == {"2": 5 / 6, "4": 5 / 6, "8": 3 / 6}  # "1.": cell 4 disagrees from its 2nd draw
    assert a["agreement"]["8"]["all_success"] == 2 and a["agreement"]["8"]["all_failure"] == 1
    p = [1, 0.5, 0, 0.5, 1, 7 / 8]
    assert a["p"]["mean"] == pytest.approx(np.mean(p))
    assert a["p"]["successes_of_draws"]["4"] == 2  # "1111...." and "1.1.1.1." (the x cell has 7 usable)
    need = [1, 25, 1, 25, 1, math.ceil(7 / 64 * 100)]
    assert a["draws_needed"]["median"] == np.median(need) and a["draws_needed"]["max"] == 25
    ad4 = a["adaptive"]["4"]
    # cells 1, 2, 3, 5, 6 agree over their first 4 (1 kept at p = 1, 0.5 off for cell 2, 1/8 for cell 6)
    assert ad4["rollouts_per_cell"] == pytest.approx((4 * 5 + 8) / 6)
    assert ad4["error"]["max"] == pytest.approx(0.5) and ad4["error"]["mean"] == pytest.approx(
        (0.5 + 1 / 8) / 6
    )
    assert ad4["error"]["share_over_se"] == pytest.approx(2 / 6)  # 0.5 and 0.125 exceed SE 0.1
    assert a["headline"] == ad4
    assert a["fixed"]["2"]["error"]["max"] == pytest.approx(1 / 2)


def _check_against_outcomes(res: dict) -> None:
    """Every reported share and cost recomputed from the cells' outcome strings."""
    cells = res["cell_outcomes"]
    draws = res["draws"]
    assert all(len(c["outcomes"]) == draws for c in cells)
    if not any("x" in c["outcomes"] for c in cells):
        assert res["rollouts"] == len(cells) * draws
    for k, v in res["agreement"].items():
        agree = [len(set(c["outcomes"][: int(k)].replace("x", ""))) == 1 for c in cells]
        assert v["cells"]["value"] == pytest.approx(np.mean(agree))
    for first, ad in res["adaptive"].items():
        cost = [
            int(first) if len(set(c["outcomes"][: int(first)].replace("x", ""))) == 1 else draws
            for c in cells
        ]
        assert ad["rollouts_per_cell"] == pytest.approx(np.mean(cost))
    p = [c["outcomes"].count("1") / len(c["outcomes"].replace("x", "")) for c in cells]
    assert res["p"]["mean"] == pytest.approx(np.mean(p))
    by_obj = {}
    for c in cells:
        by_obj.setdefault(c["object"], []).append(len(set(c["outcomes"].replace("x", ""))) == 1)
    assert res["never_vary"] == sorted(o for o, v in by_obj.items() if all(v))


def test_bench_labels_reports_what_its_rollouts_say_and_fewer_draws_are_the_first_ones():
    kw = dict(objects=2, poses=1, designs=("soft", "semi-rigid"))
    res = bench_labels(draws=4, **kw)
    assert list(res["objects"]) == ["002_master_chef_can", "003_cracker_box"]  # suite order
    assert "063-a_marbles" in res["skipped"]  # no published mass: named, not run
    assert len(res["cell_outcomes"]) == 2 * 1 * 2 and res["rollouts"] == 16
    assert set(res["by_group"]) == {"soft", "semi-rigid"}
    _check_against_outcomes(res)
    # The draws of an (object, pose) come from one seeded stream: 2 draws are the first 2 of 4.
    short = bench_labels(draws=2, **{**kw, "objects": 1})
    for a, b in zip(short["cell_outcomes"], res["cell_outcomes"][:2], strict=True):
        assert (a["object"], a["pose"], a["design"]) == (b["object"], b["pose"], b["design"])
        assert a["outcomes"] == b["outcomes"][:2]


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--draws", "0"], "--draws"),
        (["--designs", "soft,bogus"], "bogus"),
    ],
)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capfd, argv, words):
    out = tmp_path / "rec.json"
    try:
        code = main(["bench", "labels", "--objects", "1", "--poses", "1", *argv, "--out", str(out)])
    except SystemExit as exc:  # argparse refuses a flag's value this way
        code = exc.code
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0]
    assert not out.exists()
