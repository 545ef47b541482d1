"""The trained surrogate as a library: batched predictions and the co-design loss with its gradient.

A :class:`GraspBatch` is B rows over P poses: each row names its pose, the object's density and
(for ``Surrogate.predict``) a design. :meth:`Surrogate.prepare` computes each pose's PointNet
feature once; a prepared batch then costs one MLP pass per call, which is what a co-design step
repeats (``Surrogate.loss_and_grad``).

**Success from the outputs.** The simulator's rule (``mjcodesign.scenarios.outcome``) is: lifted
(the COM rose at least ``lifted_fraction · lift``), no ground contact at the end, a finger touching
the object, and a non-zero finger force during the hold. From the predicted outputs:

* lifted: the displacement is relative to the palm from the start of the lift to the end, so the
  object's rise over the lift is ``lift + up · Δq``: lifted when ``up · Δq ≥ −(1 − lifted_fraction)
  · lift``;
* no ground contact: its predicted probability is below 0.5;
* finger force: a held object's hold force equals its weight (CV 0.005–0.11 in the authors' data), and a
  regression never predicts an exact zero, so the force must reach half the weight.

:func:`success_score` is the smallest of the three margins, each scaled to O(1): success is a score
above 0. The same rule on the simulator's own outputs shows how far it agrees with the simulator's
flag (the train report gives that ceiling).

**Success from the head.** A network with a success head
(:attr:`~mjcodesign.surrogate.model.ModelConfig.success_head`) predicts the success probability
directly (``Prediction.success_p``), trained on the perturbed rollouts' share of successes; co-design
can maximise it (:class:`SuccessLoss`).
"""

from __future__ import annotations

import contextlib
import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from mjcodesign.data import PoseRows
from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E
from mjcodesign.errors import DesignError, StiffnessError
from mjcodesign.surrogate.data import (
    N_OUTPUTS,
    N_REGRESSION,
    Normalizer,
    frame_inputs,
    normalize_clouds,
)
from mjcodesign.surrogate.model import Dropout, GraspNet

__all__ = [
    "DesignLoss",
    "SuccessLoss",
    "DesignGradient",
    "design_vector",
    "dropout_draws",
    "GraspBatch",
    "InputRange",
    "Poses",
    "Prediction",
    "Surrogate",
    "success_score",
]

G = 9.81  # [m/s²]
_CONTACT_THRESHOLD = 0.5  # predicted ground-contact probability above which the grasp fails
_FORCE_FRACTION = 0.5  # of the weight: a held object's hold force equals its weight (NOTES)
_RANGE_TOL = 1e-9
"""Each side of a training range is widened by this fraction of its width plus this much: round-off
of the recorded ends, never extrapolation."""
_ENCODE_CHUNK = 256  # poses per PointNet call when preparing (memory: ~1.3 MB of activations per pose)


def success_score(
    body_force, displacement, p_contact, up, mass, lift: float, lifted_fraction: float
) -> np.ndarray:
    """The smallest margin of the success rule (module docstring); success where it is > 0.

    ``body_force`` (B, 6) [N m, N], ``displacement`` (B, 3) [m], ``p_contact`` (B,) in [0, 1], ``up``
    (B, 3) the world vertical in the gripper frame, ``mass`` (B,) [kg], ``lift`` [m].
    """
    rise = np.einsum("bk,bk->b", np.asarray(displacement, dtype=float), np.asarray(up, dtype=float))
    lifted = (rise + (1.0 - lifted_fraction) * lift) / lift
    free = (_CONTACT_THRESHOLD - np.asarray(p_contact, dtype=float)) / _CONTACT_THRESHOLD
    weight = np.asarray(mass, dtype=float) * G
    force = (
        np.linalg.norm(np.asarray(body_force, dtype=float)[:, 3:], axis=1) / weight - _FORCE_FRACTION
    ) / _FORCE_FRACTION
    return np.minimum(np.minimum(lifted, free), force)


