"""From simulated stiffness to print settings: calibration tables, per-block mapping, print sheet.

The paper printed one material (TPU 95A) and varied only structure: segment blocks through sparse infill
density, flexure blocks through solid layers (or wall loops). A :class:`Calibration` holds one measured
curve per block kind, setting -> Young's modulus, read from a user-editable TOML file (the packaged
default, ``mjcodesign/fabrication/calibration_tpu95a.toml``, is a labelled placeholder). :func:`plan_print`
maps each block's log E to the nearest achievable setting and reports the modulus it achieves.

Curves are interpolated piecewise-linearly in ln E over the setting, because the moduli span a factor
of about 35 and a linear interpolation in E would bias every low-stiffness block upwards.

Setting names are PrusaSlicer's; :data:`SETTINGS` gives the Bambu Studio / OrcaSlicer names too.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType

import numpy as np

try:  # stdlib from Python 3.11; the same API as the tomli package before it
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from mjcodesign.design.finger import Block, BlockKind, FingerDesign
from mjcodesign.design.stiffness import Stiffness
from mjcodesign.errors import CalibrationError

__all__ = [
    "SETTINGS",
    "INFILL_PATTERNS",
    "FINGER_NAMES",
    "SettingSpec",
    "CalibrationCurve",
    "Calibration",
    "BlockPrint",
    "PrintPlan",
    "plan_print",
]

_MPA = 1e6
_MM = 1e-3
# Settings may sit off the step grid by float noise only (a TOML 0.1 is not exactly 0.1).
_GRID_TOL = 1e-9
# Largest layer or loop count a table may name; any more is a typo at this finger's size.
_MAX_COUNT = 100
# No FDM nozzle lays layers this thick; a larger value is a unit mistake (metres or microns).
_MAX_LAYER_HEIGHT = 2e-3
_DEFAULT_TABLE = "calibration_tpu95a.toml"
FINGER_NAMES = ("A", "B")
"""Names of the two fingers, in the order of :class:`~mjcodesign.design.Stiffness` rows."""


class _Type(enum.Enum):
    PERCENT = "percent"
    COUNT = "count"
    REAL = "real"
    PATTERN = "pattern"


@dataclass(frozen=True)
class SettingSpec:
    """One slicer setting that a calibration may set, in PrusaSlicer and Bambu/Orca vocabulary."""

    prusa: str
    bambu: str
    type: _Type
    unit: str
    lo: float = 0.0
    hi: float = math.inf

    def check(self, value) -> float | str:
        """Validated value (number in ``unit``, or pattern name); raises :class:`CalibrationError`."""
        if self.type is _Type.PATTERN:
            if value not in INFILL_PATTERNS:
                raise CalibrationError(
                    f"{self.prusa} = {value!r} is not a known pattern; choose from {sorted(INFILL_PATTERNS)}"
                )
            return str(value)
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise CalibrationError(f"{self.prusa} must be a finite number, got {value!r}")
        if not self.lo <= value <= self.hi:
            raise CalibrationError(f"{self.prusa} = {value} {self.unit} is outside [{self.lo}, {self.hi}]")
        if self.type is _Type.COUNT and int(value) != value:
            raise CalibrationError(f"{self.prusa} must be a whole number of {self.unit}, got {value}")
        return float(value)

    def format(self, value: float | str) -> str:
        """Value as the slicers write it in their config files (``23%``, ``4``, ``0.5``, ``gyroid``)."""
        if self.type is _Type.PATTERN:
            return str(value)
        if self.type is _Type.PERCENT:
            return f"{value:g}%"
        if self.type is _Type.COUNT:
            return str(int(value))
        return f"{value:g}"


INFILL_PATTERNS: Mapping[str, str] = MappingProxyType(
    {
        # PrusaSlicer name -> Bambu Studio / OrcaSlicer name.
        "rectilinear": "zig-zag",
        "grid": "grid",
        "line": "line",
        "cubic": "cubic",
        "triangles": "triangles",
        "honeycomb": "honeycomb",
        "3dhoneycomb": "3dhoneycomb",
        "gyroid": "gyroid",
        "concentric": "concentric",
        "hilbertcurve": "hilbertcurve",
        "archimedeanchords": "archimedeanchords",
        "octagramspiral": "octagramspiral",
        "adaptivecubic": "adaptivecubic",
        "lightning": "lightning",
    }
)
"""Infill patterns both slicer families know, PrusaSlicer name -> Bambu/Orca name."""

SETTINGS: Mapping[str, SettingSpec] = MappingProxyType(
    {
        "fill_density": SettingSpec("fill_density", "sparse_infill_density", _Type.PERCENT, "%", 0, 100),
        "fill_pattern": SettingSpec("fill_pattern", "sparse_infill_pattern", _Type.PATTERN, ""),
        "fill_angle": SettingSpec("fill_angle", "infill_direction", _Type.REAL, "deg", 0, 360),
        "perimeters": SettingSpec("perimeters", "wall_loops", _Type.COUNT, "loops", 0, _MAX_COUNT),
        "top_solid_layers": SettingSpec(
            "top_solid_layers", "top_shell_layers", _Type.COUNT, "layers", 0, _MAX_COUNT
        ),
        "bottom_solid_layers": SettingSpec(
            "bottom_solid_layers", "bottom_shell_layers", _Type.COUNT, "layers", 0, _MAX_COUNT
        ),
        "top_solid_min_thickness": SettingSpec(
            "top_solid_min_thickness", "top_shell_thickness", _Type.REAL, "mm", 0, 100
        ),
        "bottom_solid_min_thickness": SettingSpec(
            "bottom_solid_min_thickness", "bottom_shell_thickness", _Type.REAL, "mm", 0, 100
        ),
    }
)
"""Per-block settings a calibration may name (PrusaSlicer names) and how each slicer spells them."""

_CALIBRATED = ("fill_density", "perimeters", "top_solid_layers", "bottom_solid_layers")


@dataclass(frozen=True)
class CalibrationCurve:
    """Measured Young's modulus of one block kind against one print setting.

    ``settings`` (in ``parameter``'s unit, strictly increasing, on the ``step`` grid) and ``young``
    [Pa] (strictly increasing) have the same length, at least two. ``fixed`` holds the other settings
    every block of this kind is printed with.
    """

    kind: BlockKind
    parameter: str
    settings: np.ndarray
    young: np.ndarray
    step: float
    fixed: Mapping[str, float | str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        where = f"[{self.kind.value}]"
        if self.parameter not in _CALIBRATED:
            raise CalibrationError(f"{where} parameter {self.parameter!r} is not one of {list(_CALIBRATED)}")
        spec = SETTINGS[self.parameter]
        s = _column(self.settings, f"{where} setting")
        e = _column(self.young, f"{where} young_mpa")
        if s.size != e.size:
            raise CalibrationError(f"{where} setting has {s.size} rows but young_mpa has {e.size}")
        if s.size < 2:
            raise CalibrationError(f"{where} needs at least two rows, got {s.size}")
        for v in s:
            spec.check(float(v))
        if np.any(e <= 0):
            raise CalibrationError(f"{where} young_mpa must be positive")
        if np.any(np.diff(s) <= 0):
            raise CalibrationError(f"{where} setting must be strictly increasing")
        if np.any(np.diff(e) <= 0):
            i = int(np.flatnonzero(np.diff(e) <= 0)[0])
            raise CalibrationError(
                f"{where} young_mpa is not monotone: {e[i] / _MPA:g} MPa at {s[i]:g} then "
                f"{e[i + 1] / _MPA:g} MPa at {s[i + 1]:g} {spec.unit}"
            )
        if not (math.isfinite(self.step) and self.step > 0):
            raise CalibrationError(f"{where} step must be positive, got {self.step}")
        if spec.type is _Type.COUNT and int(self.step) != self.step:
            raise CalibrationError(f"{where} step must be a whole number of {spec.unit}")
        k = (s - s[0]) / self.step
        if np.any(np.abs(k - np.round(k)) > _GRID_TOL * max(1.0, float(np.abs(k).max()))):
            raise CalibrationError(f"{where} settings must lie on the step grid ({self.step:g} {spec.unit})")
        fixed = {}
        for key, value in dict(self.fixed).items():
            if key not in SETTINGS:
                raise CalibrationError(f"{where} fixed setting {key!r} is not one of {sorted(SETTINGS)}")
            if key == self.parameter:
                raise CalibrationError(f"{where} fixed repeats the calibrated parameter {key!r}")
            fixed[key] = SETTINGS[key].check(value)
        s.setflags(write=False)
        e.setflags(write=False)
        object.__setattr__(self, "settings", s)
        object.__setattr__(self, "young", e)
        object.__setattr__(self, "fixed", MappingProxyType(fixed))

    @property
    def unit(self) -> str:
        """Unit of the calibrated setting (``%``, ``layers``, ``loops``)."""
        return SETTINGS[self.parameter].unit

    def young_at(self, setting: np.ndarray | float) -> np.ndarray:
        """Young's modulus [Pa] at ``setting`` (interpolated in ln E, clamped to the table)."""
        return np.exp(np.interp(setting, self.settings, np.log(self.young)))

    def nearest(self, young: float) -> tuple[float, float, bool]:
        """Achievable setting nearest in ln E to ``young`` [Pa].

        Returns (setting, achieved Young's modulus [Pa], clamped), where ``clamped`` says ``young`` lies
        outside the table and the end row was taken.
        """
        target = math.log(young)
        log_e = np.log(self.young)
        clamped = bool(target < log_e[0] or target > log_e[-1])
        exact = float(np.interp(target, log_e, self.settings))
        k = (exact - self.settings[0]) / self.step
        candidates = {
            round(float(self.settings[0] + self.step * j), 9) for j in (math.floor(k), math.ceil(k))
        }
        candidates = [min(max(c, self.settings[0]), self.settings[-1]) for c in candidates]
        best = min(candidates, key=lambda c: (abs(math.log(self.young_at(c)) - target), c))
        return best, float(self.young_at(best)), clamped

    def slicer_settings(self, setting: float) -> dict[str, float | str]:
        """All per-block settings (PrusaSlicer names) for a block printed at ``setting``."""
        return {**self.fixed, self.parameter: SETTINGS[self.parameter].check(setting)}


@dataclass(frozen=True)
class Calibration:
    """Calibration of one material: one curve for segment blocks, one for flexure blocks.

    ``layer_height`` and ``first_layer_height`` [m] are the layer heights the curves were measured at;
    the export sets the first per object and prints the second on the sheet (it is a printer setting).
    """

    name: str
    material: str
    segment: CalibrationCurve
    flexure: CalibrationCurve
    layer_height: float
    first_layer_height: float
    example: bool = False
    source: str = ""

    def __post_init__(self) -> None:
        if self.segment.kind is not BlockKind.SEGMENT or self.flexure.kind is not BlockKind.FLEXURE:
            raise CalibrationError("calibration curves are assigned to the wrong block kinds")
        for name in ("layer_height", "first_layer_height"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v < _MAX_LAYER_HEIGHT):
                raise CalibrationError(
                    f"{name}_mm must be in (0, {_MAX_LAYER_HEIGHT / _MM:g}) mm, got {v / _MM:g}"
                )

    def curve(self, kind: BlockKind) -> CalibrationCurve:
        """The curve for a block kind."""
        return self.segment if kind is BlockKind.SEGMENT else self.flexure

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read a calibration TOML file (see the packaged default for the format)."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise CalibrationError(f"cannot read calibration file {path}: {exc}") from exc
        return cls.from_toml(text, source=str(path))

    @classmethod
    def default(cls) -> Calibration:
        """The packaged example table (placeholder values for TPU 95A, not measurements)."""
        text = resources.files("mjcodesign.fabrication").joinpath(_DEFAULT_TABLE).read_text(encoding="utf-8")
        return cls.from_toml(text, source=f"mjcodesign/fabrication/{_DEFAULT_TABLE}")

    @classmethod
    def from_toml(cls, text: str, source: str = "") -> Calibration:
        """Parse a calibration from TOML text."""
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise CalibrationError(f"calibration {source or 'text'} is not valid TOML: {exc}") from exc
        head = _table(data, "calibration")
        curves = {}
        for kind in BlockKind:
            t = _table(data, kind.value)
            parameter = _get(t, "parameter", kind.value)
            if parameter not in SETTINGS:
                raise CalibrationError(
                    f"[{kind.value}] parameter {parameter!r} is not one of {list(_CALIBRATED)}"
                )
            unit = _get(t, "unit", kind.value)
            if unit != SETTINGS[parameter].unit:
                want = SETTINGS[parameter].unit
                raise CalibrationError(
                    f"[{kind.value}] unit {unit!r} does not match {parameter} (in {want!r})"
                )
            fixed = t.get("fixed", {})
            if not isinstance(fixed, dict):
                raise CalibrationError(f"[{kind.value}] fixed must be a table of settings")
            curves[kind] = CalibrationCurve(
                kind=kind,
                parameter=parameter,
                settings=_get(t, "setting", kind.value),
                young=np.asarray(_column(_get(t, "young_mpa", kind.value), f"[{kind.value}] young_mpa"))
                * _MPA,
                step=_number(t.get("step", 1), f"[{kind.value}] step"),
                fixed=fixed,
            )
        return cls(
            name=str(head.get("name", source)),
            material=str(_get(head, "material", "calibration")),
            segment=curves[BlockKind.SEGMENT],
            flexure=curves[BlockKind.FLEXURE],
            layer_height=_number(_get(head, "layer_height_mm", "calibration"), "layer_height_mm") * _MM,
            first_layer_height=_number(
                _get(head, "first_layer_height_mm", "calibration"), "first_layer_height_mm"
            )
            * _MM,
            example=bool(head.get("example", False)),
            source=source,
        )


@dataclass(frozen=True)
class BlockPrint:
    """How to print one block: the target modulus, the chosen setting and what it achieves."""

    finger: int
    """Finger index (0 = A, 1 = B)."""
    block: Block
    log_e: float
    """Target ln(E / Pa) from the design."""
    parameter: str
    """The calibrated setting (PrusaSlicer name)."""
    setting: float
    """Its chosen value, in :attr:`unit`."""
    unit: str
    achieved_e: float
    """Young's modulus [Pa] the calibration gives for :attr:`setting`."""
    clamped: bool
    """The target lies outside the calibration table; the end row was taken."""
    settings: Mapping[str, float | str]
    """Every per-block slicer setting (PrusaSlicer names), the calibrated one included."""

    @property
    def name(self) -> str:
        """Object name in the 3MF and STL files, e.g. ``A03_flexure``."""
        return f"{FINGER_NAMES[self.finger]}{self.block.index:02d}_{self.block.kind.value}"

    @property
    def target_e(self) -> float:
        """Target Young's modulus [Pa]."""
        return math.exp(self.log_e)

    @property
    def rel_error(self) -> float:
        """(achieved − target) / target, dimensionless."""
        return self.achieved_e / self.target_e - 1.0

    def as_dict(self) -> dict:
        """JSON-ready record (moduli in Pa)."""
        return {
            "name": self.name,
            "finger": FINGER_NAMES[self.finger],
            "index": self.block.index,
            "kind": self.block.kind.value,
            "log_e": self.log_e,
            "target_e": self.target_e,
            "parameter": self.parameter,
            "setting": self.setting,
            "unit": self.unit,
            "achieved_e": self.achieved_e,
            "achieved_log_e": math.log(self.achieved_e),
            "rel_error": self.rel_error,
            "clamped": self.clamped,
            "slicer_settings": {k: SETTINGS[k].format(v) for k, v in self.settings.items()},
        }


@dataclass(frozen=True)
class PrintPlan:
    """Print settings of every block of both fingers: ``blocks[finger][block]``."""

    design: FingerDesign
    calibration: Calibration
    blocks: tuple[tuple[BlockPrint, ...], ...]

    def __iter__(self):
        """All blocks, finger A base to tip, then finger B."""
        return (b for finger in self.blocks for b in finger)

    @property
    def max_abs_rel_error(self) -> float:
        """Largest ``|achieved / target − 1|`` over all blocks."""
        return max(abs(b.rel_error) for b in self)

    def as_dict(self) -> dict:
        """JSON-ready print sheet (moduli in Pa, lengths in mm)."""
        cal = self.calibration
        return {
            "calibration": {
                "name": cal.name,
                "material": cal.material,
                "source": cal.source,
                "example": cal.example,
                "layer_height_mm": cal.layer_height / _MM,
                "first_layer_height_mm": cal.first_layer_height / _MM,
            },
            "finger": {
                "length_mm": self.design.length / _MM,
                "width_mm": self.design.width / _MM,
                "flexure_thickness_mm": self.design.flexure_thickness / _MM,
            },
            "max_abs_rel_error": self.max_abs_rel_error,
            "blocks": [b.as_dict() for b in self],
        }

    def markdown(self) -> str:
        """Human print sheet: prerequisites, then one row per block."""
        cal = self.calibration
        lines = [
            "# Print sheet",
            "",
            f"Material: {cal.material}. Calibration: {cal.name} ({cal.source}).",
        ]
        if cal.example:
            lines += [
                "",
                "**The calibration is the packaged EXAMPLE with placeholder values, not measurements. "
                "Measure your own coupons and pass your table with --calibration.**",
            ]
        lines += [
            "",
            f"Printer settings the calibration assumes: layer height {cal.layer_height / _MM:g} mm, "
            f"first layer height {cal.first_layer_height / _MM:g} mm. Each finger prints as one object, "
            "lying on its flexure side (the 2 mm spine on the bed), with per-block settings on its parts.",
            "",
            "| block | log E | target E [MPa] | setting | achieved E [MPa] | error | other settings |",
            "|---|---|---|---|---|---|---|",
        ]
        for b in self:
            other = ", ".join(
                f"{k}={SETTINGS[k].format(v)}" for k, v in b.settings.items() if k != b.parameter
            )
            note = " (clamped)" if b.clamped else ""
            lines.append(
                f"| {b.name} | {b.log_e:.3f} | {b.target_e / _MPA:.3g} | {b.parameter} "
                f"{SETTINGS[b.parameter].format(b.setting)} | {b.achieved_e / _MPA:.3g} | "
                f"{b.rel_error:+.1%}{note} | {other} |"
            )
        lines += ["", f"Largest |error|: {self.max_abs_rel_error:.1%}.", ""]
        return "\n".join(lines)


def plan_print(
    stiffness: Stiffness, calibration: Calibration, design: FingerDesign | None = None
) -> PrintPlan:
    """Map every block's log E to the nearest achievable setting of its kind's calibration curve."""
    design = design or FingerDesign()
    blocks = design.blocks()
    if stiffness.n_blocks != len(blocks):
        raise CalibrationError(
            f"stiffness has {stiffness.n_blocks} blocks per finger but the design has {len(blocks)}"
        )
    fingers = []
    for f, row in enumerate(stiffness.log_e):
        out = []
        for block, log_e in zip(blocks, row, strict=True):
            curve = calibration.curve(block.kind)
            setting, achieved, clamped = curve.nearest(math.exp(float(log_e)))
            out.append(
                BlockPrint(
                    finger=f,
                    block=block,
                    log_e=float(log_e),
                    parameter=curve.parameter,
                    setting=setting,
                    unit=curve.unit,
                    achieved_e=achieved,
                    clamped=clamped,
                    settings=MappingProxyType(curve.slicer_settings(setting)),
                )
            )
        fingers.append(tuple(out))
    return PrintPlan(design=design, calibration=calibration, blocks=tuple(fingers))


def _table(data: dict, name: str) -> dict:
    t = data.get(name)
    if not isinstance(t, dict):
        raise CalibrationError(f"calibration has no [{name}] table")
    return t


def _get(table: dict, key: str, where: str):
    if key not in table:
        raise CalibrationError(f"[{where}] is missing {key!r}")
    return table[key]


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CalibrationError(f"{what} must be a finite number, got {value!r}")
    return float(value)


def _column(values, what: str) -> np.ndarray:
    if isinstance(values, np.ndarray):
        arr = values.astype(float, copy=True)
    else:
        if not isinstance(values, list | tuple) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in values
        ):
            raise CalibrationError(f"{what} must be a list of numbers")
        arr = np.array(values, dtype=float)
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{what} must be a flat list of finite numbers")
    return arr
