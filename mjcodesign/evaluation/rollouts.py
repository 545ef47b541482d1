"""Every rollout of a suite: objects × poses × perturbation draws × designs (× densities × disturbances).

Designs are compared on the same poses and the same draws (common random numbers): the draws of an
(object, pose) come from their own seeded stream (:meth:`PerturbationModel.stream`), whatever the
designs, worker count or order. A palm draw whose start overlaps the object or the ground by more than
the pose sampler accepts (:data:`~mjcodesign.poses.candidates.MAX_PENETRATION`) is drawn again: a robot
whose error would put its open fingers into the object meets it on the way down instead, and a start
inside it is not a grasp. Success comes from the simulator (MuJoCo C through :func:`run_jobs`); the
surrogate only scores poses for the ``surrogate`` pose policy.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import DesignError, MeshError, MjcodesignError, PoseError
from mjcodesign.evaluation.candidates import ObjectCandidates, predict_candidates
from mjcodesign.evaluation.config import DesignGroup
from mjcodesign.evaluation.suite import Suite, SuiteObject
from mjcodesign.jobs import GraspJob, SceneCache, load_grasp_object, run_jobs
from mjcodesign.models.types import FingerModel, SimOptions
from mjcodesign.objects import MASS_MODES, mass_by_rule, parse_density, published_mass
from mjcodesign.poses.candidates import MAX_PENETRATION
from mjcodesign.scenarios.grasp import GraspScenario, at_paper_disturbance, scene_at_pose
from mjcodesign.scenarios.outcome import Outcome
from mjcodesign.scenarios.perturb import MAX_REDRAWS, Perturbation, draw_perturbations
from mjcodesign.sim.protocol import get_backend

__all__ = [
    "MAX_REDRAWS",
    "POSE_POLICIES",
    "PreparedObject",
    "SuiteRun",
    "check_real_masses",
    "object_jobs",
    "outcome_rows",
    "prepare_object",
    "record_suite_examples",
    "run_suite",
]

POSE_POLICIES = ("fixed", "surrogate", "oracle")
"""``fixed``: each object's first pose; ``surrogate``: the surrogate's best pose for the design;
``oracle``: the simulator's best pose for the design (measured on the same draws: an upper bound of any
pose selector, optimistic by the winner's curse). Every report also gives ``all``: every pose."""

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, kw_only=True)
class SuiteRun:
    """What runs on a suite: designs, draws per pose, regimes, disturbances, pose policies."""

    designs: tuple[DesignGroup, ...]
    perturbations: int = 8
    """Perturbed rollouts per (object, pose, design)."""
    densities: tuple[str, ...] = ("light",)
    """Object densities: presets or kg/m³ (each is a regime of its own)."""
    impulses: tuple[float, ...] = (0.1,)
    """Disturbances in the paper's units [N s] (``paper_impulse`` maps them); the first is the table's."""
    pose_policies: tuple[str, ...] = ("fixed",)
    mass: str = "density"
    """``density``: each object at every density of ``densities``; ``real``: each object at its
    published mass instead (one regime, ``real``; objects without one are refused); ``auto``: as
    ``real``, objects without a published mass at the one density of ``densities``."""
    model: str = "chain"
    seed: int = 0
    """Seed of the perturbation draws."""
    scenario: GraspScenario = field(default_factory=GraspScenario)
    options: SimOptions | None = None
    """The finger model's numerical options (e.g. the tendon's ``routing``); None for the defaults."""

    def __post_init__(self) -> None:
        if not self.designs:
            raise DesignError("an evaluation needs at least one design")
        labels = [g.label for g in self.designs]
        if len(set(labels)) != len(labels):
            raise DesignError("a design is listed twice")
        if isinstance(self.perturbations, bool) or int(self.perturbations) < 1:
            raise DesignError(f"--perturbations must be >= 1, got {self.perturbations}")
        for d in self.densities:
            parse_density(d)
        if not self.impulses or not all(np.isfinite(i) and i >= 0 for i in self.impulses):
            raise DesignError(f"impulses must be finite values >= 0 (paper N s), got {self.impulses}")
        for p in self.pose_policies:
            if p not in POSE_POLICIES:
                raise DesignError(f"pose sampling {p!r}: choose from {', '.join(POSE_POLICIES)}")
        if self.mass not in MASS_MODES:
            raise DesignError(f"mass {self.mass!r}: choose from {', '.join(MASS_MODES)}")
        if self.mass != "density" and len(self.densities) != 1:
            raise DesignError(f"--mass {self.mass} is one regime: give at most one --density")
        if isinstance(self.seed, bool) or int(self.seed) < 0:
            raise DesignError(f"seed must be >= 0, got {self.seed}")
        FingerModel(self.model)

    @property
    def needs_surrogate(self) -> bool:
        """Whether a checkpoint is needed (``surrogate`` pose policy)."""
        return "surrogate" in self.pose_policies