@dataclass(frozen=True, eq=False)
class InputRange:
    """The range of each input the surrogate was trained on: ln E per block and the object density.

    Outside it the network extrapolates (a checkpoint trained at one density put a 2.2 MN force on a
    denser object), so ``Surrogate.predict`` and ``Surrogate.loss_and_grad`` refuse such
    inputs (``check``), and every command built on them (``predict``, ``optimize``, ``evaluate``,
    ``hw grasp``) with them.
    """

    log_e_low: np.ndarray
    """ln(E / Pa) [-], shape (22,)."""
    log_e_high: np.ndarray
    density_low: float
    """[kg/m³]."""
    density_high: float

    def __post_init__(self) -> None:
        for name in ("log_e_low", "log_e_high"):
            v = np.asarray(getattr(self, name), dtype=float).ravel()
            if v.shape != (N_LOG_E,) or not np.all(np.isfinite(v)):
                raise DesignError(f"input range {name} must be {N_LOG_E} finite values, got shape {v.shape}")
            object.__setattr__(self, name, v)
        for name in ("density_low", "density_high"):
            object.__setattr__(self, name, float(getattr(self, name)))
        if not (np.isfinite(self.density_low) and np.isfinite(self.density_high)):
            raise DesignError("input range of the density must be finite")
        if np.any(self.log_e_low > self.log_e_high) or self.density_low > self.density_high:
            raise DesignError("input range: a low end above its high end")

    @classmethod
    def of_samples(cls, log_e: np.ndarray, density: np.ndarray) -> InputRange:
        """The smallest and largest value of each input over training rows ``log_e`` (S, 22), ``density`` (S,)."""
        log_e, density = np.asarray(log_e, dtype=float), np.asarray(density, dtype=float)
        return cls(log_e.min(axis=0), log_e.max(axis=0), float(density.min()), float(density.max()))

    @classmethod
    def recorded(cls, meta: dict) -> InputRange | None:
        """The range of a checkpoint that measured none, from its record ``meta``; None without one.

        A checkpoint of a datagen dataset (``meta["dataset"]``): ln E over the printable range (datagen
        draws every block uniformly over it) and the density over the dataset's configured range (the
        low and high of ``--density``; one value when it was trained at one density).
        """
        density = (meta.get("dataset") or {}).get("density")
        if not isinstance(density, dict) or "low_kg_m3" not in density:
            return None
        low, high = float(density["low_kg_m3"]), float(density["high_kg_m3"])
        return cls(np.full(N_LOG_E, LOG_E_MIN), np.full(N_LOG_E, LOG_E_MAX), low, high)

    @classmethod
    def of_dataset(cls, density: np.ndarray, configured: tuple[float, float]) -> InputRange:
        """A datagen dataset's range: ln E printable, the density its configuration and rows span [kg/m³].

        ln E spans the printable range (datagen draws every block over it). The density spans the
        configured ``--density`` range ``configured`` (low, high: what the rows were drawn over) and the
        rows' ``density`` (one value per row): a dataset at published masses (mass rule ``real`` or
        ``auto``) holds each object at its own density, whatever the configured one.
        """
        density = np.asarray(density, dtype=float)
        low, high = min(float(density.min()), configured[0]), max(float(density.max()), configured[1])
        return cls(np.full(N_LOG_E, LOG_E_MIN), np.full(N_LOG_E, LOG_E_MAX), low, high)

    def as_dict(self) -> dict:
        """JSON-ready."""
        return {
            "log_e_low": self.log_e_low.tolist(),
            "log_e_high": self.log_e_high.tolist(),
            "density_low_kg_m3": self.density_low,
            "density_high_kg_m3": self.density_high,
        }

    @classmethod
    def from_dict(cls, d: dict) -> InputRange:
        """Inverse of :meth:`as_dict`."""
        return cls(d["log_e_low"], d["log_e_high"], d["density_low_kg_m3"], d["density_high_kg_m3"])

    def check(self, log_e: np.ndarray | None, density: np.ndarray) -> None:
        """Raise :class:`~mjcodesign.errors.DesignError` naming the first input outside its range (widened by ``_RANGE_TOL``).

        ``log_e`` (B, 22) or None (not checked), ``density`` (B,) [kg/m³].
        """
        density = np.asarray(density, dtype=float).ravel()
        lo, hi = _widened(self.density_low, self.density_high)
        bad = ~((density >= lo) & (density <= hi))
        if np.any(bad):
            raise DesignError(
                f"density {density[bad][0]:g} kg/m³ is outside the surrogate's training range "
                f"[{self.density_low:g}, {self.density_high:g}] kg/m³"
            )
        if log_e is None:
            return
        log_e = np.asarray(log_e, dtype=float).reshape(-1, N_LOG_E)
        lo, hi = _widened(self.log_e_low, self.log_e_high)
        bad = ~((log_e >= lo) & (log_e <= hi))
        if np.any(bad):
            row, block = np.argwhere(bad)[0]
            raise DesignError(
                f"ln E[{block}] = {log_e[row, block]:g} is outside the surrogate's training range "
                f"[{self.log_e_low[block]:.4g}, {self.log_e_high[block]:.4g}]"
            )


