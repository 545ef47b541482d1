"""What a simulator hands to an observer, and how observers are found.

An observer (the Rerun recorder of the top-level ``viz`` package, for one) receives whole rollouts and
rest shapes after they are computed, so it never changes a simulation. Observers are found by
name in the entry-point group ``mjcodesign.observers`` (``pyproject.toml``); the core never imports
them, and :func:`load_observer` turns a missing one into an :class:`~mjcodesign.errors.ObserverError`.

An observer that replays states may also offer :class:`Capture`: a backend that steps a rollout itself
(MuJoCo C's ``run``) then hands it, in :attr:`Rollout.captured`, what the observer copied from
``MjData`` (read only) at the steps it asked for, instead of the observer recomputing them
(``mj_forward`` per logged state); the copies are the only time an observer adds to a run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from mjcodesign.errors import ObserverError

if TYPE_CHECKING:
    import mujoco

    from mjcodesign.models.types import Built
    from mjcodesign.scenarios.grasp import GraspScenario, GraspScene
    from mjcodesign.scenarios.outcome import Outcome

__all__ = [
    "ENTRY_POINT_GROUP",
    "Rollout",
    "Snapshot",
    "Observer",
    "Capture",
    "observer_class",
    "load_observer",
]

ENTRY_POINT_GROUP = "mjcodesign.observers"


@dataclass(frozen=True)
class Rollout:
    """One grasp rollout, complete enough to replay every step.

    ``mj_setState`` of ``states[t]``, then the controls of step t+1 and ``mj_forward``, reproduce the
    data of step t, contact forces included.
    """

    label: str
    """Name of the run (a design preset, a backend...); observers keep runs with different labels apart."""
    scene: GraspScene
    scenario: GraspScenario
    model: mujoco.MjModel
    """The model that ran: the scene's, or a copy with another design's stiffness."""
    log_e: np.ndarray
    """ln(E / Pa) of the design that ran, per finger and block, shape (2, n_blocks): what the backend
    was given (``scene.built.stiffness``), never read back from the model."""
    x0: np.ndarray
    """Initial state, ``mjSTATE_FULLPHYSICS``, shape (nstate,)."""
    states: np.ndarray
    """State after every step, shape (nstep, nstate); fewer rows than ``ctrl`` if the run diverged."""
    ctrl: np.ndarray
    """Controls of every step (``scenario.control_spec()``), shape (nstep, nu + 6 nbody)."""
    starts: dict[str, int]
    """First step of every phase, and ``end`` (:func:`mjcodesign.scenarios.grasp.phase_controls`)."""
    outcome: Outcome
    scratch: mujoco.MjData | None = field(default=None, compare=False, repr=False)
    """An ``MjData`` of ``model`` that the simulator is done with (None if it has none to spare): an
    observer may overwrite it instead of allocating its own (the arena of a scene is ~15 MB)."""
    captured: dict[int, Any] = field(default_factory=dict, compare=False, repr=False)
    """What the observer's :meth:`Capture.capture` returned per step (-1: the initial state), for the
    steps of :meth:`Capture.capture_steps` that the simulator could take; empty otherwise."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "log_e", np.asarray(self.log_e, dtype=float))
        if self.log_e.ndim != 2:
            raise ValueError(f"log_e must have shape (n_fingers, n_blocks), got {self.log_e.shape}")
        if self.states.ndim != 2 or self.states.shape[1] != self.x0.size:
            raise ValueError(f"states must have shape (nstep, {self.x0.size}), got {self.states.shape}")
        if len(self.states) > len(self.ctrl):
            raise ValueError("more states than control steps")


