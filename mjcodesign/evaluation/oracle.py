"""The oracle: CMA-ES on the simulator alone, on the evaluation's own objective.

No surrogate: each candidate design is rolled out on a suite's objects at every suite pose and the
first ``perturbations`` draws of each pose (the draws :func:`~mjcodesign.evaluation.run_suite` gives
every design: common random numbers), and scored as the evaluation scores a design
(:func:`~mjcodesign.evaluation.analysis.per_object_cells`): per object the share of its usable rollouts
that succeed under the pose policy (``all``: every pose; ``oracle``: the simulator's best pose for
that design), and the mean of those shares over objects. An object whose rollouts were all unusable
(diverged, implausible) counts 0, so a design cannot gain by breaking the simulator. The best design
is the upper bound of what one design reaches on these objects, within the budget and up to the
winner's curse of its draws (re-evaluate it on fresh draws or more of them: ``evaluate``).

The search variable is Algorithm 1's (z, ``ln E = 13.5 + 3.5 · sigmoid(z)``). ``start`` is one design (a
preset or design file) or several proposals, such as a surrogate's joint designs: every proposal is
scored first on the same rollouts, and the first generation is centred on the best of them, so the
result is never below any proposal on the search's own draws. With a surrogate's designs as the
proposals this is the surrogate-then-simulator loop: the surrogate proposes, the simulator verifies
and CMA-ES continues from the best verified proposal for the rest of the budget. A generation's designs go through the simulator together, one
object at a time (one compiled scene per object). ``cmaes`` is imported inside :func:`oracle_search`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from mjcodesign.codesign.optimize import LOG_E_MAX, LOG_E_MIN, log_e_of, z_of
from mjcodesign.design.stiffness import N_LOG_E, Stiffness
from mjcodesign.errors import DesignError, MjcodesignError, UnsupportedError
from mjcodesign.evaluation.analysis import ALL_POSES, object_rates, per_object_cells, select_policy
from mjcodesign.evaluation.config import DesignGroup
from mjcodesign.evaluation.rollouts import (
    SuiteRun,
    object_jobs,
    outcome_rows,
    prepare_object,
)
from mjcodesign.evaluation.suite import Suite
from mjcodesign.jobs import load_grasp_object, run_jobs
from mjcodesign.objects import parse_density
from mjcodesign.sim.protocol import get_backend

__all__ = [
    "MIN_POPULATION",
    "ORACLE_POLICIES",
    "OracleConfig",
    "OracleResult",
    "oracle_search",
    "score_designs",
]

ORACLE_POLICIES = (ALL_POSES, "oracle")
"""``all``: success over every suite pose (the table's "every pose"); ``oracle``: each object's best pose
for the design."""

MIN_POPULATION = 4
"""Fewer designs a generation leave CMA-ES's rank-mu update with no weight (cmaes divides by zero)."""
_INSIDE = 1e-3
"""How far inside the printable range a start at its bound is moved to have a z (ln Pa)."""

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, kw_only=True)
class OracleConfig:
    """CMA-ES settings of the oracle; the budget is in rollouts."""

    budget: int
    """Most rollouts; a generation that would pass it is not started."""
    policy: str = ALL_POSES
    sigma: float = 1.0
    """Initial step size in z (sigmoid's slope is 1/4 at 0: about 0.9 ln E)."""
    population: int | None = None
    """Designs per generation (None: CMA-ES's 4 + 3 ln 22 = 13)."""
    seed: int = 0
    """Seed of CMA-ES's own sampling (the draws are the suite run's)."""

    def __post_init__(self) -> None:
        if isinstance(self.budget, bool) or not isinstance(self.budget, int) or self.budget < 1:
            raise DesignError(f"budget must be an integer >= 1 rollouts, got {self.budget!r}")
        if self.policy not in ORACLE_POLICIES:
            raise DesignError(f"oracle policy {self.policy!r}: choose from {', '.join(ORACLE_POLICIES)}")
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise DesignError(f"sigma must be > 0, got {self.sigma}")
        if self.population is not None and (
            isinstance(self.population, bool) or self.population < MIN_POPULATION
        ):
            raise DesignError(f"population must be >= {MIN_POPULATION} designs, got {self.population!r}")


