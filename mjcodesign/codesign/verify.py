"""Ground truth for a co-design: the designs re-simulated in MuJoCo at the poses the surrogate picks.

For each object and each design compared (the optimised one, and the soft and semi-rigid presets):

* the pose: the optimised design's chosen pose on the objects it was optimised for; otherwise the
  candidate pose of lowest L_opt for that design (what the surrogate would pick for it);
* the surrogate's predicted success there (:meth:`~mjcodesign.surrogate.Surrogate.predict`): its
  success head's probability above one half under a loss that reads the head (the success objective's
  :class:`~mjcodesign.surrogate.SuccessLoss`), else the outputs' success score above zero; with a head,
  each row also carries the head's probability (``predicted_success_p``);
* the simulated outcome (:class:`~mjcodesign.jobs.GraspJob` on MuJoCo C through
  :func:`~mjcodesign.jobs.run_jobs`) under the dataset's grasp scenario (tendon drive included),
  finger model and geometry, as the checkpoint records them
  (:func:`~mjcodesign.surrogate.dataset_config`); a checkpoint that records none runs the default
  chain and :class:`GraspScenario` with the checkpoint's lift, and the result says so.

:func:`verify` returns rows and success rates per (object set, design), predicted beside simulated.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from mjcodesign.codesign.problem import PoseSet, object_key, row_densities
from mjcodesign.design.finger import FingerDesign
from mjcodesign.design.stiffness import PRESETS, Stiffness
from mjcodesign.jobs import GraspJob, load_grasp_object, run_jobs
from mjcodesign.models.types import FingerModel
from mjcodesign.scenarios.grasp import GraspScenario
from mjcodesign.sim.mujoco_c import MujocoBackend

__all__ = ["BASELINES", "pick_poses", "verify"]

BASELINES = ("soft", "semi-rigid")
"""Presets the optimised design is compared with."""


def pick_poses(surrogate, poses: PoseSet, design, density, loss=None) -> np.ndarray:
    """Per object, the pose row of lowest L_opt for ``design`` (22 ln E), shape (K,).

    ``density`` [kg/m³]: one for all objects or one per object name (:func:`row_densities`).
    """
    from mjcodesign.surrogate import GraspBatch, Poses

    rows = np.arange(len(poses))
    batch = GraspBatch(Poses.of(poses), rows, row_densities(poses, density))
    per_row = surrogate.loss_and_grad(np.asarray(design, dtype=float), batch, loss=loss).rows
    return np.array([poses.rows(k)[np.argmin(per_row[poses.rows(k)])] for k in range(len(poses.objects))])


def predicted_success(surrogate, poses: PoseSet, rows, designs, density):
    """The surrogate at pose ``rows`` with ``designs`` (one per row, (n, 22)): (success, score, p).

    The success is the outputs' (score above zero); ``p`` the success head's probability, shape (n,),
    or None for a network without a head.
    """
    from mjcodesign.surrogate import GraspBatch, Poses

    rows = np.asarray(rows, dtype=np.int64)
    batch = GraspBatch(
        Poses.of(poses), rows, row_densities(poses, density)[rows], np.asarray(designs, dtype=float)
    )
    pred = surrogate.predict(batch)
    return pred.success, pred.success_score, pred.success_p


def verify(
    surrogate,
    sets: dict[str, tuple[PoseSet, list | None, np.ndarray | None]],
    density: float | dict[str, float],
    *,
    object_seed: int = 0,
    cache_dir=None,
    scenario: GraspScenario | None = None,
    options=None,
    loss=None,
    progress=None,
) -> dict:
    """Simulate each set's objects with the optimised design(s) and the presets.

    ``sets``: name -> (poses, the optimised design of each object (22 ln E; None: only the presets),
    the optimised design's chosen pose rows (None: the surrogate picks them here)). ``scenario``
    replaces the dataset's, and ``options`` (:class:`~mjcodesign.models.types.SimOptions`, e.g. the
    tendon's routing) the dataset's model options. ``loss`` picks the presets' poses and, when it
    reads the success head (``needs_success_head``), makes the head's probability the prediction. Returns JSON-ready rows and
    rates per (set, design), ``predicted_by`` (``success head`` or ``score``), and ``simulation``: the
    scenario, tendon drive and finger model they ran under, and where those came from.
    """
    from mjcodesign.surrogate import dataset_config

    t0 = time.perf_counter()
    config = dataset_config(surrogate)
    if config is None:
        source = "defaults"
        model, geometry, dataset_options = FingerModel.CHAIN, FingerDesign(), None
        dataset_scenario = GraspScenario(lift=surrogate.lift, lifted_fraction=surrogate.lifted_fraction)
    else:
        source = "checkpoint"
        model, geometry, dataset_scenario = config.model, config.geometry, config.scenario
        dataset_options = config.options
    if scenario is not None:
        source, dataset_scenario = "given", scenario
    scenario = dataset_scenario
    options = dataset_options if options is None else options
    # An object goes by its name (a mesh file's stem); it is loaded from the source its poses recorded
    # (the command's mesh file, the dataset's), else from the checkpoint's dataset, else by its name.
    sources = {object_key(s): s for s in config.objects} if config is not None else {}
    by_head = bool(getattr(loss, "needs_success_head", False))
    jobs, meta = [], []
    for set_name, (poses, designs, chosen) in sets.items():
        objs = {}
        variants = [("optimised", designs)] + [(b, [PRESETS[b]] * len(poses.objects)) for b in BASELINES]
        for label, per_object in variants:
            if per_object is None or any(d is None for d in per_object):
                continue
            if label == "optimised" and chosen is not None:
                rows = np.asarray(chosen)
            else:
                rows = _pick_each(surrogate, poses, per_object, density, loss)
            ok, score, p = predicted_success(surrogate, poses, rows, np.array(per_object), density)
            if by_head:
                ok = p > 0.5
            rho = row_densities(poses, density)
            for k, name in enumerate(poses.objects):
                rho_k = float(rho[poses.rows(k)[0]])
                if name not in objs:
                    loads = poses.source_of(name) if poses.sources else sources.get(name, name)
                    objs[name] = load_grasp_object(loads, rho_k, seed=object_seed, cache_dir=cache_dir)
                design = Stiffness(per_object[k])
                jobs.append(
                    GraspJob(obj=objs[name], pose=poses.gripper_pose(int(rows[k])), design=design,
                             finger_model=model, scenario=scenario, density=rho_k,
                             seed=object_seed, geometry=geometry, options=options,
                             label=f"{set_name}/{label}/{name}")
                )  # fmt: skip
                p_k = None if p is None else float(p[k])
                meta.append((set_name, label, name, int(rows[k]), bool(ok[k]), float(score[k]), p_k))
    if progress is not None:
        progress(f"simulating {len(jobs)} grasps")
    outs = run_jobs(jobs, MujocoBackend())
    rows_out = [
        {
            "set": s,
            "design": label,
            "object": name,
            "pose_row": row,
            "predicted_success": pred,
            "predicted_score": score,
            **({} if p is None else {"predicted_success_p": p}),
            "simulated_success": bool(o.success),
            "reason": o.reason,
        }
        for (s, label, name, row, pred, score, p), o in zip(meta, outs, strict=True)
    ]
    rates = []
    for s in dict.fromkeys(r["set"] for r in rows_out):
        for label in dict.fromkeys(r["design"] for r in rows_out if r["set"] == s):
            sel = [r for r in rows_out if r["set"] == s and r["design"] == label]
            head = [r["predicted_success_p"] for r in sel if "predicted_success_p" in r]
            rates.append(
                {
                    "set": s,
                    "design": label,
                    "objects": len(sel),
                    "simulated_success": float(np.mean([r["simulated_success"] for r in sel])),
                    "predicted_success": float(np.mean([r["predicted_success"] for r in sel])),
                    **({"predicted_success_p": float(np.mean(head))} if head else {}),
                    "agreement": float(
                        np.mean([r["simulated_success"] == r["predicted_success"] for r in sel])
                    ),
                }
            )
    simulation = {
        "source": source,
        "model": model.value,
        "tendon": scenario.tendon.text(),
        "routing": "guided" if options is None else options.routing,
        "scenario": dataclasses.asdict(scenario),
    }
    return {
        "predicted_by": "success head" if by_head else "score",
        "rates": rates,
        "rows": rows_out,
        "rollouts": len(jobs),
        "simulation": simulation,
        "wall_s": time.perf_counter() - t0,
    }


def _pick_each(surrogate, poses: PoseSet, per_object, density, loss) -> np.ndarray:
    """The surrogate's pose for each object with its own design (one pass when all designs are equal)."""
    designs = np.asarray(per_object, dtype=float)
    if np.all(designs == designs[0]):
        return pick_poses(surrogate, poses, designs[0], density, loss)
    return np.array(
        [pick_poses(surrogate, poses.select([n], len(poses.rows(k))), designs[k], density, loss)[0]
         + poses.rows(k)[0] for k, n in enumerate(poses.objects)]
    )  # fmt: skip
