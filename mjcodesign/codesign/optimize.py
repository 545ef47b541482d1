"""Co-design of the 22 block stiffnesses and a grasp pose per object through the surrogate (Algorithm 1).

The design variable is z (22 values per design); the stiffness is ``ln E = 13.5 + 3.5 · sigmoid(z)``,
so every iterate is printable (:data:`~mjcodesign.design.stiffness.LOG_E_MIN` ..
:data:`~mjcodesign.design.stiffness.LOG_E_MAX`). Each iteration:

1. the surrogate predicts every candidate pose of every object at the current design(s), and L_opt is
   computed per pose (:class:`~mjcodesign.surrogate.DesignLoss`);
2. per object, :class:`~mjcodesign.codesign.selection.PoseSelection` says which poses count (the B
   lowest; after ``patience`` iterations with the same B, only the best of them);
3. the counted losses are summed over the objects that share a design, and AdamW takes a step on z.

It stops when every object has converged or after ``max_iterations``. ``joint`` mode optimises one
design for all objects; ``individual`` one design per object (its z stops moving once the object has
converged).

**L_opt in our frame.** The paper's loss is ``w1 Σ(‖f‖ + ‖Δq‖) + w2 Σ(|min(f_y, 0)| + |min(Δq_y, 0)| +
c_g)``. Its y is the *world's vertical*: the authors' scene is y-up and their outputs are in the world
frame, so a negative f_y is a finger force that does not hold the object up and a negative Δq_y an
object that slid down against the finger. Our outputs are in the gripper (palm) frame
(:class:`~mjcodesign.scenarios.outcome.Outcome`), whose y is the *closing* axis (finger A to finger B,
:func:`mjcodesign.poses.palm_frame`) and whose z is the palm normal, opposite to the approach. No
gripper axis is vertical for every grasp (poses approach from the top and the sides), so the paper's y
is the world vertical expressed in the gripper frame, ``up = R[2, :]`` (row 2 of the palm rotation;
``up = +z`` for a top-down grasp): ``f_y = up · f``, ``Δq_y = up · Δq``. The surrogate's
:class:`~mjcodesign.surrogate.DesignLoss` implements exactly that, with the authors' weights (w1 = 1e-3,
w2 = 1e3) and their norm: ``‖·‖`` is read as the authors' code computes it, the sum of absolute
components (6 wrench, 3 displacement); w1 only regularises, the w2 terms decide.

**The success objective** (:attr:`Objective.SUCCESS`). The per-pose loss is the predicted failure
probability ``1 − p`` of the surrogate's success head (:class:`~mjcodesign.surrogate.SuccessLoss`),
ranked and counted by the same pose selection: the B most likely poses of each object until the set is
fixed, then the best one. At the end the counted total is ``Σ_k (1 − p_k)`` over the objects' chosen
poses, so minimising it maximises the mean over objects of the predicted success probability at each
object's best pose. The surrogate gives no uncertainty (one deterministic network), so none is
penalised. A surrogate without a success head is refused.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from mjcodesign.codesign.problem import PoseSet, row_densities
from mjcodesign.codesign.selection import PoseSelection
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E
from mjcodesign.errors import DesignError

__all__ = [
    "Mode",
    "Objective",
    "OptimizeConfig",
    "OptimizeResult",
    "Step",
    "log_e_of",
    "optimize",
    "z_of",
]

_SPAN = LOG_E_MAX - LOG_E_MIN  # 3.5: ln E = LOG_E_MIN + _SPAN · sigmoid(z)
_INIT_FRACTION = 0.6  # the authors' z starts at 0.6 of the range (ln E 15.6); the paper does not say
_TORCH_WEIGHT_DECAY = 0.01  # torch's AdamW default, which the authors' optimize.py keeps


class Mode(enum.Enum):
    """One design for all objects, or one per object."""

    JOINT = "joint"
    INDIVIDUAL = "individual"


class Objective(enum.Enum):
    """What a pose's loss is: the paper's L_opt, or the predicted failure probability (module docstring)."""

    LOPT = "lopt"
    SUCCESS = "success"


def log_e_of(z) -> np.ndarray:
    """``ln E = 13.5 + 3.5 · sigmoid(z)`` [ln Pa], elementwise."""
    return LOG_E_MIN + _SPAN / (1.0 + np.exp(-np.asarray(z, dtype=float)))


def z_of(log_e) -> np.ndarray:
    """Inverse of :func:`log_e_of` for ln E strictly inside the printable range."""
    u = (np.asarray(log_e, dtype=float) - LOG_E_MIN) / _SPAN
    if np.any((u <= 0) | (u >= 1)):
        raise DesignError(f"ln E must lie strictly inside ({LOG_E_MIN}, {LOG_E_MAX}) to have a z")
    return np.log(u / (1.0 - u))


@dataclass(frozen=True, kw_only=True)
class OptimizeConfig:
    """Algorithm 1's settings; defaults are the paper's (B, T_p, AdamW lr) or the authors' where it is silent."""

    mode: Mode = Mode.JOINT
    objective: Objective = Objective.LOPT
    """``lopt``: the paper's Algorithm 1 on L_opt; ``success``: on the success head's 1 − p."""
    top_b: int = 5
    """B: poses that count per object before the set is fixed."""
    patience: int = 100
    """T_p: iterations of an unchanged top-B set before it is fixed; also the top-1 stall that ends an object."""
    max_iterations: int = 2000
    """N (the authors stop at 10k; at ~70 ms an iteration that is 12 min, past the 5-min target)."""
    lr: float = 0.1
    weight_decay: float = _TORCH_WEIGHT_DECAY
    """AdamW's decoupled weight decay on z (pulls ln E towards the middle of the range, 15.25)."""
    init_log_e: float = LOG_E_MIN + _INIT_FRACTION * _SPAN
    """Starting ln E of every block."""
    tol: float = 1e-3
    """Relative band around an object's top-1 reference loss: an object converges when its loss stayed
    within 0.1 % of the reference for T_p iterations (:mod:`~mjcodesign.codesign.selection`). (The authors stop when the total
    changes by < 1e-6 per iteration for 1000 iterations, which on our smooth surrogate never happens
    before their 10k cap.)"""
    mc_samples: int = 0
    """Success objective: Monte Carlo dropout draws of the head per evaluation (0: one deterministic
    pass; :class:`~mjcodesign.surrogate.SuccessLoss`)."""
    uncertainty: float = 0.0
    """Success objective: weight of the draws' spread in each row's loss (needs ``mc_samples`` >= 2)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", Mode(self.mode))
        try:
            object.__setattr__(self, "objective", Objective(self.objective))
        except ValueError:
            names = ", ".join(o.value for o in Objective)
            raise DesignError(f"unknown objective {self.objective!r}: choose from {names}") from None
        ints = (self.top_b, self.patience, self.max_iterations)
        if any(isinstance(v, bool) or not isinstance(v, int) or v < 1 for v in ints):
            raise DesignError(f"top_b, patience and max_iterations must be integers >= 1, got {ints}")
        if not (math.isfinite(self.lr) and self.lr > 0 and self.weight_decay >= 0 and self.tol >= 0):
            raise DesignError("lr > 0, weight_decay >= 0 and tol >= 0 required")
        if (self.mc_samples or self.uncertainty) and self.objective is not Objective.SUCCESS:
            raise DesignError("Monte Carlo dropout and its uncertainty penalty are for --objective success")
        if self.objective is Objective.SUCCESS:
            self.success_loss()  # refuses a bad sample count or weight now, not at the first iteration
        if not LOG_E_MIN < self.init_log_e < LOG_E_MAX:
            raise DesignError(f"init_log_e must be inside ({LOG_E_MIN}, {LOG_E_MAX}), got {self.init_log_e}")

    def success_loss(self):
        """The :class:`~mjcodesign.surrogate.SuccessLoss` of the success objective under these settings."""
        from mjcodesign.surrogate import SuccessLoss

        return SuccessLoss(samples=self.mc_samples, uncertainty=self.uncertainty)

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return {
            "mode": self.mode.value,
            "objective": self.objective.value,
            "top_b": self.top_b,
            "patience": self.patience,
            "max_iterations": self.max_iterations,
            "lr": self.lr,
            "weight_decay": self.weight_decay,
            "init_log_e": self.init_log_e,
            "tol": self.tol,
            "mc_samples": self.mc_samples,
            "uncertainty": self.uncertainty,
        }


@dataclass(frozen=True)
class Step:
    """One iteration, handed to ``on_step``."""

    iteration: int
    total: float
    """Sum of the counted losses over the objects."""
    converged: int
    """Objects converged so far."""


@dataclass
class OptimizeResult:
    """The optimised design(s), each object's chosen pose, and the loss curves."""

    objects: tuple[str, ...]
    mode: Mode
    designs: np.ndarray
    """ln E [ln Pa], shape (G, 22): G = 1 (joint) or K (individual, one per object)."""
    chosen: np.ndarray
    """Chosen pose row of each object in the :class:`PoseSet`, shape (K,)."""
    top_b: list[list[int]]
    """Each object's last top-B set, pose rows of the :class:`PoseSet`."""
    phases: list[str]
    curves: np.ndarray
    """Counted loss per iteration and object, shape (iterations, K)."""
    grad_norms: np.ndarray
    """‖d counted loss / d ln E‖ per iteration and design, shape (iterations, G)."""
    iterations: int = 0
    stopped: str = ""
    """``converged`` or ``max_iterations``."""
    wall_s: float = 0.0
    config: dict = field(default_factory=dict)

    @property
    def total_curve(self) -> np.ndarray:
        """Sum of the counted losses per iteration, shape (iterations,)."""
        return self.curves.sum(axis=1)

    def design_of(self, k: int) -> np.ndarray:
        """The design (22 ln E) object ``k`` is grasped with."""
        return self.designs[0 if self.mode is Mode.JOINT else k]

    def summary(self) -> dict:
        """JSON-ready: designs, chosen poses, phases, the curves' ends."""
        return {
            "mode": self.mode.value,
            "objects": list(self.objects),
            "designs": self.designs.tolist(),
            "chosen_pose_row": self.chosen.tolist(),
            "top_b_rows": self.top_b,
            "phases": self.phases,
            "iterations": self.iterations,
            "stopped": self.stopped,
            "wall_s": self.wall_s,
            "loss_start": self.total_curve[0].item() if self.iterations else None,
            "loss_end": self.total_curve[-1].item() if self.iterations else None,
            "grad_norm_start": self.grad_norms[0].tolist() if self.iterations else None,
            "config": self.config,
        }


