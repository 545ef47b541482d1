"""The grasp landscape: how much design signal the grasp scenario carries, and how robust that signal is.

A fixed set: objects × sampler poses × designs (soft, semi-rigid, paper-optimized and random ones) ×
densities × tendon drives, run through :func:`mjcodesign.jobs.run_jobs` (the designs at one pose are
one ``mujoco.rollout`` call). Per drive and density it reports:

* success per design group (``soft``, ``semi-rigid``, ``paper-optimized``, ``random``);
* (object, pose) pairs where every, some or no design succeeds;
* the spread of each outcome across designs at a fixed pose (the standard deviation over designs,
  averaged over pairs): displacement, lift height, vertical hold force;
* implausible, diverged and far (object more than :data:`FAR` from where the grasp held it) counts,
  how many far ones the energy bound flagged implausible, NaN outputs; failure kinds per design group;
* CPU seconds per rollout.

``sweep`` adds how the landscape moves with one setting at a time: the tendon (force tension, position
ticks), the object density, and the disturbance (none, the default impulse in N·s, and the same Δv for
every object).

``regime="real"`` runs the landscape of the real regime instead
(:func:`mjcodesign.bench.landscape_real.bench_landscape_real`: the suite's in-domain objects at their
published masses under :data:`~mjcodesign.scenarios.grasp.REAL_REGIME`, with intervals and a
sensitivity table).

A density ``real`` places every object at its published mass (:func:`mjcodesign.objects.published_mass`,
uniform density mass / volume); an object without one is listed under ``skipped``.
"""

from __future__ import annotations

import time
from collections import Counter

import numpy as np

from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.models.types import FingerModel
from mjcodesign.objects import parse_density, published_mass, real_density
from mjcodesign.poses import sample_poses, to_gripper_pose
from mjcodesign.scenarios import DEFAULT_IMPULSE, GraspScenario, parse_tendon
from mjcodesign.scenarios.outcome import Failure
from mjcodesign.sim import MujocoBackend

__all__ = ["bench_landscape", "OBJECTS", "DESIGNS", "SWEEP_DESIGNS", "FAR", "CI", "REAL", "REGIMES"]

OBJECTS = (
    "012_strawberry",
    "013_apple",
    "014_lemon",
    "017_orange",
    "018_plum",
    "056_tennis_ball",
    "010_potted_meat_can",
    "004_sugar_box",
)
"""Eight in-domain YCB objects that fit the 60-mm stroke: fruit, two balls, a can and a box."""
DESIGNS = ("soft", "semi-rigid", "paper-optimized") + tuple(f"random:{s}" for s in range(8))
"""The presets and eight random designs (`Stiffness.random` seeds 0-7)."""
FAR = 0.1
"""An object displaced more than this [m] (palm frame, grasp to end) has left the grasp for good."""
SWEEP_DESIGNS = ("soft", "semi-rigid", "paper-optimized", "random:0", "random:1")
"""The designs of the sweep (on fewer poses: it has 15 settings)."""
CI = {"objects": ("013_apple",), "poses": 2, "designs": ("soft", "semi-rigid", "random:1"), "sweep": False}
"""The short version the tests run."""
_DELTA_V = 0.5
"""Δv [m/s] of the fixed-Δv disturbance: the default 0.0179 N·s on the 35 g potted-meat can."""
_SWEEP_TENDONS = ("force:2", "force:4", "force:25", "position:500", "position:1500")
_SWEEP_DENSITIES = (10.0, 400.0)
"""10 kg/m³: the authors' density 2 at real size for equal grip-to-weight."""
REAL = "real"
"""The density entry that places every object at its published mass."""
REGIMES = ("paper", REAL)
"""``paper``: the blocks and sweep over densities and tendon drives; ``real``: the real regime's landscape."""


def _rho(obj, density: str | float) -> float:
    """The object's density [kg/m³] for a density entry: a preset, a number, or :data:`REAL`."""
    if density == REAL:
        return real_density(obj, published_mass(obj.name).mass)
    return parse_density(density)


def _group(name: str) -> str:
    return "random" if name.startswith("random:") else name


