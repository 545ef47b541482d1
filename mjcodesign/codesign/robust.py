"""Co-design for a model that is uncertain: one surrogate per model variant, seen as one.

The simulator's answer depends on settings that cannot be settled without a bench: the tendon's path
(``guided`` over every hinge or ``printed`` through the channels, which buckles soft flexures) and the
finger–object friction (0.6 – 1.0, :data:`~mjcodesign.scenarios.TAPE_FRICTION_RANGE`). A
:class:`VariantSurrogate` holds one surrogate trained on each variant's data (the first one the nominal
model) and gives :func:`~mjcodesign.codesign.optimize.optimize` one loss per (object, pose) row:

- ``worst``: the largest of the variants' losses (for the success objective, ``1 −`` the smallest
  predicted success probability), so a design is judged by the variant it does worst under;
- ``mean``: their mean (the expected loss when every variant is equally likely).

Pose selection (the B best poses, then the best) ranks the combined loss, so the pose chosen for an
object is the one that holds up across the variants. The gradient is that of the combined loss: under
``worst``, each row's gradient comes from the variant that is worst there.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from mjcodesign.errors import DesignError

__all__ = ["Robust", "VariantSurrogate"]


class Robust(enum.Enum):
    """How the variants' losses of a row combine."""

    WORST = "worst"
    MEAN = "mean"


@dataclass(frozen=True)
class _Batches:
    """One prepared batch per variant (the same rows, each with that surrogate's pose features)."""

    parts: tuple

    def __len__(self) -> int:
        return len(self.parts[0])

    @property
    def density(self) -> np.ndarray:
        return self.parts[0].density


class VariantSurrogate:
    """Surrogates of the same finger under several model variants, combined row by row (module docstring).

    ``members``: (name, :class:`~mjcodesign.surrogate.Surrogate`) pairs, the nominal model first; its
    record (``meta``), lift and success constants are this surrogate's. Raises :class:`DesignError` for
    fewer than two members or a repeated name.
    """

    def __init__(self, members, rule: Robust | str = Robust.WORST):
        members = tuple((str(n), s) for n, s in members)
        names = [n for n, _ in members]
        if len(members) < 2:
            raise DesignError("a robust co-design needs the nominal surrogate and at least one variant")
        if len(set(names)) != len(names):
            raise DesignError(f"the variants' names must differ, got {names}")
        try:
            self.rule = Robust(rule)
        except ValueError:
            raise DesignError(f"--robust must be worst or mean, got {rule!r}") from None
        self.members = members
        nominal = members[0][1]
        self.meta = nominal.meta
        self.lift = nominal.lift
        self.lifted_fraction = nominal.lifted_fraction

    @property
    def names(self) -> tuple[str, ...]:
        """The variants' names, the nominal first."""
        return tuple(n for n, _ in self.members)

    @property
    def has_success_head(self) -> bool:
        """Whether every variant's network has a success head."""
        return all(s.has_success_head for _, s in self.members)

    def check_inputs(self, log_e, density) -> None:
        """Each variant's input-range check (:meth:`~mjcodesign.surrogate.Surrogate.check_inputs`)."""
        for _, s in self.members:
            s.check_inputs(log_e, density)

    def prepare(self, batch):
        """``batch`` prepared for every variant's network."""
        if isinstance(batch, _Batches):
            return batch
        return _Batches(tuple(s.prepare(batch) for _, s in self.members))

    def _combine(self, stacked):
        return stacked.max(dim=0).values if self.rule is Robust.WORST else stacked.mean(dim=0)

    def loss_and_grad(self, design, batch, loss=None):
        """The combined loss of one design over every row, and its gradient in ln E.

        ``loss`` as :meth:`~mjcodesign.surrogate.Surrogate.loss_and_grad` takes it; a loss that counts
        only some rows (the optimiser's pose selection) ranks and counts the *combined* rows.
        """
        import torch

        from mjcodesign.surrogate import DesignGradient, DesignLoss
        from mjcodesign.surrogate.inference import design_vector

        d = design_vector(design)
        loss = loss or DesignLoss()
        plain = loss.uncounted() if hasattr(loss, "counted") else loss
        for _, s in self.members:
            s.check_loss(plain)
        self.check_inputs(None, batch.density)
        batch = self.prepare(batch)
        x = torch.tensor(d, dtype=torch.float64, requires_grad=True)
        with torch.enable_grad():
            rows = [
                s.loss_rows(x.to(s.dtype), b, plain).to(torch.float64)
                for (_, s), b in zip(self.members, batch.parts, strict=True)
            ]
            combined = self._combine(torch.stack(rows))
            if hasattr(loss, "counted"):
                combined = loss.counted(combined)
            total = combined.sum()
            (grad,) = torch.autograd.grad(total, x)
        return DesignGradient(
            total.item(), grad.numpy().astype(float), combined.detach().numpy().astype(float)
        )

    def predict(self, batch):
        """The variants' predictions combined: the worst (or mean) success score and head probability.

        The physical outputs (force, displacement, ground contact) are the nominal variant's.
        """
        from mjcodesign.surrogate import Prediction

        preds = [s.predict(batch) for _, s in self.members]
        pick = np.min if self.rule is Robust.WORST else np.mean
        score = pick(np.stack([p.success_score for p in preds]), axis=0)
        heads = [p.success_p for p in preds]
        p = None if any(h is None for h in heads) else pick(np.stack(heads), axis=0)
        first = preds[0]
        return Prediction(first.body_force, first.displacement, first.ground_contact, score, p)
