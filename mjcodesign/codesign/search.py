"""Baseline 2: direct search on the simulator, no surrogate (CMA-ES on MuJoCo C).

The same design variable (z, ``ln E = 13.5 + 3.5 · sigmoid(z)``) and the same objective as Algorithm 1,
with the simulator's outcomes in place of the surrogate's predictions: each candidate design is
rolled out at every candidate pose of every object (:func:`~mjcodesign.jobs.run_jobs`), L_opt is
computed per rollout (:class:`~mjcodesign.surrogate.DesignLoss`, the ground-contact flag as c_g),
each object counts its best pose, and the fitness is the sum over objects. A rollout the simulator
could not use (diverged, implausible, bad pose) counts as a failed grasp: ``penalty_weight · 1``.

The search stops when the rollouts spent reach ``budget`` (a whole generation that would pass it is
not started). ``cmaes`` (``pip install 'mjcodesign[codesign]'``) is imported inside :func:`cma_search`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mjcodesign.codesign.optimize import log_e_of, z_of
from mjcodesign.codesign.problem import PoseSet
from mjcodesign.design.stiffness import N_LOG_E, Stiffness
from mjcodesign.errors import DesignError, UnsupportedError
from mjcodesign.jobs import GraspJob, load_grasp_object, run_jobs
from mjcodesign.scenarios.grasp import GraspScenario
from mjcodesign.sim.mujoco_c import MujocoBackend

__all__ = ["SearchConfig", "SearchResult", "cma_search", "simulated_losses"]


@dataclass(frozen=True, kw_only=True)
class SearchConfig:
    """CMA-ES settings; the budget is in rollouts."""

    budget: int
    """Most rollouts (the issue: the number the surrogate's dataset needed)."""
    sigma: float = 1.0
    """Initial step size in z (sigmoid's slope is 1/4 at 0: about 0.9 ln E)."""
    init_log_e: float = 15.6
    """Mean of the first generation, every block (Algorithm 1's start)."""
    population: int | None = None
    """Designs per generation (None: CMA-ES's 4 + 3 ln 22 = 13)."""
    seed: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.budget, bool) or not isinstance(self.budget, int) or self.budget < 1:
            raise DesignError(f"budget must be an integer >= 1 rollouts, got {self.budget!r}")
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise DesignError(f"sigma must be > 0, got {self.sigma}")


@dataclass
class SearchResult:
    """The best design found, its simulated outcomes, and the search's history."""

    objects: tuple[str, ...]
    design: np.ndarray
    """ln E of the best design, shape (22,)."""
    fitness: float
    chosen: np.ndarray
    """Each object's best pose row at the best design, shape (K,)."""
    success: np.ndarray
    """Simulated success of each object at its chosen pose, shape (K,)."""
    rollouts: int = 0
    evaluations: int = 0
    generations: int = 0
    best_curve: list[float] = field(default_factory=list)
    """Best fitness so far after each generation."""
    wall_s: float = 0.0

    def summary(self) -> dict:
        """JSON-ready."""
        return {
            "objects": list(self.objects),
            "design": self.design.tolist(),
            "fitness": self.fitness,
            "chosen_pose_row": self.chosen.tolist(),
            "success": dict(zip(self.objects, self.success.tolist(), strict=True)),
            "success_rate": float(np.mean(self.success)),
            "rollouts": self.rollouts,
            "evaluations": self.evaluations,
            "generations": self.generations,
            "best_curve": self.best_curve,
            "wall_s": self.wall_s,
        }


def simulated_losses(outcomes, up: np.ndarray, loss=None) -> np.ndarray:
    """L_opt of each simulated outcome (the ground-contact flag as c_g), shape (n,).

    ``up``: the world vertical in the gripper frame of each outcome's pose, (n, 3).
    """
    import torch

    from mjcodesign.surrogate import DesignLoss

    base = loss or DesignLoss()
    f = torch.tensor([o.body_force for o in outcomes], dtype=torch.float64)
    d = torch.tensor([o.displacement for o in outcomes], dtype=torch.float64)
    c = torch.tensor([float(o.ground_contact) for o in outcomes], dtype=torch.float64)
    rows = base.rows(f, d, c, torch.as_tensor(np.asarray(up, dtype=float))).numpy().astype(float)
    unusable = np.array([o.failure is not None and o.failure.is_sample_error for o in outcomes], dtype=bool)
    return np.where(unusable, base.penalty_weight, rows)