def _widened(low, high):
    slack = _RANGE_TOL * (1.0 + np.abs(np.asarray(high)) + np.abs(np.asarray(low)))
    return low - slack, high + slack


@dataclass(frozen=True, eq=False)
class Poses:
    """P grasp poses as the surrogate sees them, in the gripper frame."""

    clouds: np.ndarray
    """Partial point clouds [m], shape (P, N, 3) (:func:`mjcodesign.data.partial_cloud`)."""
    com: np.ndarray
    """Object COM [m], shape (P, 3)."""
    up: np.ndarray
    """World vertical (unit), shape (P, 3): row 2 of the palm's rotation."""
    volume: np.ndarray
    """Object volume [m³], shape (P,) (mass = density · volume)."""

    def __post_init__(self) -> None:
        c = np.asarray(self.clouds)
        p = len(c)
        if c.ndim != 3 or c.shape[2] != 3 or any(np.shape(a) != (p, 3) for a in (self.com, self.up)):
            raise DesignError("poses need clouds (P, N, 3), com (P, 3) and up (P, 3)")
        if np.shape(self.volume) != (p,):
            raise DesignError("poses need a volume per pose, shape (P,)")

    @classmethod
    def of(cls, poses: PoseRows, rows: np.ndarray | None = None) -> Poses:
        """Rows ``rows`` (all when None) of :class:`~mjcodesign.data.PoseRows`.

        A dataset's (``GraspData.poses``) or a co-design's candidates (:class:`~mjcodesign.codesign.PoseSet`).
        """
        r = np.arange(len(poses)) if rows is None else np.asarray(rows)
        return cls(poses.clouds[r], poses.com[r], poses.up[r], poses.volume[r])

    def __len__(self) -> int:
        return len(self.clouds)


@dataclass(frozen=True, eq=False)
class PoseFeatures:
    """What the network needs per pose, computed once: the cloud feature and the moved COM."""

    features: torch.Tensor
    """(P, F)."""
    com: torch.Tensor
    """COM after the cloud's centring and scaling, (P, 3)."""
    up: torch.Tensor
    """(P, 3)."""
    frame: torch.Tensor
    """:func:`~mjcodesign.surrogate.data.frame_inputs`, z-scored, (P, 7)."""


@dataclass(frozen=True, eq=False)
class GraspBatch:
    """B rows over :attr:`poses`: each a pose, a density and (for predictions) a design."""

    poses: Poses
    pose: np.ndarray
    """Pose of each row, shape (B,), int."""
    density: np.ndarray
    """Object density [kg/m³], shape (B,)."""
    log_e: np.ndarray | None = None
    """ln(E / Pa) of each row, shape (B, 22); None for ``Surrogate.loss_and_grad`` (one design)."""
    features: PoseFeatures | None = None
    """Set by :meth:`Surrogate.prepare`."""

    def __post_init__(self) -> None:
        pose = np.asarray(self.pose, dtype=np.int64).ravel()
        object.__setattr__(self, "pose", pose)
        object.__setattr__(self, "density", np.asarray(self.density, dtype=float).ravel())
        if len(self.density) != len(pose):
            raise DesignError(f"{len(pose)} rows but {len(self.density)} densities")
        if len(pose) and (pose.min() < 0 or pose.max() >= len(self.poses)):
            raise DesignError(f"a row's pose is outside 0..{len(self.poses) - 1}")
        if self.log_e is not None:
            log_e = np.asarray(self.log_e, dtype=float)
            if log_e.shape != (len(pose), N_LOG_E):
                raise StiffnessError(f"log_e must have shape ({len(pose)}, {N_LOG_E}), got {log_e.shape}")
            object.__setattr__(self, "log_e", log_e)

    @property
    def mass(self) -> np.ndarray:
        """Object mass of each row [kg]."""
        return self.density * self.poses.volume[self.pose]

    def __len__(self) -> int:
        return len(self.pose)


@dataclass(frozen=True)
class Prediction:
    """The surrogate's outputs for B rows, physical units, gripper frame."""

    body_force: np.ndarray
    """Torque about the COM [N m] (3), force [N] (3), shape (B, 6)."""
    displacement: np.ndarray
    """Object displacement relative to the palm [m], shape (B, 3)."""
    ground_contact: np.ndarray
    """Probability of ground contact at the end, shape (B,)."""
    success_score: np.ndarray
    """:func:`success_score`, shape (B,)."""
    success_p: np.ndarray | None = None
    """The success head's probability, shape (B,); None for a network without a head."""

    @property
    def success(self) -> np.ndarray:
        """The success the outputs imply (score > 0), shape (B,)."""
        return self.success_score > 0