def bench_landscape(
    *,
    regime: str = "paper",
    objects: tuple[str, ...] | None = None,
    poses: int | None = None,
    designs: tuple[str, ...] = DESIGNS,
    densities: tuple[str, ...] = ("light", "heavy"),
    tendons: tuple[str, ...] = ("force:10", "position:1000"),
    sweep: bool = True,
    sweep_designs: tuple[str, ...] = SWEEP_DESIGNS,
    sweep_poses: int = 2,
    blocks: bool = True,
    seed: int = 0,
    model: str = "chain",
    nthread: int | None = None,
    sensitivity_designs: tuple[str, ...] | None = None,
    on_progress=None,
) -> dict:
    """Run the landscape (see the module docstring); returns a JSON-ready dict.

    ``regime="real"`` hands ``objects`` (default: the suite's in-domain objects), ``poses`` (default:
    all of the suite's), ``designs``, ``sweep`` (the sensitivity table), ``sensitivity_designs``,
    ``model``, ``nthread``, ``seed`` and ``on_progress`` to
    :func:`~mjcodesign.bench.landscape_real.bench_landscape_real`; the other arguments are the paper
    regime's. Otherwise ``objects`` defaults to :data:`OBJECTS` and ``poses`` to 4.

    ``poses``: sampler poses per object (:func:`mjcodesign.poses.sample_poses`, ``seed``); an object
    without any is listed under ``skipped`` with the reason. The sweep runs ``sweep_designs`` on the
    first ``sweep_poses`` poses of every object (each setting is a full block otherwise: 352 rollouts);
    ``blocks=False`` runs the sweep alone. ``on_progress(text)`` hears one line per block of rollouts.
    """
    if regime not in REGIMES:
        raise DesignError(f"unknown regime {regime!r}: choose from {', '.join(REGIMES)}")
    if regime == REAL:
        from mjcodesign.bench.landscape_real import bench_landscape_real

        return bench_landscape_real(
            objects=objects,
            poses=poses,
            designs=tuple(designs),
            sensitivity=sweep,
            sensitivity_designs=sensitivity_designs,
            model=model,
            nthread=nthread,
            seed=seed,
            on_progress=on_progress,
        )
    objects = OBJECTS if objects is None else objects
    poses = 4 if poses is None else poses
    if poses < 1 or not designs or not objects:
        raise DesignError("the landscape needs at least one object, pose and design")
    for tendon in tendons:  # refused before any object is posed, not after
        parse_tendon(tendon)
    for density in densities:
        if density != REAL:
            parse_density(density)
    backend = MujocoBackend(nthread)
    stiffness = {name: Stiffness.parse(name) for name in designs}
    loaded, skipped = [], {}
    for name in objects:
        try:
            if REAL in densities:
                published_mass(name)  # an object without a published mass is skipped with the reason
            obj = load_grasp_object(name, "light", seed=seed)
            cands = sample_poses(obj, poses, seed=seed)
            loaded.append((obj, [to_gripper_pose(cands, i) for i in range(len(cands))]))
        except Exception as exc:  # noqa: BLE001 - an object that cannot be posed is reported, not fatal
            skipped[name] = f"{type(exc).__name__}: {exc}"
    if not loaded:
        raise DesignError(f"no object could be loaded and posed: {skipped}")
    scenes = SceneCache(size=4)
    base = {"impulse": DEFAULT_IMPULSE}
    out_blocks = []
    for tendon in tendons if blocks else ():
        for density in densities:
            out_blocks.append(
                _block(
                    loaded,
                    stiffness,
                    backend,
                    scenes,
                    model,
                    tendon,
                    density,
                    base,
                    label=f"{tendon} {density}",
                )
            )
            if on_progress:
                on_progress(out_blocks[-1]["label"])
    out = {
        "objects": [o.name for o, _ in loaded],
        "poses_per_object": {o.name: len(p) for o, p in loaded},
        "skipped": skipped,
        "designs": list(designs),
        "model": model,
        "seed": seed,
        "far_m": FAR,
        "blocks": out_blocks,
    }
    if sweep:
        loaded = [(o, p[:sweep_poses]) for o, p in loaded]
        stiffness = {name: Stiffness.parse(name) for name in sweep_designs}
        out["sweep_designs"], out["sweep_poses"] = list(sweep_designs), sweep_poses
        light = REAL if REAL in densities else parse_density("light")  # the base every change is set against
        settings = [(t, light, base, f"tendon {t}") for t in _SWEEP_TENDONS]
        for mode in tendons:
            settings.append((mode, light, base, f"base {mode}"))  # what each change is measured against
            settings += [(mode, rho, base, f"density {rho:g} {mode}") for rho in _SWEEP_DENSITIES]
            settings.append((mode, light, {"impulse": 0.0}, f"impulse 0 {mode}"))
            settings.append((mode, light, {"delta_v": _DELTA_V}, f"impulse dv {_DELTA_V} m/s {mode}"))
        rows = []
        for tendon, rho, disturbance, label in settings:
            rows.append(
                _block(loaded, stiffness, backend, scenes, model, tendon, rho, disturbance, label=label)
            )
            if on_progress:
                on_progress(label)
        out["sweep"] = rows
    return out