@dataclass
class OracleResult:
    """The best design found, its score per object, and the search's history."""

    objects: tuple[str, ...]
    design: np.ndarray
    """ln E of the best design, shape (22,)."""
    success: float
    """Mean over objects of the best design's success share (the objective)."""
    per_object: dict[str, float]
    start: str
    """Label of the proposal the search started from (the best of ``proposals``)."""
    start_success: float
    proposals: list[dict] = field(default_factory=list)
    """Every proposal scored before the search, in the order given: label, success, per-object shares."""
    proposal_rollouts: int = 0
    """Rollouts spent scoring the proposals (part of ``rollouts``)."""
    rollouts: int = 0
    evaluations: int = 0
    generations: int = 0
    curve: list[dict] = field(default_factory=list)
    """Per generation: rollouts so far, the generation's best and mean score, the best so far."""
    wall_s: float = 0.0

    def summary(self) -> dict:
        """JSON-ready."""
        return {
            "objects": list(self.objects),
            "design": self.design.tolist(),
            "success": self.success,
            "per_object": self.per_object,
            "start": self.start,
            "start_success": self.start_success,
            "gain_over_start": self.success - self.start_success,
            "proposals": self.proposals,
            "proposal_rollouts": self.proposal_rollouts,
            "rollouts": self.rollouts,
            "evaluations": self.evaluations,
            "generations": self.generations,
            "curve": self.curve,
            "wall_s": self.wall_s,
        }


class _Scorer:
    """Rolls designs out on the prepared objects and scores them; counts rollouts."""

    def __init__(self, suite: Suite, run: SuiteRun, policy: str, *, cache_dir=None, progress=None):
        self.suite, self.run, self.policy = suite, run, policy
        densities = [(str(d), parse_density(d)) for d in run.densities]
        self.prepared = []
        for i, so in enumerate(suite.objects):
            obj = load_grasp_object(so.source, "light", seed=suite.seed, cache_dir=cache_dir)
            # Every object is prepared before any rolls out: keeping each draw's scene would hold them all.
            self.prepared.append((so, prepare_object(suite, run, so, obj, densities, keep_scenes=False)))
            if progress:
                progress("preparing objects", i + 1, len(suite.objects))
        self.backend = get_backend("mujoco")
        self.rollouts = 0

    def __call__(self, designs: Sequence[Stiffness]) -> list[dict[str, float]]:
        """Per design, each object's success share (0 where no rollout was usable)."""
        groups = [DesignGroup(f"candidate{i}", "oracle", d) for i, d in enumerate(designs)]
        rows: list[dict] = []
        for so, prep in self.prepared:
            jobs, meta = object_jobs(prep, so, self.run, groups)
            rows += outcome_rows(so, meta, run_jobs(jobs, self.backend, scenes=prep.scenes))
            self.rollouts += len(jobs)
        found = object_rates(per_object_cells(select_policy(rows, self.policy)).values())
        names = [so.name for so, _ in self.prepared]
        return [{n: found[g.label].get(n, 0.0) for n in names} for g in groups]

    def per_design(self) -> int:
        """Rollouts one design costs (usable draws × regimes × impulses)."""
        draws = sum(sum(p is not None for p in d) for _, prep in self.prepared for d in prep.draws)
        regimes = len(self.prepared[0][1].regimes) if self.prepared else 0
        return draws * max(regimes, 1) * len(self.run.impulses)


def _check_budget(budget: int, population: int, per_design: int, starts: int = 1) -> None:
    if per_design * (population + starts) > budget:
        what = "the start" if starts == 1 else f"the {starts} proposals"
        raise DesignError(
            f"a budget of {budget} rollouts does not cover {what} and one generation "
            f"({population + starts} designs x {per_design} rollouts)"
        )


def score_designs(
    suite: Suite, run: SuiteRun, designs: Sequence[Stiffness], *, policy: str = ALL_POSES, cache_dir=None
) -> list[dict[str, float]]:
    """Each design's success share per object of ``suite``, as the oracle scores it."""
    return _Scorer(suite, run, policy, cache_dir=cache_dir)(designs)