def check_real_masses(sources) -> None:
    """Raise :class:`MeshError` (one line) when an object of ``sources`` has no published mass."""
    missing = []
    for src in sources:
        try:
            published_mass(str(src))
        except MeshError:
            missing.append(str(src))
    if missing:
        raise MeshError(
            f"--mass real: {len(missing)} object{'s' if len(missing) > 1 else ''} without a published mass "
            f"({', '.join(missing[:4])}{', …' if len(missing) > 4 else ''}): evaluate them at a --density, "
            "or leave them out"
        )


def _regimes(run: SuiteRun, so: SuiteObject, obj, densities: list) -> list[tuple[str, float]]:
    """(label, density [kg/m³]) of each regime of one object: ``run``'s densities, or its published mass.

    Under ``auto`` an object without a published mass is at the one density, still labelled ``real``
    (the regime's label, so that every object is in one table); its rows record the density used.
    """
    if run.mass == "density":
        return densities
    found = mass_by_rule(so.source, run.mass)
    if found is None:
        return [("real", densities[0][1])]
    return [("real", found.mass * obj.density / obj.mass)]  # mass / volume


def _draws(
    suite: Suite, run: SuiteRun, so: SuiteObject, base, k: int, scenes: SceneCache | None
) -> tuple[list[Perturbation | None], int]:
    """The ``run.perturbations`` draws of pose ``k`` (None where given up) and how many were redrawn.

    With ``scenes`` (``base``'s cache), each accepted draw's scene is kept there for its rollout.
    """
    keep = None
    if scenes is not None:
        keep = lambda p, scene: scenes.keep_perturbed(base, run.scenario, so.poses[k], p, scene)  # noqa: E731
    return draw_perturbations(
        suite.perturbation,
        suite.perturbation.stream(run.seed, so.name, k),
        run.perturbations,
        base,
        run.scenario,
        so.poses[k],
        max_penetration=MAX_PENETRATION,
        keep=keep,
    )


def _outcome_row(o: Outcome, scenario: GraspScenario) -> dict:
    f = np.asarray(o.body_force, dtype=float)
    return {
        "success": bool(o.success),
        "sample_error": any(x.is_sample_error for x in o.failures),
        "failures": [x.value for x in o.failures],
        "reason": o.reason,
        "hold_force_n": float(np.linalg.norm(f[3:])),
        "slip_m": float(np.linalg.norm(o.displacement)),
        "lift_margin_m": float(o.lift_height - scenario.lifted_fraction * scenario.lift),
        "lift_height_m": float(o.lift_height),
        "body_force": [float(x) for x in f],
        "displacement": [float(x) for x in o.displacement],
    }


def _surrogate_choice(surrogate, obj, so: SuiteObject, run: SuiteRun, rho: float, n_points: int) -> dict:
    """Per design label: the pose the surrogate scores best (suite pose index) and every pose's score.

    K-fold surrogates (:class:`~mjcodesign.surrogate.FoldSurrogates`) score the object with the fold
    that never trained on it; the choice records that fold and whether the object was in their data.
    """
    fold = {}
    if hasattr(surrogate, "for_object"):
        fold = {"fold": surrogate.fold_for(so.name), "held_out": surrogate.held_out_for(so.name)}
        surrogate = surrogate.for_object(so.name)
    cands = ObjectCandidates(
        obj,
        so.poses,
        np.stack([p.matrix() for p in so.poses]),
        so.pose_source,
        np.arange(len(so.poses)),
    ).with_clouds(n_points, run.seed)
    out = {}
    for g in run.designs:
        if g.for_object(so.name) is None:
            continue
        scores, _ = predict_candidates(surrogate, cands, g.for_object(so.name), rho)
        best = int(cands.source_index[int(np.argmax(scores))])
        out[g.label] = {
            "pose": best,
            "scores": {int(i): float(s) for i, s in zip(cands.source_index, scores, strict=True)},
            **fold,
        }
    return out


@dataclass
class PreparedObject:
    """One suite object made ready to roll out: loaded, its regimes, compiled scenes and draws."""

    obj: object
    """The :class:`~mjcodesign.objects.GraspObject` (loaded at ``light``; each job sets its density)."""
    regimes: list[tuple[str, float]]
    """(label, density [kg/m³]) of each regime (:func:`_regimes`)."""
    scenes: SceneCache
    draws: list[list[Perturbation | None]]
    """Per pose, the run's perturbation draws (None: given up, or the pose itself cannot be simulated)."""
    redrawn: int = 0
    given_up: int = 0