@dataclass(frozen=True)
class Snapshot:
    """One finger at rest under a load (crosscheck scenarios), in the finger frame [m].

    Either a MuJoCo model (``built`` and its ``data`` at rest) or a tetrahedral mesh (``positions``,
    ``tets``, ``tet_block``, ``tendon``: the Warp FEM).
    """

    label: str
    """Name of the shape, '/'-separated (``curl/chain/0.08N``); observers keep labels apart."""
    log_e: np.ndarray
    """ln(E / Pa) of the finger's blocks, base to tip, shape (n_blocks,)."""
    metrics: dict[str, float] = field(default_factory=dict)
    built: Built | None = None
    data: mujoco.MjData | None = None
    positions: np.ndarray | None = None
    """Deformed vertices [m], shape (n_vertices, 3)."""
    tets: np.ndarray | None = None
    """Vertex indices, corners first, shape (n_tets, 4) or (n_tets, 10)."""
    tet_block: np.ndarray | None = None
    """Block index of every tet, shape (n_tets,)."""
    tendon: np.ndarray | None = None
    """Tendon waypoints [m], base to tip, shape (n_waypoints, 3)."""
    group: str | None = None
    """Shapes of one group (a prefix of ``label``, e.g. one model's curls at several tensions) are drawn
    in one place; None: the label alone."""
    forces: tuple[np.ndarray, np.ndarray] | None = None
    """External forces on the finger: points [m] (k, 3) and forces [N] (k, 3) (contacts, a tip load)."""
    obstacle: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """A box the finger rests against: centre [m] (3,), rotation (3, 3), half extents [m] (3,)."""

    def __post_init__(self) -> None:
        if self.group is not None and not (self.label + "/").startswith(self.group + "/"):
            raise ValueError(f"group {self.group!r} is not a prefix of the label {self.label!r}")
        mujoco_given = self.built is not None and self.data is not None
        mesh_given = self.positions is not None and self.tets is not None and self.tet_block is not None
        if mujoco_given == mesh_given:
            raise ValueError("a snapshot needs either built and data, or positions, tets and tet_block")


class Observer(Protocol):
    """What a backend or command calls; an observer writes or shows, it never changes the runs."""

    def rollout(self, rollout: Rollout) -> None:
        """Record one grasp rollout."""
        ...

    def snapshot(self, snapshot: Snapshot) -> None:
        """Record one rest shape."""
        ...

    def close(self) -> None:
        """Flush and release the output (a file is complete afterwards)."""
        ...


@runtime_checkable
class Capture(Protocol):
    """Optional for an observer: take what it logs of a state while the simulator steps.

    After ``mj_step`` with the controls of step t+1, ``MjData`` still holds the forward quantities
    (kinematics, tendon paths, contacts, constraint and actuator forces) of state t: only the state
    itself moved on. These are what ``mj_setState`` of ``states[t]``, the controls of step t+1 and
    ``mj_forward`` give (up to the constraint solver's tolerance: the warm start differs), so a
    simulator calls :meth:`capture` right after that step and the observer need not replay it.
    """

    def capture_steps(self, n_steps: int, timestep: float, starts: dict[str, int]) -> set[int]:
        """The states to capture among ``-1`` (the initial state) ... ``n_steps - 1``."""
        ...

    def capture(self, model: mujoco.MjModel, data: mujoco.MjData) -> Any:
        """Copy what is needed from ``data`` (which must not be changed)."""
        ...


def observer_class(name: str) -> type:
    """The class registered as ``name`` in ``mjcodesign.observers`` (imports its package).

    Raises :class:`ObserverError` with one line if it is not registered or its package (e.g.
    ``rerun-sdk``) is not installed.
    """
    eps = entry_points(group=ENTRY_POINT_GROUP)
    if name not in eps.names:
        known = ", ".join(sorted(eps.names)) or "none"
        raise ObserverError(f"no observer named {name!r} is installed (registered: {known})")
    try:
        return eps[name].load()
    except ImportError as exc:
        raise ObserverError(
            f"observer {name!r} is not usable: {exc} (install the extra: pip install 'mjcodesign[viz]')"
        ) from exc


def load_observer(name: str, **options) -> Observer:
    """The observer registered as ``name``, constructed with ``options`` (see :func:`observer_class`)."""
    return observer_class(name)(**options)