@dataclass(frozen=True, kw_only=True)
class DesignLoss:
    """The paper's L_opt: ``base · Σ|y|`` over the 9 outputs, plus ``penalty`` times each failure sign.

    The authors (``optimize.py``) weight every output's magnitude by 1e-3 and by 1e3 a negative
    vertical force, a negative vertical displacement and a positive contact. Our outputs are in the
    gripper frame, so "vertical" is along ``up``: per row, ``base · Σ_i |y_i| + penalty · (relu(−up·F)
    [N] + relu(−up·Δq) [m] + p_contact)``; the loss is the sum over rows.
    """

    base_weight: float = 1e-3
    penalty_weight: float = 1e3

    def rows(
        self, body_force: torch.Tensor, displacement: torch.Tensor, p_contact: torch.Tensor, up: torch.Tensor
    ):
        """Per-row loss (B,) from physical outputs (torch, differentiable)."""
        base = body_force.abs().sum(dim=1) + displacement.abs().sum(dim=1)
        f_up = (body_force[:, 3:] * up).sum(dim=1)
        d_up = (displacement * up).sum(dim=1)
        bad = torch.relu(-f_up) + torch.relu(-d_up) + p_contact
        return self.base_weight * base + self.penalty_weight * bad


@dataclass(frozen=True, kw_only=True)
class SuccessLoss:
    """The predicted failure probability ``1 − p_success`` of each row, from the success head.

    Summed over the rows it is the expected number of failed grasps; minimising it maximises the
    mean predicted success probability. A network without a head has no ``p_success`` and is refused
    (:meth:`Surrogate.loss_and_grad`).

    With ``samples`` = K ≥ 2 the head is read K times with the network's dropout on (Monte Carlo
    dropout; BatchNorm stays in its inference mode) and a row's loss is ``1 − mean_k p_k + uncertainty
    · std_k p_k``: the mean is the prediction, the spread over the draws its uncertainty, which
    ``uncertainty`` > 0 penalises (a design the network is unsure of costs more). The K dropout masks
    come from ``seed`` and are the same at every call, so the loss is a deterministic, differentiable
    function of the design (common random numbers for the optimiser).
    """

    needs_success_head = True
    samples: int = 0
    """Monte Carlo dropout draws (0: one deterministic pass, the default)."""
    uncertainty: float = 0.0
    """Weight of the draws' standard deviation in a row's loss (needs ``samples`` >= 2)."""
    seed: int = 0
    """Seed of the dropout masks."""

    def __post_init__(self) -> None:
        k, lam = self.samples, self.uncertainty
        if isinstance(k, bool) or not isinstance(k, int) or k < 0 or k == 1:
            raise DesignError(f"Monte Carlo dropout needs 0 (off) or >= 2 samples, got {k!r}")
        if isinstance(lam, bool) or not (isinstance(lam, int | float) and 0 <= lam < float("inf")):
            raise DesignError(f"the uncertainty weight must be a finite number >= 0, got {lam!r}")
        if lam > 0 and k == 0:
            raise DesignError("an uncertainty penalty needs Monte Carlo dropout samples (>= 2)")

    def rows(self, body_force, displacement, p_contact, up, p_success: torch.Tensor) -> torch.Tensor:
        """Per-row loss (B,): ``1 − p_success`` (torch, differentiable)."""
        return 1.0 - p_success

    def draw_rows(self, p_draws: torch.Tensor) -> torch.Tensor:
        """Per-row loss (B,) from K dropout draws of the head, shape (K, B) (class docstring)."""
        out = 1.0 - p_draws.mean(dim=0)
        if self.uncertainty > 0:
            out = out + self.uncertainty * p_draws.std(dim=0, correction=0)
        return out


@contextlib.contextmanager
def dropout_draws(model: torch.nn.Module, seed: int):
    """Within the block, ``model``'s dropout layers are on (all else in inference mode) under ``seed``.

    The global torch generator is forked, so the caller's random state is left as it was.
    """
    layers = [m for m in model.modules() if isinstance(m, Dropout | torch.nn.Dropout)]
    was = [m.training for m in layers]
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        try:
            for m in layers:
                m.train()
            yield
        finally:
            for m, t in zip(layers, was, strict=True):
                m.train(t)