def _block(
    loaded, stiffness, backend, scenes, model, tendon: str, density, disturbance: dict, *, label: str
) -> dict:
    """Every object, pose and design under one tendon drive, density (or :data:`REAL`) and disturbance."""
    drive = parse_tendon(tendon)
    jobs, masses = [], {}
    for obj, poses in loaded:
        rho = _rho(obj, density)
        mass = masses[obj.name] = obj.mass * rho / obj.density
        impulse = disturbance.get("impulse", mass * disturbance.get("delta_v", 0.0))
        scenario = GraspScenario(tendon=drive, impulse=float(min(impulse, 5.0)))
        for p, pose in enumerate(poses):
            for name, st in stiffness.items():
                jobs.append(
                    GraspJob(
                        obj=obj,
                        pose=pose,
                        design=st,
                        finger_model=FingerModel(model),
                        scenario=scenario,
                        density=rho,
                        label=f"{obj.name}/{p}/{name}",
                    )
                )
    cpu0, wall0 = time.process_time(), time.perf_counter()
    outs = run_jobs(jobs, backend, scenes=scenes)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    return {**_summary(jobs, outs, label, tendon, density, disturbance, cpu, wall), "mass_kg": masses}


def _summary(jobs, outs, label, tendon, density, disturbance, cpu, wall) -> dict:
    groups: dict[str, list[bool]] = {}
    pairs: dict[tuple[str, str], list] = {}
    kinds: Counter = Counter()
    by_group: dict[str, Counter] = {}
    far = far_flagged = nan = 0
    for job, out in zip(jobs, outs, strict=True):
        obj, pose, name = job.label.split("/", 2)
        groups.setdefault(_group(name), []).append(out.success)
        pairs.setdefault((obj, pose), []).append((job, out))
        kinds.update(f.value for f in out.failures)
        by_group.setdefault(_group(name), Counter()).update(f.value for f in out.failures)
        vals = np.array(out.body_force + out.displacement + (out.lift_height,))
        nan += int(not np.all(np.isfinite(vals)))
        unsimulated = out.failure in (Failure.DIVERGED, Failure.BAD_POSE)
        is_far = np.linalg.norm(out.displacement) > FAR and not unsimulated
        far += int(is_far)
        far_flagged += int(is_far and Failure.IMPLAUSIBLE in out.failures)
    cats = Counter()
    spread = {"displacement_m": [], "lift_height_m": [], "hold_force_z_n": []}
    for members in pairs.values():
        ok = [o.success for _, o in members]
        cats["all" if all(ok) else "none" if not any(ok) else "mixed"] += 1
        usable = [o for _, o in members if not (o.failure and o.failure.is_sample_error)]
        if len(usable) > 1:
            spread["displacement_m"].append(float(np.std([np.linalg.norm(o.displacement) for o in usable])))
            spread["lift_height_m"].append(float(np.std([o.lift_height for o in usable])))
            spread["hold_force_z_n"].append(float(np.std([o.body_force[5] for o in usable])))
    return {
        "label": label,
        "tendon": tendon,
        "density_kg_m3": None if density == REAL else parse_density(density),
        "mass": "real" if density == REAL else "density",
        "disturbance": disturbance,
        "rollouts": len(outs),
        "success": {g: float(np.mean(v)) for g, v in groups.items()},
        "success_all": float(np.mean([o.success for o in outs])),
        "pairs": {k: cats.get(k, 0) for k in ("all", "mixed", "none")},
        "spread_across_designs": {k: (float(np.mean(v)) if v else None) for k, v in spread.items()},
        "implausible": kinds.get(Failure.IMPLAUSIBLE.value, 0),
        "diverged": kinds.get(Failure.DIVERGED.value, 0),
        "bad_pose": kinds.get(Failure.BAD_POSE.value, 0),
        "far": far,
        "far_implausible": far_flagged,
        "nan": nan,
        "failures": dict(kinds),
        "failures_by_group": {g: dict(c) for g, c in by_group.items()},
        "cpu_s_per_rollout": cpu / max(len(outs), 1),
        "wall_s": wall,
    }
