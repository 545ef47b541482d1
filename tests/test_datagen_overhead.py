"""scripts/datagen_overhead.py: the CPU split of a shard adds up, the backend is left as it was, bad input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

_SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "datagen_overhead.py"


def test_the_split_adds_up_and_the_backend_is_restored(script_module):
    import mjcodesign.sim.mujoco_c as mc

    before = (mc.mj_rollout, mc.outcome_from_states, mc._stiffness_writer)
    do = script_module("datagen_overhead")
    res = do.measure(["013_apple"], 1, 3, 1, 0)
    assert (mc.mj_rollout, mc.outcome_from_states, mc._stiffness_writer) == before
    (p,) = res["passes"]
    assert res["shards"] == 1 and p["rollouts"] == 3
    parts = p["rollout_cpu_s"] + p["outcomes_cpu_s"] + p["model_copies_cpu_s"] + p["rest_cpu_s"]
    assert parts == pytest.approx(p["process_cpu_s"], rel=1e-9)
    # every piece was timed: rollouts, three outcome replays and three model copies cost CPU
    assert p["rollout_cpu_s"] > 0 and p["outcomes_cpu_s"] > 0 and p["model_copies_cpu_s"] > 0
    assert p["cpu_ratio_ceiling"] == pytest.approx(p["rollout_cpu_s"] / p["process_cpu_s"])


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--passes", "0"], "at least 1"),
        (["--designs-per-pose", "x"], "take integers"),
        (["--objects", ","], "no object"),
        (["--objects", "no_such_object_xyz"], "no_such_object_xyz"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, args, says):
    out = tmp_path / "o.json"
    res = subprocess.run(
        [sys.executable, str(_SCRIPT), "--out", str(out), *args], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in res.stderr
    assert not out.exists()