class _Evaluator:
    """Rolls out one design at every pose of ``poses``; counts rollouts."""

    def __init__(self, poses: PoseSet, density: float, *, object_seed: int, cache_dir, scenario):
        self.poses = poses
        self.density = float(density)
        self.scenario = scenario or GraspScenario()
        objs = {
            n: load_grasp_object(n, density, seed=object_seed, cache_dir=cache_dir) for n in poses.objects
        }
        self.obj_of_row = [objs[poses.objects[k]] for k in poses.object_of]
        self.pose_of_row = [poses.gripper_pose(i) for i in range(len(poses))]
        self.backend = MujocoBackend()
        self.rollouts = 0

    def __call__(self, log_e) -> tuple[float, np.ndarray, np.ndarray]:
        """(fitness, each object's best pose row, each object's success there)."""
        design = Stiffness(np.asarray(log_e, dtype=float))
        jobs = [
            GraspJob(obj=o, pose=p, design=design, scenario=self.scenario, density=self.density)
            for o, p in zip(self.obj_of_row, self.pose_of_row, strict=True)
        ]
        outs = run_jobs(jobs, self.backend)
        self.rollouts += len(jobs)
        rows = simulated_losses(outs, self.poses.up)
        chosen, ok, total = [], [], 0.0
        for k in range(len(self.poses.objects)):
            r = self.poses.rows(k)
            best = int(r[np.argmin(rows[r])])
            chosen.append(best)
            ok.append(bool(outs[best].success))
            total += float(rows[best])
        return total, np.array(chosen), np.array(ok)


def cma_search(
    poses: PoseSet,
    density: float,
    config: SearchConfig,
    *,
    object_seed: int = 0,
    cache_dir=None,
    scenario: GraspScenario | None = None,
    on_generation: Callable[[SearchResult], None] | None = None,
) -> SearchResult:
    """CMA-ES over one design for all objects of ``poses`` (module docstring).

    ``on_generation`` gets the result so far after every generation.
    """
    try:
        from cmaes import CMA
    except ImportError:
        raise UnsupportedError(
            "the CMA-ES baseline needs cmaes (pip install 'mjcodesign[codesign]')"
        ) from None
    t0 = time.perf_counter()
    ev = _Evaluator(poses, density, object_seed=object_seed, cache_dir=cache_dir, scenario=scenario)
    per_eval = len(poses)
    opt = CMA(
        mean=z_of(np.full(N_LOG_E, config.init_log_e)),
        sigma=config.sigma,
        seed=config.seed,
        population_size=config.population,
    )
    best = (np.inf, None, None, None)
    curve: list[float] = []
    evaluations = generations = 0
    while ev.rollouts + opt.population_size * per_eval <= config.budget:
        told = []
        for _ in range(opt.population_size):
            z = opt.ask()
            log_e = log_e_of(z)
            fit, chosen, ok = ev(log_e)
            evaluations += 1
            told.append((z, fit))
            if fit < best[0]:
                best = (fit, log_e, chosen, ok)
        opt.tell(told)
        generations += 1
        curve.append(float(best[0]))
        if on_generation is not None:
            on_generation(_result(poses, best, ev.rollouts, evaluations, generations, curve, t0))
    if best[1] is None:
        raise DesignError(
            f"a budget of {config.budget} rollouts does not cover one generation "
            f"({opt.population_size} designs x {per_eval} poses)"
        )
    return _result(poses, best, ev.rollouts, evaluations, generations, curve, t0)


def _result(poses, best, rollouts, evaluations, generations, curve, t0) -> SearchResult:
    return SearchResult(
        objects=poses.objects,
        design=best[1],
        fitness=float(best[0]),
        chosen=best[2],
        success=best[3],
        rollouts=rollouts,
        evaluations=evaluations,
        generations=generations,
        best_curve=list(curve),
        wall_s=time.perf_counter() - t0,
    )