def prepare_object(
    suite: Suite,
    run: SuiteRun,
    so: SuiteObject,
    obj,
    densities: list[tuple[str, float]],
    *,
    keep_scenes: bool = True,
) -> PreparedObject:
    """Compile ``so``'s first scene and draw every pose's perturbations (common to all designs).

    ``obj``: ``so`` loaded (:func:`~mjcodesign.jobs.load_grasp_object` at ``light``, the suite's seed).
    With ``keep_scenes``, the scene each accepted draw's start check built is kept in ``scenes`` for its
    one rollout (a model copy each, ~1 MB), where a disturbance of ``run`` rolls out on that scene;
    a caller that prepares many objects before rolling any out passes False.
    """
    regimes = _regimes(run, so, obj, densities)
    scenes = SceneCache(size=len(regimes) * len(run.impulses) + 1)
    first = GraspJob(
        obj=obj,
        pose=so.poses[0],
        design=next(
            (g.for_object(so.name) for g in run.designs if g.for_object(so.name)),
            Stiffness.preset("soft"),
        ),
        finger_model=run.model,
        options=run.options,
        scenario=run.scenario,
        density=regimes[0][1],
    )
    base = scenes.scene(first)
    # The draws' scenes are rolled out only by jobs on this scene: those of a disturbance that leaves
    # run.scenario as it is (at_paper_disturbance), in the first regime.
    keep = keep_scenes and any(at_paper_disturbance(run.scenario, i) == run.scenario for i in run.impulses)
    prep = PreparedObject(obj=obj, regimes=regimes, scenes=scenes, draws=[])
    for k in range(len(so.poses)):
        try:
            scene_at_pose(base, so.poses[k])
        except PoseError:  # the frozen pose itself cannot be simulated: every draw of it is given up
            prep.draws.append([None] * run.perturbations)
            prep.given_up += run.perturbations
            continue
        d, r = _draws(suite, run, so, base, k, scenes if keep else None)
        prep.draws.append(d)
        prep.redrawn += r
        prep.given_up += sum(x is None for x in d)
    return prep


def object_jobs(
    prep: PreparedObject, so: SuiteObject, run: SuiteRun, designs: Sequence[DesignGroup]
) -> tuple[list[GraspJob], list[tuple]]:
    """Every rollout of one object for ``designs``: the jobs, and each job's (regime, draw) key.

    Order: regime, impulse, pose, draw, design; a design that does not grasp ``so`` is skipped.
    """
    jobs, meta = [], []
    for dens, rho in prep.regimes:
        for imp in run.impulses:
            scenario = at_paper_disturbance(run.scenario, imp)
            for k, pose in enumerate(so.poses):
                for j, p in enumerate(prep.draws[k]):
                    if p is None:
                        continue
                    for g in designs:
                        design = g.for_object(so.name)
                        if design is None:  # an individual design exists for its own objects only
                            continue
                        jobs.append(
                            GraspJob(
                                obj=prep.obj,
                                pose=pose,
                                design=design,
                                finger_model=run.model,
                                options=run.options,
                                scenario=scenario,
                                density=rho,
                                seed=run.seed,
                                perturbation=p,
                                label=f"{g.label}/{so.name}/{dens}/{imp}/{k}/{j}",
                            )
                        )
                        meta.append((dens, rho, imp, k, j, g, p, scenario))
    return jobs, meta


def outcome_rows(so: SuiteObject, meta: list[tuple], outs: Sequence[Outcome]) -> list[dict]:
    """The result rows of :func:`object_jobs`' jobs (``meta``) and their outcomes."""
    return [
        {
            "object": so.name,
            "domain": so.domain,
            "fold": so.fold,
            "density": dens,
            "density_kg_m3": rho,
            "impulse_paper_ns": float(imp),
            "pose": k,
            "draw": j,
            "design": g.label,
            "perturbation": p.as_dict(),
            **_outcome_row(o, scenario),
        }
        for (dens, rho, imp, k, j, g, p, scenario), o in zip(meta, outs, strict=True)
    ]


