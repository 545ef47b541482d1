"""Where data generation's CPU goes beside the rollouts: one thread, the shards of ``bench datagen``.

``bench datagen`` times the whole pipeline against bare ``mujoco.rollout`` calls and gives one ratio,
which moves by ±0.06 between passes on a shared machine. This script splits the pipeline's CPU
instead, in one process and one MuJoCo thread (``Worker(nthread=1)``, as each of datagen's worker
threads runs a shard): per pass over the shards, the process's CPU seconds, the CPU inside the
``mujoco.rollout`` calls, inside the outcome replays (``outcome_from_states``: the hold-force
``mj_forward`` replays, the contact wrenches, the energy and motion bounds) and inside the model
copies with each design's stiffness; the rest is the shard's other Python (jobs, scene at the pose,
initial state and controls, divergence checks, rows). Shares are of the rollouts' CPU, so they are
comparable across commits and machines of another speed: ``1 / (1 + other_over_rollout)`` is the
pipeline-to-raw ratio that one thread's CPU allows, before writes and threads.

Run it at two commits with ``scripts/at-commit C python3 scripts/datagen_overhead.py ...``: it
imports whatever mjcodesign is installed. Bad input exits 2 with one line on stderr.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import tempfile
import time
from pathlib import Path


def _fail(message: str) -> None:
    """Exit 2 with ``message`` as the one line on stderr (bad input)."""
    print(f"datagen_overhead: {message}", file=sys.stderr)
    sys.exit(2)


class _Clock:
    """CPU seconds of the thread that runs each wrapped call, summed per name."""

    def __init__(self):
        self.cpu: dict[str, float] = {}

    def timed(self, f, name: str):
        """``f``, its calls' CPU added to ``name``."""

        @functools.wraps(f)
        def timed(*args, **kwargs):
            t0 = time.thread_time()
            try:
                return f(*args, **kwargs)
            finally:
                self.cpu[name] = self.cpu.get(name, 0.0) + time.thread_time() - t0

        return timed

    def reset(self) -> None:
        self.cpu.clear()


def _instrument(clock: _Clock):
    """Time the MuJoCo C backend's rollout calls, outcome replays and model copies; returns the undo."""
    import mjcodesign.sim.mujoco_c as mc

    saved = {k: getattr(mc, k) for k in ("mj_rollout", "outcome_from_states", "_stiffness_writer")}

    class _Rollout:  # stands in for the module's ``mujoco.rollout``
        rollout = staticmethod(clock.timed(saved["mj_rollout"].rollout, "rollout"))

    mc.mj_rollout = _Rollout
    mc.outcome_from_states = clock.timed(saved["outcome_from_states"], "outcomes")
    mc._stiffness_writer = lambda scene: clock.timed(saved["_stiffness_writer"](scene), "model_copies")
    return lambda: [setattr(mc, k, v) for k, v in saved.items()]


def measure(objects: list[str], poses_per_object: int, designs_per_pose: int, passes: int, seed: int) -> dict:
    """Per pass, the CPU split of :class:`~mjcodesign.data.Worker` over the bench's shards (module docstring)."""
    clock = _Clock()
    undo = _instrument(clock)
    try:
        return _passes(clock, objects, poses_per_object, designs_per_pose, passes, seed)
    finally:
        undo()


def _passes(clock: _Clock, objects, poses_per_object, designs_per_pose, passes, seed) -> dict:
    from mjcodesign.bench.datagen import _shards
    from mjcodesign.data import DatagenConfig, DatasetDir, ObjectTask, Worker, parse_density_spec

    config = DatagenConfig(
        objects=tuple(objects),
        poses_per_object=poses_per_object,
        designs_per_pose=designs_per_pose,
        density=parse_density_spec("light"),
        backend="mujoco",
        seed=seed,
    )
    worker = Worker(nthread=1)
    with tempfile.TemporaryDirectory(prefix="datagen-overhead-") as tmp:
        ds = DatasetDir.open(Path(tmp) / "dataset", config, {"command": ["datagen_overhead"]})
        try:
            for i in range(len(objects)):
                ds.object_ready(worker.prepare(ObjectTask(i, config, None)))
            shards = _shards(ds, config, None)
        finally:
            ds.close()
        for t in shards:  # scenes compiled, caches warm: what a long dataset's shards see
            worker.run([t])
        rows = []
        for _ in range(passes):
            clock.reset()
            t0 = time.process_time()
            rollouts = sum(len(r.samples) + len(r.rejected) for t in shards for r in worker.run([t]))
            total = time.process_time() - t0
            cpu = dict(clock.cpu)
            roll = cpu.get("rollout", 0.0)
            other = total - roll
            rows.append(
                {
                    "process_cpu_s": total,
                    "rollout_cpu_s": roll,
                    "outcomes_cpu_s": cpu.get("outcomes", 0.0),
                    "model_copies_cpu_s": cpu.get("model_copies", 0.0),
                    "rest_cpu_s": other - cpu.get("outcomes", 0.0) - cpu.get("model_copies", 0.0),
                    "rollouts": rollouts,
                    "rollout_ms_each": 1e3 * roll / rollouts,
                    "other_ms_per_rollout": 1e3 * other / rollouts,
                    "outcome_ms_per_rollout": 1e3 * cpu.get("outcomes", 0.0) / rollouts,
                    "model_copy_ms_per_rollout": 1e3 * cpu.get("model_copies", 0.0) / rollouts,
                    "other_over_rollout": other / roll,
                    "cpu_ratio_ceiling": roll / total,
                }
            )
    return {"shards": len(shards), "passes": rows}


def main(argv: list[str] | None = None) -> None:
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="012_strawberry,013_apple,010_potted_meat_can")
    ap.add_argument("--poses-per-object", default="4")
    ap.add_argument("--designs-per-pose", default="35")
    ap.add_argument("--passes", default="3")
    ap.add_argument("--seed", default="0")
    ap.add_argument("--out", help="write the result here as JSON (with its provenance)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    a = ap.parse_args(argv)
    try:
        poses, designs, passes, seed = (
            int(v) for v in (a.poses_per_object, a.designs_per_pose, a.passes, a.seed)
        )
    except ValueError:
        _fail("--poses-per-object, --designs-per-pose, --passes and --seed take integers")
    if min(poses, designs, passes) < 1:
        _fail("--poses-per-object, --designs-per-pose and --passes must be at least 1")
    objects = [o for o in a.objects.split(",") if o]
    if not objects:
        _fail("--objects names no object")
    if a.out and not Path(a.out).resolve().parent.is_dir():
        _fail(f"--out: no folder {Path(a.out).parent}")
    from mjcodesign.bench.record import provenance
    from mjcodesign.errors import MjcodesignError

    try:
        res = measure(objects, poses, designs, passes, seed)
    except MjcodesignError as exc:
        _fail(str(exc))
    res["settings"] = {
        "objects": objects,
        "poses_per_object": poses,
        "designs_per_pose": designs,
        "seed": seed,
    }
    res["provenance"] = provenance(
        "datagen_overhead",
        command="python3 scripts/datagen_overhead.py " + " ".join(sys.argv[1:] if argv is None else argv),
    )
    if a.out:
        Path(a.out).write_text(json.dumps(res, indent=1))
    if a.json or not a.out:
        print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
