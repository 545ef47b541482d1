"""``mjcodesign datagen``, ``mjcodesign data info``, ``mjcodesign data verify`` and ``mjcodesign bench datagen``.

Wire them into the main CLI with ``cli_data.add_parser(subparsers)`` and
``cli_data.add_bench_parser(bench_subparsers)``. Every input is checked before anything is written, so
a refused command (exit 2, one line on stderr) leaves no folder behind.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

from mjcodesign.cli.common import (
    Parser,
    add_mass_mode,
    add_regime,
    emit,
    int_at_least,
    quiet_warp,
    user_cache_dir,
    warn_failed_objects,
)
from mjcodesign.cli.finger_flags import add_routing, grasp_model_name
from mjcodesign.optional import WARP_DEVICES

__all__ = [
    "add_parser",
    "add_bench_parser",
    "run_datagen",
    "run_info",
    "run_verify",
    "run_bench",
    "datagen_config",
    "success_warning",
]

_MODELS = ("chain", "flex")
_BENCH_OBJECTS = "012_strawberry,013_apple,010_potted_meat_can"
# A dataset whose success rate is outside [_SUCCESS_LOW, _SUCCESS_HIGH] holds almost one outcome: too
# little of the other for a surrogate to learn where designs differ.
_SUCCESS_LOW, _SUCCESS_HIGH = 0.05, 0.95
_DAMAGED_SHOWN = 5  # damaged files named on the one error line of `data verify` (--json lists all)
# Ray binds its external address unless told otherwise; these keep a local instance on loopback.
_RAY_LOCAL_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_USAGE_STATS_ENABLED": "0"}
# Joining a cluster: one attempt at Ray's first connection to the head (about 42 s when the port answers
# but is no Ray head: 5 s connect, 5 s pubsub, 30 s cluster id) instead of 20 (about 14 minutes); the
# port was found answering just before. A value the user set is kept.
_RAY_JOIN_ENV = {"RAY_gcs_server_port_wait_time_s": "1"}


def add_parser(subparsers) -> None:
    """Register ``datagen`` and ``data`` (with ``data info``) on an ``argparse`` subparsers object."""
    p = subparsers.add_parser(
        "datagen",
        help="generate a grasp dataset (Parquet): objects x poses x designs, resumable, on all cores",
    )
    p.add_argument(
        "--objects",
        required=True,
        help="a set (ycb-in-domain, ycb-ood, egad-like), a folder of OBJ/STL/PLY files, or comma-separated "
        "YCB names, egad-like:N or mesh files",
    )
    p.add_argument("--poses-per-object", type=int, default=50, help="poses asked of the sampler per object")
    p.add_argument("--designs-per-pose", type=int, default=35, help="stiffness designs per pose")
    add_regime(p)
    p.add_argument(
        "--density",
        default=None,
        help="object density per pose: light (100), heavy (400), a number [kg/m³], or uniform:LO,HI (the "
        "paper's relative scale, not real objects), or ycb-median (680); default: the regime's (real: "
        "ycb-median for objects without a published mass; paper: light)",
    )
    add_mass_mode(p, "in place of --density")
    p.add_argument(
        "--tendon",
        default=None,
        help="force:N (tension per finger [N]) or position:TICKS (the XL330 servo's goal, ticks of 4096); "
        "default: the regime's (real: position:1000; paper: force:10)",
    )
    p.add_argument("--model", choices=_MODELS, default="chain", type=grasp_model_name)
    add_routing(p)
    p.add_argument("--backend", choices=("mujoco", "mjwarp"), default="mujoco")
    p.add_argument(
        "--device",
        choices=WARP_DEVICES,
        default="auto",
        help="mjwarp: Warp device (auto: CUDA if any)",
    )
    p.add_argument("--sampler", choices=("uniform", "sobol"), default="uniform", help="design sampler")
    p.add_argument(
        "--perturbations",
        default="1",
        help="K: perturbed rollouts per (pose, design) cell under the evaluation's perturbation model "
        "(palm, mass, friction, tendon), a row storing success_p and the outputs' means and spreads, "
        "every rollout in rollouts/; K:M: K, extended to M where the K disagree (e.g. 4:16); "
        "1: one nominal rollout (default)",
    )
    p.add_argument("--workers", type=int, default=1, help="processes (1: this one, MuJoCo on every core)")
    p.add_argument(
        "--ray",
        default=None,
        help="run the shards on Ray: 'local' (a new Ray on this machine; RAY_ADDRESS is ignored) or a "
        "running cluster's HOST:PORT (its head's GCS port; refused within 5 s when nothing answers there)",
    )
    p.add_argument("--seed", type=int, default=0, help="seeds poses, densities, designs and point clouds")
    p.add_argument("--object-seed", type=int, default=0, help="seeds CoACD and egad-like shapes")
    p.add_argument(
        "--scenario",
        default=None,
        help="grasp phases as JSON (text or a file), GraspScenario fields replacing the regime's, e.g. "
        '\'{"lift": 0.05, "delta_v": 0}\'',
    )
    p.add_argument("--out", required=True, help="dataset folder (created; a rerun continues it)")
    p.add_argument("--resume", action="store_true", help="continue the dataset in --out (it must exist)")
    p.set_defaults(func=run_datagen)

    data = subparsers.add_parser("data", help="datasets written by datagen")
    dsub = data.add_subparsers(dest="what", required=True, parser_class=Parser)
    info = dsub.add_parser("info", help="counts and success rates of a dataset")
    info.add_argument("dir", help="dataset folder")
    info.add_argument("--json", action="store_true")
    info.add_argument("--plot", default=None, help="draw success against mean ln E per object into FILE.png")
    info.set_defaults(func=run_info)
    check = dsub.add_parser(
        "verify", help="check every file against the manifest's size and SHA-256 (exit 2 naming the damaged)"
    )
    check.add_argument("dir", help="dataset folder")
    check.add_argument("--json", action="store_true", help="the report as JSON on stdout (also when damaged)")
    check.set_defaults(func=run_verify)


def add_bench_parser(bench_subparsers) -> None:
    """Register ``datagen`` on the ``bench`` command's subparsers object."""
    p = bench_subparsers.add_parser(
        "datagen", help="data generation: raw mujoco.rollout vs the pipeline with writes, pose/cloud time"
    )
    p.add_argument("--objects", default=_BENCH_OBJECTS, help="comma-separated objects, or a set name")
    p.add_argument("--poses-per-object", type=int, default=4)
    p.add_argument("--designs-per-pose", type=int, default=35)
    p.add_argument("--backend", choices=("mujoco", "mjwarp"), default="mujoco")
    p.add_argument("--device", choices=WARP_DEVICES, default="auto")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--repeats",
        type=int_at_least(1),
        default=2,
        help="raw and pipeline passes, alternated (fastest kept)",
    )
    p.add_argument("--out", default=None, help="also write the JSON to this file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run_bench)


def _scenario(text: str | None, base):
    """``base`` (a GraspScenario) with the fields ``--scenario`` gives (JSON text or a JSON file)."""
    from mjcodesign.errors import DesignError
    from mjcodesign.scenarios.grasp import GraspScenario

    if text is None:
        return base
    raw = Path(text).read_text(encoding="utf-8") if Path(text).is_file() else text
    try:
        fields = json.loads(raw)
    except ValueError:
        raise DesignError("--scenario must be a JSON object or a JSON file") from None
    names = {f.name for f in dataclasses.fields(GraspScenario)} - {"tension", "tendon"}
    if not isinstance(fields, dict) or set(fields) - names:
        bad = sorted(set(fields) - names) if isinstance(fields, dict) else fields
        raise DesignError(
            f"--scenario: unknown fields {bad} (the tendon is set by --tendon); known: {sorted(names)}"
        )
    if "impulse" in fields and "delta_v" not in fields:
        fields["delta_v"] = None  # an impulse [N s] replaces the regime's velocity change
    try:
        return dataclasses.replace(base, **fields)
    except TypeError as exc:
        raise DesignError(f"--scenario: {exc}") from None


def datagen_config(args: argparse.Namespace):
    """The :class:`~mjcodesign.data.DatagenConfig` of ``datagen``'s arguments (library errors: exit 2).

    ``--regime`` gives the scenario, the tendon, the density and the mass rule; the flags that name one
    replace it.
    """
    from mjcodesign.data import (
        DatagenConfig,
        parse_density_spec,
        parse_perturbations,
        parse_tendon,
        resolve_objects,
    )
    from mjcodesign.scenarios import get_regime

    draws, extend_to = parse_perturbations(args.perturbations)
    regime = get_regime(args.regime)
    density, mass = regime.masses(args.density, args.mass)
    scenario = _scenario(args.scenario, regime.scenario)
    same = ("poses_per_object", "designs_per_pose", "model", "backend", "sampler", "seed", "object_seed")
    return DatagenConfig(
        objects=resolve_objects(args.objects),
        density=parse_density_spec(density),
        tendon=scenario.tendon if args.tendon is None else parse_tendon(args.tendon),
        scenario=scenario,
        mass=mass,
        perturbations=draws,
        perturbations_max=extend_to,
        routing=args.routing,
        **{k: getattr(args, k) for k in same},
    )


def quiet_worker() -> None:
    """Run first in every worker process: Warp's banner and module log off stdout (the JSON goes there)."""
    if importlib.util.find_spec("warp") is not None:
        try:
            quiet_warp()
        except (ImportError, OSError, RuntimeError):
            pass  # the task that needs Warp reports it


def _device(args: argparse.Namespace) -> str:
    """Warp device for ``--device`` (auto: CUDA when present); checks the mjwarp backend is installed."""
    from mjcodesign.errors import DesignError

    if args.backend != "mjwarp":
        return "cpu"
    if importlib.util.find_spec("mujoco_warp") is None or importlib.util.find_spec("warp") is None:
        raise DesignError("--backend mjwarp needs mujoco-warp and warp-lang (pip install 'mjcodesign[warp]')")
    quiet_worker()
    from mjcodesign.optional import warp_device

    return warp_device(args.device)


def _check_run(args: argparse.Namespace, config) -> None:
    """Refuse what cannot run before anything is written."""
    from mjcodesign.data import MANIFEST
    from mjcodesign.errors import DesignError, UnsupportedError

    if args.workers < 1:
        raise DesignError(f"--workers must be >= 1, got {args.workers}")
    if args.ray is not None:
        if args.workers != 1:
            raise DesignError("--ray runs the shards on Ray's CPUs: leave --workers at 1")
        if importlib.util.find_spec("ray") is None:
            raise DesignError("--ray needs the ray package (pip install 'mjcodesign[ray]')")
    if args.resume and not (Path(args.out) / MANIFEST).is_file():
        raise DesignError(
            f"--resume: {args.out} holds no dataset to resume (run without --resume to start one)"
        )
    if config.backend == "mjwarp" and config.model.is_flex:
        raise UnsupportedError(
            "--backend mjwarp batches designs as worlds, which share flex stiffness: use mujoco"
        )


class _DatagenProgress:
    """``datagen``'s progress (:class:`~mjcodesign.cli.progress.StageProgress`), from the run's events.

    Two stages: ``posing objects`` (each object prepared or failed) and ``shards`` (each shard written,
    with the samples/s of this run); an object that failed or has fewer poses than asked says why in
    one line.
    """

    def __init__(self, *, stream=None, tty: bool | None = None):
        from mjcodesign.cli.progress import StageProgress

        self.bar = StageProgress("datagen", stream=stream, tty=tty)
        self.objects = self.objects_done = self.shards = self.shards_done = self.samples = 0

    def __enter__(self):
        self.bar.__enter__()
        return self

    def __exit__(self, *exc):
        return self.bar.__exit__(*exc)

    def __call__(self, event) -> None:
        if event.kind == "start":
            self.objects, self.shards, self.shards_done = event.objects, event.total, event.done
            if self.objects:
                self.bar.update("posing objects", 0, self.objects)
            self.bar.update("shards", self.shards_done, self.shards)
        elif event.kind in ("object", "object_failed"):
            self.objects_done += 1
            self.shards = event.total
            name = event.keys[0]
            self.bar.update("posing objects", self.objects_done, self.objects, unit=name)
            if event.message:
                verb = "failed: " if event.kind == "object_failed" else ""
                self.bar.note(f"{name}: {verb}{event.message}")
        elif event.kind in ("shard", "shard_failed"):
            self.shards_done += 1
            self.samples += event.samples + event.rejected
            rate = self.samples / max(time.perf_counter() - self.bar.t0, 1e-9)
            detail = f"{rate:.3g} samples/s" + (" (failed)" if event.kind == "shard_failed" else "")
            self.bar.update("shards", self.shards_done, self.shards, unit=event.keys[0], detail=detail)


def _ray_environment(ray: str | None) -> None:
    """Ray's settings for ``--ray``: a local instance on loopback, or a short first connection to a head.

    ``--ray local`` asks for a new Ray on this machine, so ``RAY_ADDRESS`` (which Ray would otherwise
    join) is removed from this process's environment, with a note on stderr.
    """
    if ray == "local":
        joined = os.environ.pop("RAY_ADDRESS", None)
        if joined:
            sys.stderr.write(
                f"datagen: --ray local starts a Ray on this machine; RAY_ADDRESS={joined} is ignored "
                f"(--ray {joined} joins that cluster)\n"
            )
        for k, v in _RAY_LOCAL_ENV.items():
            os.environ.setdefault(k, v)
    elif ray is not None:
        for k, v in _RAY_JOIN_ENV.items():
            os.environ.setdefault(k, v)


def run_datagen(args: argparse.Namespace) -> int:
    """Run ``datagen``: the summary JSON on stdout; library errors propagate (exit 2 there)."""
    from concurrent.futures.process import BrokenProcessPool

    from mjcodesign.data import generate

    config = datagen_config(args)
    _check_run(args, config)
    device = _device(args)
    quiet_worker()  # the poses' SDF runs on Warp in this process with --workers 1
    _ray_environment(args.ray)
    try:
        # stdout is the summary's: what else prints during the run (Ray's cluster messages, such as a
        # node that died) goes to stderr with the progress.
        with _DatagenProgress() as bar, contextlib.redirect_stdout(sys.stderr):
            res = generate(
                config,
                args.out,
                workers=args.workers,
                ray=args.ray,
                device=device,
                cache_dir=user_cache_dir(),
                worker_setup=quiet_worker,
                command=["mjcodesign", *sys.argv[1:]],
                on_event=bar,
            )
    except BrokenProcessPool:
        sys.stderr.write("error: a worker process died (out of memory?); rerun the same command to resume\n")
        return 1
    print(json.dumps(res))
    warn_failed_objects(args.out)
    return 0


def success_warning(rate: float, samples: int) -> str | None:
    """The one-line warning ``data info`` gives on a dataset whose success rate is near 0 or 1, else None."""
    if samples == 0 or _SUCCESS_LOW <= rate <= _SUCCESS_HIGH:
        return None
    side = f"above {_SUCCESS_HIGH:.0%}" if rate > _SUCCESS_HIGH else f"below {_SUCCESS_LOW:.0%}"
    return (
        f"success rate {rate:.1%} of {samples} samples is {side}: a surrogate trained on it sees almost one "
        "outcome (change the density or mass, the tendon or the disturbance)"
    )


def run_info(args: argparse.Namespace) -> int:
    """Run ``data info``."""
    from mjcodesign.data import open_dataset, plot_success, summarize

    ds = open_dataset(args.dir)
    res = summarize(ds)
    warning = success_warning(res["success_rate"], res["samples"])
    if warning:
        print(f"warning: {warning}", file=sys.stderr, flush=True)
    if args.plot:
        res["plot"] = str(plot_success(ds, args.plot))
    if args.json:
        print(json.dumps(res))
        return 0
    flat = {k: v for k, v in res.items() if not isinstance(v, dict)}
    emit(flat, False)
    rows = [{"object": k, **v} for k, v in res["by_object"].items()]
    if rows:
        emit(
            [
                {k: r.get(k, "") for k in ("object", "status", "poses", "samples", "success_rate")}
                for r in rows
            ],
            False,
        )
    for key in ("by_density", "by_design_group"):
        emit([{key[3:]: k, **v} for k, v in res[key].items()] or [{key[3:]: "-"}], False)
    if "labels" in res:
        emit({f"labels: {k}": v for k, v in res["labels"].items()}, False)
    for key in ("failures", "rejected_by_kind", "rejected_top_reasons"):
        if res[key]:
            emit({f"{key}: {k}": v for k, v in res[key].items()}, False)
    return 0


def run_verify(args: argparse.Namespace) -> int:
    """Run ``data verify``: the report on stdout; a damaged dataset exits 2 with one line naming its files."""
    from mjcodesign.data import open_dataset
    from mjcodesign.errors import DatasetError

    found = open_dataset(args.dir).verify()
    report = {"path": str(args.dir), **found.as_dict()}
    if args.json:
        print(json.dumps(report))
    else:
        emit({k: v for k, v in report.items() if k != "damaged"}, False)
    if found.damaged:
        lines = [d.line() for d in found.damaged]
        shown = "; ".join(lines[:_DAMAGED_SHOWN]) + (
            f"; and {len(lines) - _DAMAGED_SHOWN} more" if len(lines) > _DAMAGED_SHOWN else ""
        )
        raise DatasetError(f"{args.dir}: {len(lines)} damaged file(s): {shown}")
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Run ``bench datagen``."""
    from mjcodesign.bench.datagen import bench_datagen
    from mjcodesign.data import resolve_objects

    device = _device(args)
    quiet_worker()
    res = bench_datagen(
        objects=list(resolve_objects(args.objects)),
        poses_per_object=args.poses_per_object,
        designs_per_pose=args.designs_per_pose,
        backend=args.backend,
        device=device,
        seed=args.seed,
        cache_dir=user_cache_dir(),
        repeats=args.repeats,
    )
    if args.out:
        from mjcodesign.bench import write_json

        write_json(res, args.out)
    if args.json:
        print(json.dumps(res))
    else:
        emit({k: v for k, v in res.items() if not isinstance(v, dict | list)}, False)
    return 0