@functools.lru_cache(maxsize=4)
def _counted_type(base_type: type) -> type:
    """A subclass of the loss type ``base_type`` whose gradient comes only from the rows ``choose`` picks.

    ``choose`` gets every row's loss (numpy) and returns a boolean mask; the rows it leaves out are
    detached, so one forward and backward pass both ranks the poses and gives the counted gradient.
    """
    import torch

    @dataclasses.dataclass(frozen=True, kw_only=True)
    class CountedLoss(base_type):
        choose: Callable[[np.ndarray], np.ndarray]

        def rows(self, *outputs):
            return self.counted(super().rows(*outputs))

        if hasattr(base_type, "draw_rows"):  # the success loss on Monte Carlo dropout draws

            def draw_rows(self, draws):
                return self.counted(super().draw_rows(draws))

        def counted(self, r):
            """The per-row losses ``r`` with the rows ``choose`` leaves out detached."""
            mask = torch.from_numpy(np.asarray(self.choose(r.detach().double().numpy()), dtype=bool))
            return torch.where(mask, r, r.detach())

        def uncounted(self):
            """The loss this one counts rows of (every row's gradient kept)."""
            return base_type(**{f.name: getattr(self, f.name) for f in dataclasses.fields(base_type)})

    return CountedLoss


def _counted_loss(base, choose):
    fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
    return _counted_type(type(base))(**fields, choose=choose)


