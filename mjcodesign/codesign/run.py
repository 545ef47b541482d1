"""One co-design run, end to end: candidate poses, the surrogate, Algorithm 1, files, ground truth.

:func:`run_codesign` is what ``mjcodesign optimize`` runs. It checks every input before it writes
anything (an object without poses, a checkpoint of another schema), then writes into ``out``:

- ``design.txt`` (joint) or ``designs/OBJECT.txt`` (individual): the ``--design`` text of the design;
- ``poses/OBJECT.json``: each object's chosen pose, the ``grasp --pose`` JSON;
- ``curves.png``: counted L_opt per object and in total;
- ``result.json``: everything the command prints with ``--json``, and the loss curves.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mjcodesign.codesign.optimize import Mode, Objective, OptimizeConfig, OptimizeResult, Step, optimize
from mjcodesign.codesign.problem import PoseSet, load_pose_set, object_key, real_densities
from mjcodesign.codesign.report import (
    design_text,
    plot_curves,
    pose_record,
    write_design,
    write_json,
    write_pose,
)
from mjcodesign.codesign.verify import verify
from mjcodesign.errors import MeshError
from mjcodesign.objects import parse_density
from mjcodesign.outputs import OutputFolder, OutputKind, check_output, staged

__all__ = ["held_out_objects", "run_codesign"]


def held_out_objects(meta: dict, available: tuple[str, ...], optimised: tuple[str, ...]) -> tuple[str, ...]:
    """The checkpoint's test objects (never trained on) that have poses here and were not optimised for."""
    test = (meta.get("split") or {}).get("test_objects") or []
    return tuple(n for n in test if n in available and n not in optimised)


def dataset_masses(surrogate, density: float | None, mass: str | None) -> tuple[float, str]:
    """(density [kg/m³], mass rule) of a co-design: the given ones, else the checkpoint dataset's.

    The dataset's rule (``density``, ``real``, ``auto``) and its density when it is one value; a
    dataset drawn over a range, or a checkpoint without its dataset's config, gives ``light`` (the
    paper's protocol's table density).
    """
    from mjcodesign.surrogate import dataset_config

    config = dataset_config(surrogate)
    if mass is None:
        mass = "density" if config is None else config.mass
    if density is None:
        fixed = config is not None and config.density.is_fixed
        density = config.density.low if fixed else parse_density("light")
    return float(density), mass


def run_codesign(
    *,
    checkpoint: str | Path,
    objects: tuple[str, ...],
    poses: str | Path,
    per_object: int,
    density: float | None,
    out: str | Path,
    config: OptimizeConfig,
    mass: str | None = "density",
    overwrite: bool = False,
    seed: int = 0,
    ground_truth: bool = True,
    cache_dir: str | Path | None = None,
    sources: dict[str, str] | None = None,
    on_step: Callable[[Step], None] | None = None,
    progress: Callable[[str], None] | None = None,
    variants: dict[str, str | Path] | None = None,
    robust: str = "worst",
) -> tuple[dict, OptimizeResult]:
    """Optimise, re-simulate and write the files (module docstring); returns the JSON and the result.

    ``out`` follows the output-folder rule of :mod:`mjcodesign.outputs`, checked before any work
    (``overwrite``: write beside another writer's files, keeping them); the files land there at once.
    ``density`` and ``mass`` None: the checkpoint dataset's (:func:`dataset_masses`).
    ``mass="real"`` puts every object at its published mass instead of ``density``
    (:func:`~mjcodesign.codesign.problem.real_densities`): an optimised object without one is refused,
    a held-out one left out and named in ``held_out_without_mass``. ``sources`` maps an object's name
    to the mesh file that loads it (the command's ``--objects`` files): the candidates' clouds and the
    re-simulation use that mesh (:func:`~mjcodesign.codesign.problem.load_pose_set`).

    ``variants`` (name -> checkpoint, each trained on a dataset of one model variant: another tendon
    routing, friction, …) makes the co-design robust (:mod:`~mjcodesign.codesign.robust`): ``checkpoint``
    is the nominal model, ``robust`` (``worst`` or ``mean``) combines the variants' losses, and the
    ground truth is simulated under the nominal model and under each variant's
    (``ground_truth_variants``).
    """
    from mjcodesign.surrogate import load_surrogate

    folder = check_output(
        out, OutputKind.CODESIGN, overwrite=overwrite, inputs={"--ckpt": checkpoint, "--poses": poses}
    )
    say = progress or (lambda _msg: None)
    surrogate = load_surrogate(checkpoint)  # first: a checkpoint of another schema is refused in ~1 s
    variant_models = {}
    if variants:
        surrogate, variant_models = _variant_surrogate(surrogate, variants, robust)
    say("reading poses")
    everything = load_pose_set(poses, seed=seed, cache_dir=cache_dir, sources=sources)
    chosen_set = everything.select([object_key(o) for o in objects], per_object)
    held = held_out_objects(surrogate.meta, everything.objects, chosen_set.objects)
    no_mass: list[str] = []
    density, mass = dataset_masses(surrogate, density, mass)
    if mass == "real":
        density = real_densities(chosen_set)  # refuses an optimised object without a published mass
        for name in held:
            try:
                density.update(real_densities(everything.select([name], per_object)))
            except MeshError:
                no_mass.append(name)
        held = tuple(n for n in held if n not in no_mass)
    elif mass == "auto":
        density = real_densities(
            everything.select((*chosen_set.objects, *held), per_object), fallback=density
        )
    elif mass != "density":
        raise MeshError(f"mass must be density, real or auto, got {mass!r}")
    held_set = everything.select(held, per_object) if held else None
    root = Path(out)
    say(f"optimising {len(chosen_set.objects)} objects ({config.mode.value})")
    result = optimize(surrogate, chosen_set, density, config, on_step=on_step)
    truth, variant_truth = None, {}
    if ground_truth:
        say("re-simulating in MuJoCo")
        object_seed = int((surrogate.meta.get("dataset") or {}).get("object_seed", 0))
        designs = [result.design_of(k) for k in range(len(chosen_set.objects))]
        sets = {"optimised": (chosen_set, designs, result.chosen)}
        if held_set is not None:
            joint = [result.designs[0]] * len(held_set.objects) if config.mode is Mode.JOINT else None
            sets["held_out"] = (held_set, joint, None)
        truth = verify(
            surrogate,
            sets,
            density,
            object_seed=object_seed,
            cache_dir=cache_dir,
            loss=_loss(config),
            progress=say,
        )
        for name, (scenario, options) in variant_models.items():
            say(f"re-simulating in MuJoCo under {name}")
            variant_truth[name] = verify(
                surrogate,
                sets,
                density,
                object_seed=object_seed,
                cache_dir=cache_dir,
                scenario=scenario,
                options=options,
                loss=_loss(config),
                progress=say,
            )
    record = _record(result, chosen_set, held, truth, checkpoint, poses, density, seed, root)
    record.update(mass=mass, held_out_without_mass=no_mass)
    if variants:
        record["robust"] = {
            "rule": surrogate.rule.value,
            "variants": {n: str(p) for n, p in variants.items()},
        }
        record["ground_truth_variants"] = variant_truth or None
    _write(folder, result, chosen_set, record)
    return record, result


