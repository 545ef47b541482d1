"""Typed exceptions. The CLI maps every `MjcodesignError` to exit code 2 and one line on stderr."""

from __future__ import annotations

__all__ = [
    "MjcodesignError",
    "DesignError",
    "StiffnessError",
    "CalibrationError",
    "MeshError",
    "PoseError",
    "SimulationDiverged",
    "OutputError",
    "DatasetError",
    "HardwareError",
    "ObserverError",
    "UnsupportedError",
    "ClusterError",
]


class MjcodesignError(Exception):
    """Base class of every error that is the caller's input or environment, not a bug."""


class DesignError(MjcodesignError, ValueError):
    """A finger design is geometrically invalid (non-positive size, waypoint outside a block...)."""


class StiffnessError(DesignError):
    """A stiffness vector has the wrong length, a NaN, or a value outside the printable range."""


class CalibrationError(MjcodesignError, ValueError):
    """A print calibration table is unreadable, incomplete or not monotone, or names an unknown setting."""


class MeshError(MjcodesignError):
    """A mesh file is missing, unreadable, empty or broken."""


class PoseError(MjcodesignError, ValueError):
    """A grasp pose is malformed or unreachable (below the ground, opening out of range...)."""


class SimulationDiverged(MjcodesignError, RuntimeError):
    """The solver warned (under-converged, bad qacc, NaN); the result must not be used."""


class OutputError(MjcodesignError, OSError):
    """An output path cannot be written."""


class DatasetError(MjcodesignError):
    """A dataset file is missing, truncated, unreadable or not the one its manifest records."""


class HardwareError(MjcodesignError, RuntimeError):
    """A robot, motor or camera refused a command, timed out or is missing."""


class ObserverError(MjcodesignError, RuntimeError):
    """A rollout observer (e.g. the Rerun recorder) is unknown, not installed, or cannot write."""


class UnsupportedError(MjcodesignError, NotImplementedError):
    """A backend cannot run this model or feature; raised instead of approximating it silently."""


class ClusterError(MjcodesignError, RuntimeError):
    """A Ray cluster cannot be reached or joined, or lost a task for good (its nodes died, its retries ran out)."""