def design_vector(design) -> np.ndarray:
    """``design`` as 22 finite ln E [ln Pa], shape (22,); :class:`StiffnessError` otherwise."""
    d = np.asarray(design, dtype=float).ravel()
    if d.shape != (N_LOG_E,) or not np.all(np.isfinite(d)):
        raise StiffnessError(f"a design is {N_LOG_E} finite values of ln E, got shape {d.shape}")
    return d


@dataclass(frozen=True)
class DesignGradient:
    """L_opt of one design over a batch, and its gradient."""

    loss: float
    grad: np.ndarray
    """d loss / d ln E, shape (22,)."""
    rows: np.ndarray
    """Per-row loss, shape (B,)."""


class Surrogate:
    """A trained :class:`GraspNet` with its normalisation and the scenario's success constants."""

    def __init__(
        self,
        model: GraspNet,
        normalizer: Normalizer,
        *,
        lift: float,
        lifted_fraction: float,
        meta: dict | None = None,
        input_range: InputRange | None = None,
    ):
        self.model = model.eval()
        self.normalizer = normalizer
        self.trained_range = input_range
        """The inputs' range measured on the training split (``InputRange.of_samples``), or None."""
        self.lift = float(lift)
        self.lifted_fraction = float(lifted_fraction)
        self.meta = dict(meta or {})
        """The checkpoint's record: dataset hash, split, training settings, metrics."""
        self._stats: tuple = ()
        self._stats_dtype = None

    @property
    def input_range(self) -> InputRange | None:
        """The inputs' training range, or None (nothing checked).

        ``trained_range``, else ``InputRange.recorded`` of the record; None for a surrogate
        with neither (one still being trained).
        """
        return self.trained_range or InputRange.recorded(self.meta)

    def check_inputs(self, log_e: np.ndarray | None, density: np.ndarray) -> None:
        """Raise :class:`~mjcodesign.errors.DesignError` for an input outside ``input_range`` (``InputRange.check``)."""
        if (r := self.input_range) is not None:
            r.check(log_e, density)

    @property
    def dtype(self) -> torch.dtype:
        """The network's float type (float32 unless the model was converted, e.g. ``model.double()``)."""
        return self.model.pc_scale.dtype

    def _normalisation(self) -> tuple:
        """(ln E mean, std, output mean, std) as tensors of :attr:`dtype`, made once per dtype."""
        if self._stats_dtype != self.dtype:
            n = self.normalizer
            with torch.inference_mode(False):  # usable by autograd whichever call makes them first
                self._stats = tuple(
                    torch.tensor(v, dtype=self.dtype)
                    for v in (n.log_e_mean, n.log_e_std, n.out_mean, n.out_std)
                )
            self._stats_dtype = self.dtype
        return self._stats

    @property
    def config(self):
        """The network's :class:`~mjcodesign.surrogate.model.ModelConfig`."""
        return self.model.config

    @torch.no_grad()
    def features(self, poses: Poses) -> PoseFeatures:
        """Each pose's cloud feature and moved COM (the PointNet runs once per pose)."""
        clouds, com = normalize_clouds(poses.clouds, poses.com)
        n = self.normalizer
        frame = (frame_inputs(poses.clouds, poses.up) - n.frame_mean) / n.frame_std
        t = torch.from_numpy(np.ascontiguousarray(clouds.transpose(0, 2, 1))).to(self.dtype)
        feats = [self.model.encode(t[i : i + _ENCODE_CHUNK]) for i in range(0, len(t), _ENCODE_CHUNK)]
        return PoseFeatures(
            torch.cat(feats) if feats else torch.zeros(0, self.config.feature_size, dtype=self.dtype),
            torch.from_numpy(com).to(self.dtype),
            torch.as_tensor(np.asarray(poses.up), dtype=self.dtype),
            torch.as_tensor(frame, dtype=self.dtype),
        )

    def prepare(self, batch: GraspBatch) -> GraspBatch:
        """``batch`` with its poses' features computed (a no-op when they are)."""
        if batch.features is not None:
            return batch
        return dataclasses.replace(batch, features=self.features(batch.poses))

    @property
    def has_success_head(self) -> bool:
        """Whether the network predicts the success probability (``Prediction.success_p``)."""
        return bool(getattr(self.config, "success_head", False))

    def _outputs(self, batch: GraspBatch, log_e: torch.Tensor):
        """Physical outputs (body force, displacement, p_contact), ``up`` and the head's p (or None) per row."""
        f = batch.features
        mean_e, std_e, mean_y, std_y = self._normalisation()
        pose = torch.from_numpy(batch.pose)
        dens = torch.from_numpy((batch.density - self.normalizer.density_mean) / self.normalizer.density_std)
        cols = [(log_e - mean_e) / std_e, f.com[pose], dens.to(self.dtype)[:, None]]
        up = f.up[pose]
        if self.config.frame_inputs:
            cols.append(f.frame[pose])
        raw = self.model.head(f.features[pose], torch.cat(cols, dim=1))
        y = raw[:, :N_REGRESSION] * std_y + mean_y
        p_success = torch.sigmoid(raw[:, N_OUTPUTS]) if self.has_success_head else None
        return y[:, :6], y[:, 6:N_REGRESSION], torch.sigmoid(raw[:, N_REGRESSION]), up, p_success

    def predict(self, batch: GraspBatch) -> Prediction:
        """The outputs of every row of ``batch`` (which needs ``log_e``).

        Raises :class:`~mjcodesign.errors.DesignError` for a design or density outside ``input_range``.
        """
        if batch.log_e is None:
            raise DesignError("predict needs a design per row (GraspBatch.log_e)")
        self.check_inputs(batch.log_e, batch.density)
        batch = self.prepare(batch)
        with torch.inference_mode():
            force, disp, p, _, ps = self._outputs(batch, torch.tensor(batch.log_e, dtype=self.dtype))
        force, disp, p = force.numpy().astype(float), disp.numpy().astype(float), p.numpy().astype(float)
        up = np.asarray(batch.poses.up, dtype=float)[batch.pose]
        score = success_score(force, disp, p, up, batch.mass, self.lift, self.lifted_fraction)
        return Prediction(force, disp, p, score, None if ps is None else ps.numpy().astype(float))

    def check_loss(self, loss) -> bool:
        """Whether ``loss`` reads the success head.

        Raises :class:`~mjcodesign.errors.DesignError` when it does and this network has none.
        """
        head = bool(getattr(loss, "needs_success_head", False))
        if head and not self.has_success_head:
            raise DesignError(
                "the success objective needs a surrogate with a success head (train one with "
                "--success-weight > 0; this checkpoint predicts the paper's 10 outputs only)"
            )
        return head

    def loss_rows(
        self, log_e: torch.Tensor, batch: GraspBatch, loss: DesignLoss | SuccessLoss
    ) -> torch.Tensor:
        """Per-row loss (B,) of one design ``log_e`` (a (22,) tensor of :attr:`dtype`), differentiable in it.

        ``batch`` must be prepared (:meth:`prepare`). Raises :class:`~mjcodesign.errors.DesignError` for a
        :class:`SuccessLoss` on a network without a head.
        """
        head = self.check_loss(loss)
        design = log_e.expand(len(batch), N_LOG_E)
        if head and getattr(loss, "samples", 0):
            with dropout_draws(self.model, loss.seed):
                draws = torch.stack([self._outputs(batch, design)[4] for _ in range(loss.samples)])
            return loss.draw_rows(draws)
        force, disp, p, up, ps = self._outputs(batch, design)
        return loss.rows(force, disp, p, up, ps) if head else loss.rows(force, disp, p, up)

    def loss_and_grad(
        self, design, batch: GraspBatch, loss: DesignLoss | SuccessLoss | None = None
    ) -> DesignGradient:
        """A loss of one design (22 ln E) over every row, and d L / d ln E.

        ``loss``: L_opt (:class:`DesignLoss`, the default) or the predicted failure probability
        (:class:`SuccessLoss`, which needs a success head). Raises
        :class:`~mjcodesign.errors.DesignError` for a density outside ``input_range`` (the design moves
        within the printable range, which the optimiser keeps) or a :class:`SuccessLoss` on a network
        without a head.
        """
        d = design_vector(design)
        loss = loss or DesignLoss()
        self.check_loss(loss)
        self.check_inputs(None, batch.density)
        batch = self.prepare(batch)
        x = torch.tensor(d, dtype=self.dtype, requires_grad=True)
        with torch.enable_grad():
            rows = self.loss_rows(x, batch, loss)
            total = rows.sum()
            (grad,) = torch.autograd.grad(total, x)
        return DesignGradient(total.item(), grad.numpy().astype(float), rows.detach().numpy().astype(float))