def optimize(
    surrogate,
    poses: PoseSet,
    density: float | dict[str, float],
    config: OptimizeConfig | None = None,
    *,
    loss=None,
    on_step: Callable[[Step], None] | None = None,
) -> OptimizeResult:
    """Algorithm 1 over the candidate ``poses`` of their objects at ``density`` [kg/m³].

    ``density``: one for all objects, or one per object name
    (:func:`~mjcodesign.codesign.problem.row_densities`).

    ``surrogate``: a :class:`~mjcodesign.surrogate.Surrogate` (or anything with its ``prepare`` and
    ``loss_and_grad``); ``loss``: a :class:`~mjcodesign.surrogate.DesignLoss` (default: the paper's), or
    with the success objective a :class:`~mjcodesign.surrogate.SuccessLoss` (its default). Raises
    :class:`DesignError` for the success objective on a surrogate without a success head.
    Deterministic: same inputs, same result, bit for bit.
    """
    import torch

    from mjcodesign.surrogate import DesignLoss, GraspBatch, Poses

    cfg = config or OptimizeConfig()
    success = cfg.objective is Objective.SUCCESS
    if success and not getattr(surrogate, "has_success_head", False):
        raise DesignError(
            "--objective success needs a surrogate with a success head (train one with --success-weight > 0); "
            "this checkpoint predicts the paper's 10 outputs only"
        )
    rho = row_densities(poses, density)
    k_objects = len(poses.objects)
    rows_of = [poses.rows(k) for k in range(k_objects)]
    if k_objects == 0 or any(len(r) == 0 for r in rows_of):
        empty = [poses.objects[k] for k, r in enumerate(rows_of) if len(r) == 0]
        raise DesignError(f"every object needs a candidate pose; none for {empty or 'any object'}")
    base = loss or (cfg.success_loss() if success else DesignLoss())
    sur_poses = Poses.of(poses)
    joint = cfg.mode is Mode.JOINT
    groups = [np.arange(k_objects)] if joint else [np.array([k]) for k in range(k_objects)]
    batches = []
    for g in groups:
        rows = np.concatenate([rows_of[k] for k in g])
        batches.append(surrogate.prepare(GraspBatch(sur_poses, rows, rho[rows])))
    sel = [PoseSelection(len(r), cfg.top_b, cfg.patience, cfg.tol) for r in rows_of]
    z0 = z_of(np.full((len(groups), N_LOG_E), cfg.init_log_e))
    t0 = time.perf_counter()
    curves: list[np.ndarray] = []
    norms: list[np.ndarray] = []
    last = [np.zeros(len(r)) for r in rows_of]
    with torch.random.fork_rng(devices=[]):
        z = torch.tensor(z0, dtype=torch.float64, requires_grad=True)
        opt = torch.optim.AdamW([z], lr=cfg.lr, weight_decay=cfg.weight_decay)
        stopped = "max_iterations"
        it = 0
        for it in range(1, cfg.max_iterations + 1):
            counted = np.zeros(k_objects)
            grad = np.zeros((len(groups), N_LOG_E))
            ln_e_grad = np.zeros((len(groups), N_LOG_E))
            active = np.array([not all(sel[k].converged for k in g) for g in groups])
            zs = z.detach().numpy().copy()
            for gi, g in enumerate(groups):
                if not active[gi]:
                    counted[g] = [float(last[k][sel[k].chosen(last[k])]) for k in g]
                    continue
                choose = _chooser(g, rows_of, sel, counted, last)
                res = surrogate.loss_and_grad(log_e_of(zs[gi]), batches[gi], loss=_counted_loss(base, choose))
                s = 1.0 / (1.0 + np.exp(-zs[gi]))
                ln_e_grad[gi] = res.grad
                grad[gi] = ln_e_grad[gi] * _SPAN * s * (1.0 - s)  # chain rule: d ln E / d z
            curves.append(counted)
            norms.append(np.linalg.norm(ln_e_grad, axis=1))
            opt.zero_grad(set_to_none=True)
            z.grad = torch.from_numpy(grad)
            frozen = z.detach().clone()
            opt.step()
            with torch.no_grad():
                z[~torch.from_numpy(active)] = frozen[~torch.from_numpy(active)]
            n_conv = sum(s.converged for s in sel)
            if on_step is not None:
                on_step(Step(it, float(counted.sum()), n_conv))
            if n_conv == k_objects:
                stopped = "converged"
                break
    designs = log_e_of(zs)  # the designs the last losses and rankings were computed at
    chosen = np.array([rows_of[k][sel[k].chosen(last[k])] for k in range(k_objects)])
    return OptimizeResult(
        objects=poses.objects,
        mode=cfg.mode,
        designs=designs,
        chosen=chosen,
        top_b=[rows_of[k][list(sel[k].current)].tolist() for k in range(k_objects)],
        phases=[s.phase.value for s in sel],
        curves=np.array(curves).reshape(-1, k_objects),
        grad_norms=np.array(norms).reshape(-1, len(groups)),
        iterations=it,
        stopped=stopped,
        wall_s=time.perf_counter() - t0,
        config=cfg.as_dict(),
    )


def _chooser(group, rows_of, sel, counted, last):
    """The ``choose`` of one design group: each object's :meth:`PoseSelection.select` on its rows' losses."""
    sizes = [len(rows_of[k]) for k in group]
    starts = np.concatenate([[0], np.cumsum(sizes)])

    def choose(values: np.ndarray) -> np.ndarray:
        mask = np.zeros(len(values), dtype=bool)
        for j, k in enumerate(group):
            v = values[starts[j] : starts[j + 1]]
            last[k] = v
            keep = sel[k].select(v)
            mask[starts[j] + keep] = True
            counted[k] = float(v[keep].sum())
        return mask

    return choose
