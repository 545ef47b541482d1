"""Which candidate poses count in an object's loss: the top-B / patience bookkeeping of Algorithm 1.

Per object (a *group*), every iteration (the paper's Algorithm 1, ``JointOptimize``):

1. **top-B phase.** The B poses of lowest L_opt count (ties: the lower pose index first). When the set
   of B poses is the same as the iteration before, a counter rises by one; any change resets it to 0.
   When the counter reaches ``patience`` (T_p), the set is fixed.
2. **top-1 phase.** From the iteration the set is fixed on, only its best pose counts: the pose of the
   fixed set with the lowest loss at that iteration. It stays the object's chosen pose.
3. **converged.** In the top-1 phase, the object's counted loss has stayed within ``tol`` (relative)
   of a reference for ``patience`` iterations; the reference is the first top-1 loss and moves to the
   loss whenever it leaves that band (up or down: Adam's momentum overshoots, and a loss that rises
   again has not settled).

The authors' ``optimize.py`` differs: one patience counter shared by all objects and never reset (the
top-5 sums stop after 100 iterations in all, however often a set changed), no top-1 phase, and a stop
on the total loss. This module keeps the paper's per-object counters, reset on a change, because an
object whose best poses still swap has not settled on a grasp; :class:`PoseSelection` is plain numpy
so that ``tests/test_codesign.py`` can walk it step by step.
"""

from __future__ import annotations

import enum

import numpy as np

from mjcodesign.errors import DesignError

__all__ = ["Phase", "PoseSelection"]


class Phase(enum.Enum):
    """Where an object is in Algorithm 1."""

    TOP_B = "top_b"
    """The B lowest-loss poses count; the set may still change."""
    TOP_1 = "top_1"
    """The set is fixed; only its best pose counts."""
    CONVERGED = "converged"
    """Top-1 phase and the loss stopped falling."""


class PoseSelection:
    """The bookkeeping of one object over ``n_poses`` candidate poses (module docstring)."""

    def __init__(self, n_poses: int, top_b: int, patience: int, tol: float = 1e-3):
        if n_poses < 1 or top_b < 1 or patience < 1 or not tol >= 0:
            raise DesignError(
                f"a pose selection needs n_poses, top_b, patience >= 1 and tol >= 0, got "
                f"{n_poses}, {top_b}, {patience}, {tol}"
            )
        self.n_poses = int(n_poses)
        self.top_b = min(int(top_b), self.n_poses)
        self.patience = int(patience)
        self.tol = float(tol)
        self.phase = Phase.TOP_B
        self.current: tuple[int, ...] = ()
        """The top-B set of the last iteration, ascending pose indices."""
        self.unchanged = 0
        """Consecutive iterations with the same top-B set as the one before."""
        self.best_pose: int | None = None
        """The chosen pose once the set is fixed."""
        self.best_loss = np.inf
        """Reference loss of the top-1 phase (the counted loss when it last left the ``tol`` band)."""
        self.stalled = 0
        """Top-1 iterations since the counted loss last left ``best_loss · (1 ± tol)``."""

    def select(self, losses) -> np.ndarray:
        """The poses (indices, ascending) whose losses count this iteration, given all ``losses`` (n_poses,).

        Advances the state by one iteration.
        """
        loss = np.asarray(losses, dtype=float)
        if loss.shape != (self.n_poses,) or not np.all(np.isfinite(loss)):
            raise DesignError(f"a pose selection needs {self.n_poses} finite losses, got {loss.shape}")
        if self.phase is Phase.TOP_B:
            top = tuple(sorted(np.argsort(loss, kind="stable")[: self.top_b].tolist()))
            self.unchanged = self.unchanged + 1 if top == self.current else 0
            self.current = top
            if self.unchanged < self.patience:
                return np.array(top, dtype=np.int64)
            fixed = np.array(top, dtype=np.int64)
            self.best_pose = int(fixed[np.argmin(loss[fixed])])  # argmin: the first of equal losses
            self.phase = Phase.TOP_1
        value = float(loss[self.best_pose])
        if not np.isfinite(self.best_loss) or abs(value - self.best_loss) > self.tol * abs(self.best_loss):
            self.best_loss, self.stalled = value, 0
        else:
            self.stalled += 1
            if self.stalled >= self.patience:
                self.phase = Phase.CONVERGED
        return np.array([self.best_pose], dtype=np.int64)

    @property
    def converged(self) -> bool:
        """Whether the object's loss stopped falling in the top-1 phase."""
        return self.phase is Phase.CONVERGED

    def chosen(self, losses) -> int:
        """The object's pose: the fixed best, or (still in the top-B phase) the lowest of ``losses``."""
        if self.best_pose is not None:
            return self.best_pose
        return int(np.argmin(np.asarray(losses, dtype=float)))
