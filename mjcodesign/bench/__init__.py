"""Benchmarks are data: a registry of named benchmarks and one runner that returns and writes their JSON.

Each benchmark is a function returning a JSON-ready dict, named here as ``"module:function"`` and
imported only when run, so that importing this package pulls in neither MuJoCo nor Warp::

    from mjcodesign.bench import run_benchmark

    res = run_benchmark("finger", out="bench.json", models=["chain"], seconds=0.05)
"""

from __future__ import annotations

import importlib
import json
import os
from collections.abc import Callable

from mjcodesign.errors import DesignError
from mjcodesign.outputs import write_atomic

__all__ = ["BENCHMARKS", "benchmark", "run_benchmark", "write_json"]

BENCHMARKS: dict[str, str] = {
    "finger": "mjcodesign.bench.finger:bench_finger",
    "grasp": "mjcodesign.bench.grasp:bench_grasp",
    "poses": "mjcodesign.bench.poses:bench_poses",
    "viz": "mjcodesign.bench.viz:bench_viz",
    "fem": "mjcodesign.bench.fem:bench_fem",
    "landscape": "mjcodesign.bench.landscape:bench_landscape",
    "calibration": "mjcodesign.bench.calibration:bench_calibration",
    "datagen": "mjcodesign.bench.datagen:bench_datagen",
    "optimize": "mjcodesign.bench.optimize:bench_optimize",
    "surrogate": "mjcodesign.bench.surrogate:bench_surrogate",
    "evaluate": "mjcodesign.bench.evaluate:bench_evaluate",
    "labels": "mjcodesign.bench.labels:bench_labels",
}
"""Benchmark name -> ``"module:function"``; the function takes keyword arguments and returns a dict."""


def benchmark(name: str) -> Callable[..., dict]:
    """The function of the benchmark ``name``, imported now; raises DesignError for an unknown name."""
    try:
        target = BENCHMARKS[name]
    except KeyError:
        raise DesignError(f"unknown benchmark {name!r}: choose from {', '.join(BENCHMARKS)}") from None
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def write_json(result, out: str | os.PathLike, *, indent: int | None = 2) -> None:
    """Write ``result`` as JSON to ``out`` atomically (a temporary file beside it, then a rename).

    A reader never sees a half-written file, and a failed write leaves ``out`` as it was. Raises
    :class:`OutputError` when the file cannot be written.
    """
    write_atomic(out, json.dumps(result, indent=indent))


def run_benchmark(
    name: str, *, out: str | os.PathLike | None = None, command: str | None = None, **kwargs
) -> dict:
    """Run the benchmark ``name`` with ``kwargs``; write its JSON to ``out`` when given; return it.

    The result carries ``"provenance"`` (:func:`~mjcodesign.bench.record.provenance`): ``command`` (the
    command line that ran it, when given), date, installed version and commit, machine and load.
    """
    from mjcodesign.bench.record import provenance

    result = benchmark(name)(**kwargs)
    if isinstance(result, dict):
        result["provenance"] = provenance(name, command=command)
    if out:
        write_json(result, out)
    return result