def run_suite(
    suite: Suite,
    run: SuiteRun,
    *,
    surrogate=None,
    n_points: int = 1024,
    cache_dir=None,
    progress: Progress | None = None,
    warn: Callable[[str], None] | None = None,
) -> dict:
    """Run every rollout; ``{"rows": [...], "objects": [...], "surrogate_choice": {...}, "wall_time_s"}``.

    ``surrogate``: a :class:`~mjcodesign.surrogate.Surrogate`, or K-fold surrogates (one per object).

    Rows are in a fixed order (object, density, impulse, pose, draw, design) and hold no wall time, so
    the same suite and seed give identical rows. An object that cannot be loaded is reported in
    ``objects`` with its error and left out (``warn`` receives one line).
    """
    if run.needs_surrogate and surrogate is None:
        raise DesignError("the surrogate pose policy needs a checkpoint (--ckpt)")
    if run.mass == "real":
        check_real_masses(o.source for o in suite.objects)
    backend = get_backend("mujoco")
    t0 = time.perf_counter()
    rows: list[dict] = []
    objects: list[dict] = []
    choice: dict[str, dict] = {}
    densities = [(str(d), parse_density(d)) for d in run.densities]

    def ready(so: SuiteObject):
        """``so`` loaded, its draws and its jobs; or the error that left it out."""
        try:
            obj = load_grasp_object(so.source, "light", seed=suite.seed, cache_dir=cache_dir)
        except MjcodesignError as exc:
            return exc
        prep = prepare_object(suite, run, so, obj, densities)
        return (prep, *object_jobs(prep, so, run, run.designs))

    # One object ahead: the next object is loaded and its draws checked on a thread of its own while
    # this one rolls out (MuJoCo releases the GIL); each object's rows do not depend on the others.
    pending = _Ahead(ready, suite.objects[0]) if suite.objects else None
    for n_done, so in enumerate(suite.objects):
        got = pending.result()
        if n_done + 1 < len(suite.objects):
            pending = _Ahead(ready, suite.objects[n_done + 1])
        if isinstance(got, MjcodesignError):
            objects.append({"name": so.name, "domain": so.domain, "error": f"{type(got).__name__}: {got}"})
            if warn:
                warn(f"{so.name}: left out ({type(got).__name__}: {got})")
            continue
        prep, jobs, meta = got
        if surrogate is not None:
            for dens, rho in prep.regimes:
                choice.setdefault(so.name, {})[dens] = _surrogate_choice(
                    surrogate, prep.obj, so, run, rho, n_points
                )
        outs = run_jobs(jobs, backend, scenes=prep.scenes)
        rows += outcome_rows(so, meta, outs)
        objects.append(
            {
                "name": so.name,
                "domain": so.domain,
                "fold": so.fold,
                "poses": len(so.poses),
                "redrawn": prep.redrawn,
                "draws_given_up": prep.given_up,
                "error": None,
            }
        )
        if progress:
            progress("objects", n_done + 1, len(suite.objects))
    return {
        "rows": rows,
        "objects": objects,
        "surrogate_choice": choice,
        "wall_time_s": time.perf_counter() - t0,
    }


class _Ahead:
    """``fn(arg)`` on a daemon thread.

    An interrupted evaluation does not wait for the object it was preparing (CoACD may take minutes on
    an uncached mesh), and the interpreter exits without it.
    """

    def __init__(self, fn, arg):
        self._value = self._error = None
        self._thread = threading.Thread(target=self._run, args=(fn, arg), daemon=True, name="suite-ahead")
        self._thread.start()

    def _run(self, fn, arg) -> None:
        try:
            self._value = fn(arg)
        except BaseException as exc:  # handed to the caller of result()
            self._error = exc

    def result(self):
        """The value, or the exception raised, once the thread has ended."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value


def record_suite_examples(
    suite: Suite, run: SuiteRun, rows: list[dict], observer, *, per_design: int = 2, cache_dir=None
) -> list[str]:
    """Re-run the best and worst rollouts of every design into ``observer``; their labels.

    Per design, among the first regime's rollouts the simulator could use: ``per_design`` held ones
    with the highest lift and ``per_design`` failed ones with the lowest, each with its own draw.
    """
    if not rows:
        return []
    first = (rows[0]["density"], rows[0]["impulse_paper_ns"])
    usable = [r for r in rows if (r["density"], r["impulse_paper_ns"]) == first and not r["sample_error"]]
    picked = []
    for g in run.designs:
        mine = [r for r in usable if r["design"] == g.label]
        best = sorted((r for r in mine if r["success"]), key=lambda r: -r["lift_height_m"])[:per_design]
        worst = sorted((r for r in mine if not r["success"]), key=lambda r: r["lift_height_m"])[:per_design]
        picked += [(g, r, "best") for r in best] + [(g, r, "worst") for r in worst]
    by_name = {o.name: o for o in suite.objects}
    loaded: dict[str, object] = {}
    jobs = []
    for g, r, tag in picked:
        so = by_name[r["object"]]
        if so.name not in loaded:
            loaded[so.name] = load_grasp_object(so.source, "light", seed=suite.seed, cache_dir=cache_dir)
        scenario = at_paper_disturbance(run.scenario, r["impulse_paper_ns"])
        jobs.append(
            GraspJob(
                obj=loaded[so.name],
                pose=so.poses[r["pose"]],
                design=g.for_object(so.name),
                finger_model=run.model,
                options=run.options,
                scenario=scenario,
                density=r["density_kg_m3"],
                perturbation=Perturbation(**r["perturbation"]),
                label=f"{g.label}/{tag}/{so.name}/pose{r['pose']}/draw{r['draw']}",
            )
        )
    if jobs:
        run_jobs(jobs, get_backend("mujoco"), observer)
    return [j.label for j in jobs]
