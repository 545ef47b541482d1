"""scripts/robustness_table.py on evaluation rows made up so that every figure is known by hand."""

from __future__ import annotations

import pytest


def _rows(success: dict[tuple[str, str, str], list[bool]]) -> list[dict]:
    """Evaluation rows: (design, object, domain) -> the successes of pose 0's draws (pose 1 always fails)."""
    rows = []
    for (design, obj, domain), outcomes in success.items():
        for pose, results in ((0, outcomes), (1, [False] * len(outcomes))):
            for draw, ok in enumerate(results):
                rows.append({"design": design, "object": obj, "domain": domain, "pose": pose, "draw": draw,
                             "density": "real", "impulse_paper_ns": 0.1, "fold": 0, "success": ok,
                             "sample_error": False, "hold_force_n": 1.0, "slip_m": 0.0, "lift_margin_m": 0.01})  # fmt: skip
    return rows


def _runs() -> dict[str, list[dict]]:
    # Two presets (a, b), a candidate c, and an individual design that has no out-of-domain rows.
    nominal = {}
    for i in range(4):
        o, ood = f"in{i}", f"out{i}"
        nominal |= {("a", o, "in-domain"): [True, False], ("b", o, "in-domain"): [False, False],
                    ("c", o, "in-domain"): [True, True], ("ind", o, "in-domain"): [True, False],
                    ("a", ood, "out-of-domain"): [True, True], ("b", ood, "out-of-domain"): [False, False],
                    ("c", ood, "out-of-domain"): [True, False]}  # fmt: skip
    variant = dict(nominal)  # the variant: preset a falls to 0, c to one draw in two in domain
    for i in range(4):
        variant |= {("a", f"in{i}", "in-domain"): [False, False], ("c", f"in{i}", "in-domain"): [True, False]}
    return {"nominal": _rows(nominal), "variant": _rows(variant)}


def test_the_table_leaves_a_design_out_of_a_split_without_its_rows_and_pairs_leads_per_variant(script_module):
    rec = script_module("robustness_table").table(_runs(), ["a", "b"])
    fixed = rec["policies"]["fixed"]
    assert fixed["out-of-domain"]["absent"] == ["ind"] and fixed["in-domain"]["absent"] == []
    assert "ind" not in fixed["out-of-domain"]["success"]["nominal"]
    inside = fixed["in-domain"]
    assert inside["success"]["nominal"]["c"]["value"] == pytest.approx(1.0)
    assert inside["success"]["variant"]["a"]["value"] == pytest.approx(0.0)
    assert inside["change"]["variant"]["a"]["difference"]["value"] == pytest.approx(-0.5)
    # c leads the best preset by 0.5 in both models (a in the nominal, then b and a tie at 0: a first)
    lead = inside["lead"]["c"]
    assert lead["per_variant"]["nominal"]["best_preset"] == "a"
    assert lead["per_variant"]["nominal"]["difference"]["value"] == pytest.approx(0.5)
    assert lead["per_variant"]["variant"]["difference"]["value"] == pytest.approx(0.5)
    assert lead["robust"]
    # out of domain c trails a by 0.5 under both: the sign holds, so it is robust too, and behind
    out = fixed["out-of-domain"]["lead"]["c"]
    assert out["robust"] and out["per_variant"]["variant"]["difference"]["value"] == pytest.approx(-0.5)
    # every pose: pose 1 always fails, so every rate halves
    assert rec["policies"]["all"]["in-domain"]["success"]["nominal"]["c"]["value"] == pytest.approx(0.5)
    assert inside["ranking"]["nominal"][0] == "c" and not inside["same_ranking_as_nominal"]["variant"]