def _variant_surrogate(nominal, variants: dict, robust: str):
    """The nominal and the ``variants``' checkpoints as one :class:`VariantSurrogate`, and the models.

    The models: each variant's (scenario, model options) for its ground truth, read from its dataset's
    config. Raises :class:`DesignError` for a variant whose checkpoint records no dataset config (its model
    cannot be simulated) or whose finger model or geometry differs from the nominal's.
    """
    from mjcodesign.codesign.robust import VariantSurrogate
    from mjcodesign.errors import DesignError
    from mjcodesign.models.types import SimOptions
    from mjcodesign.surrogate import dataset_config, load_surrogate

    base = dataset_config(nominal)
    if base is None:
        raise DesignError(
            "--robust: the --ckpt checkpoint records no dataset config, so no variant can be compared with it"
        )
    members, models = [("nominal", nominal)], {}
    for name, path in variants.items():
        s = load_surrogate(path)
        c = dataset_config(s)
        if c is None:
            raise DesignError(
                f"--variant {path}: a robust co-design needs checkpoints that record their dataset"
            )
        if (c.model, c.geometry) != (base.model, base.geometry):
            raise DesignError(
                f"--variant {path}: its dataset's finger model or geometry is not the nominal's"
            )
        members.append((name, s))
        models[name] = (c.scenario, c.options or SimOptions())
    return VariantSurrogate(members, robust), models


def _loss(config: OptimizeConfig):
    """The loss the optimisation used, for the presets' poses and the prediction (None: the paper's)."""
    if config.objective is Objective.SUCCESS:
        return config.success_loss()
    return None


def _record(result, poses: PoseSet, held, truth, checkpoint, source, density, seed, root) -> dict:
    joint = result.mode is Mode.JOINT
    designs = {n: result.design_of(k).tolist() for k, n in enumerate(result.objects)}
    return {
        "design": result.designs[0].tolist() if joint else designs,
        "design_text": design_text(result.designs[0]) if joint else None,
        "design_file": str(root / "design.txt") if joint else str(root / "designs"),
        "mode": result.mode.value,
        "objects": list(result.objects),
        "held_out_objects": list(held),
        "best_pose": {
            n: {
                "row": int(result.chosen[k]),
                **pose_record(poses, int(result.chosen[k])),
                "file": str(root / "poses" / f"{n}.json"),
            }
            for k, n in enumerate(result.objects)
        },  # fmt: skip
        "iterations": result.iterations,
        "stopped": result.stopped,
        "phases": dict(zip(result.objects, result.phases, strict=True)),
        "loss": {"start": float(result.total_curve[0]), "end": float(result.total_curve[-1])},
        "wall_s": result.wall_s,
        "s_per_iteration": result.wall_s / max(1, result.iterations),
        "ground_truth": truth,
        "density_kg_m3": {n: float(v) for n, v in density.items()}
        if isinstance(density, dict)
        else float(density),
        "seed": int(seed),
        "checkpoint": str(checkpoint),
        "poses": str(source),
        "poses_per_object": int(max(len(poses.rows(k)) for k in range(len(poses.objects)))),
        "config": result.config,
        "curves_png": str(root / "curves.png"),
    }


def _write(folder: OutputFolder, result: OptimizeResult, poses: PoseSet, record: dict) -> None:
    """Every file into the folder's temporary sibling, then swapped into place: a failure leaves nothing."""
    with staged(folder) as tmp:
        if result.mode is Mode.JOINT:
            write_design(tmp / "design.txt", result.designs[0])
        else:
            (tmp / "designs").mkdir()
            for k, n in enumerate(result.objects):
                write_design(tmp / "designs" / f"{n}.txt", result.design_of(k))
        (tmp / "poses").mkdir()
        for k, n in enumerate(result.objects):
            write_pose(tmp / "poses" / f"{n}.json", poses, int(result.chosen[k]))
        plot_curves(result, tmp / "curves.png")
        full = dict(record, curves={"objects": list(result.objects), "loss": result.curves.tolist()})
        write_json(tmp / "result.json", full)