def oracle_search(
    suite: Suite,
    run: SuiteRun,
    config: OracleConfig,
    *,
    start: DesignGroup | Sequence[DesignGroup],
    cache_dir=None,
    progress: Progress | None = None,
    on_generation: Callable[[OracleResult], None] | None = None,
) -> OracleResult:
    """CMA-ES over one design for every object of ``suite`` (module docstring).

    ``start``: one design, or proposals scored first (the search starts from the best; ties go to the
    first given). ``run`` gives the regime, scenario, draws per pose (``perturbations``), impulse (the
    first of ``impulses``) and seed; its ``designs`` are not used. ``on_generation`` gets the result so
    far.
    """
    try:
        from cmaes import CMA
    except ImportError:
        raise UnsupportedError("the oracle needs cmaes (pip install 'mjcodesign[codesign]')") from None
    starts = (start,) if isinstance(start, DesignGroup) else tuple(start)
    if not starts:
        raise DesignError("the oracle needs a design to start from")
    if any(s.design is None for s in starts):
        raise DesignError("the oracle starts from one design for every object (a preset or joint:FILE)")
    labels = [s.label for s in starts]
    if len(set(labels)) != len(labels):
        raise DesignError(f"the oracle's proposals repeat a design: {', '.join(labels)}")
    t0 = time.perf_counter()
    run = replace(run, designs=starts[:1], impulses=run.impulses[:1], pose_policies=("fixed",))
    population = config.population or 4 + int(3 * np.log(N_LOG_E))
    regimes = len(run.densities) if run.mass == "density" else 1
    _check_budget(
        config.budget,
        population,
        sum(len(o.poses) for o in suite.objects) * run.perturbations * regimes,
        len(starts),
    )
    try:
        scorer = _Scorer(suite, run, config.policy, cache_dir=cache_dir, progress=progress)
    except MjcodesignError as exc:
        raise DesignError(f"the oracle needs every suite object: {exc}") from exc
    names = tuple(so.name for so, _ in scorer.prepared)
    per_gen = scorer.per_design()  # draws given up cost nothing
    _check_budget(config.budget, population, per_gen, len(starts))
    proposal_rates = scorer([s.design for s in starts])
    proposals = [
        {"label": s.label, "success": float(np.mean(list(r.values()))), "per_object": r}
        for s, r in zip(starts, proposal_rates, strict=True)
    ]
    k = int(np.argmax([p["success"] for p in proposals]))  # the first of equal ones
    start, start_rate, start_score = starts[k], proposal_rates[k], proposals[k]["success"]
    start_design = np.asarray(start.design.log_e, dtype=float).ravel()
    best = (start_score, start_design, start_rate)
    opt = CMA(
        mean=z_of(np.clip(start_design, LOG_E_MIN + _INSIDE, LOG_E_MAX - _INSIDE)),
        sigma=config.sigma,
        seed=config.seed,
        population_size=population,
    )
    result = OracleResult(
        objects=names,
        design=start_design,
        success=start_score,
        per_object=start_rate,
        start=start.label,
        start_success=start_score,
        proposals=proposals,
        proposal_rollouts=scorer.rollouts,
        rollouts=scorer.rollouts,
        evaluations=len(starts),
    )
    while scorer.rollouts + opt.population_size * per_gen <= config.budget:
        zs = [opt.ask() for _ in range(opt.population_size)]
        designs = [Stiffness(log_e_of(z)) for z in zs]
        rates = scorer(designs)
        scores = [float(np.mean(list(r.values()))) for r in rates]
        opt.tell([(z, -s) for z, s in zip(zs, scores, strict=True)])
        i = int(np.argmax(scores))
        if scores[i] > best[0]:
            best = (scores[i], np.asarray(designs[i].log_e, dtype=float).ravel(), rates[i])
        result.generations += 1
        result.evaluations += len(designs)
        result.rollouts = scorer.rollouts
        result.success, result.design, result.per_object = best
        result.wall_s = time.perf_counter() - t0
        result.curve.append(
            {
                "generation": result.generations,
                "rollouts": scorer.rollouts,
                "best": scores[i],
                "mean": float(np.mean(scores)),
                "best_so_far": best[0],
            }
        )
        if on_generation is not None:
            on_generation(result)
        if progress:
            progress("generations", scorer.rollouts, config.budget)
    result.wall_s = time.perf_counter() - t0
    return result
