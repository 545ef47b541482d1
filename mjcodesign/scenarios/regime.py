"""The grasp's physical regime: the scenario and the rule that sets each object's mass, as one named choice.

Two regimes are named (``--regime`` on the commands that simulate grasps):

- ``real`` (the default of every command): :data:`~mjcodesign.scenarios.grasp.REAL_REGIME`, the grasp
  as the hardware runs it (the XL330 servo at the paper's 1000 ticks on the authors' 8 mm horn, the
  paper's 10 cm lift at the arm's speed, the paper's disturbance as a velocity change of the object,
  friction 1), each YCB object at its published mass and every other object (a user's mesh,
  ``egad-like:N``, a YCB object the list gives no mass for) at
  :data:`~mjcodesign.objects.YCB_MEDIAN_DENSITY`.
- ``paper``: the paper's relative scale, ``GraspScenario()`` (a constant 10 N tendon force, a 3 cm lift,
  the paper's impulse mapped to real size, friction 1) at the ``light`` density.

A regime gives defaults: a command's explicit flags (``--tendon``, ``--density``, ``--mass`` …) replace
the setting they name. :func:`regime_name` names the regime a dataset or a run was made under, or
``custom`` when its settings are another mix. ``GraspScenario()`` itself stays the paper's scale, the
library's neutral default; the commands start from :data:`DEFAULT_REGIME`.
"""

from __future__ import annotations

from dataclasses import dataclass

from mjcodesign.errors import DesignError
from mjcodesign.objects import MASS_MODES, parse_density
from mjcodesign.scenarios.drive import TendonForce
from mjcodesign.scenarios.grasp import REAL_REGIME, GraspScenario

__all__ = ["DEFAULT_REGIME", "REGIMES", "Regime", "get_regime", "regime_name"]


@dataclass(frozen=True)
class Regime:
    """A named grasp regime: the scenario, and how an object's mass is set."""

    name: str
    scenario: GraspScenario
    mass: str
    """Mass rule (:data:`~mjcodesign.objects.MASS_MODES`): ``auto`` (the published mass, else
    :attr:`density`) or ``density``."""
    density: str
    """Density preset or kg/m³ of the objects :attr:`mass` leaves to a density."""
    summary: str

    def masses(
        self, density: str | float | None, mass: str | float | None
    ) -> tuple[str | float, str | float]:
        """(density, mass rule) of a command's ``--density`` and ``--mass`` (None: not given) in this regime.

        Neither given: the regime's. A density alone: every object from it (``density``). A mass rule or
        mass given: it, with the given density or the regime's for the objects it leaves to one.
        """
        if mass is None:
            return (self.density, self.mass) if density is None else (density, "density")
        return (self.density if density is None else density), mass

    def __post_init__(self) -> None:
        if self.mass not in MASS_MODES:
            raise DesignError(f"regime {self.name}: mass rule {self.mass!r} is not one of {MASS_MODES}")
        parse_density(self.density)


REGIMES: dict[str, Regime] = {
    "real": Regime(
        "real",
        REAL_REGIME,
        mass="auto",
        density="ycb-median",
        summary="the hardware's grasp: XL330 servo at 1000 ticks on the 8 mm horn, 10 cm lift, disturbance "
        "0.51 m/s, friction 1; YCB objects at their published masses, others at 680 kg/m³",
    ),
    "paper": Regime(
        "paper",
        GraspScenario(),
        mass="density",
        density="light",
        summary="the paper's relative scale: 10 N tendon force, 3 cm lift, impulse 0.0179 N s, friction 1, "
        "light density (100 kg/m³)",
    ),
}
"""The named regimes, by ``--regime`` value."""

DEFAULT_REGIME = "real"
"""The regime every command simulates in unless told otherwise: designs disagree on 31 % [27, 36] of
(object, pose) pairs under it (``bench landscape --regime real``, docs/regime.md), against 3 % of
rollouts failing at the paper's ``light`` scale."""


def get_regime(name: str) -> Regime:
    """The regime called ``name``; :class:`DesignError` (one line) for an unknown name."""
    try:
        return REGIMES[name]
    except KeyError:
        raise DesignError(f"--regime must be one of {', '.join(REGIMES)}, got {name!r}") from None


def regime_name(scenario: GraspScenario, mass: str) -> str:
    """The name of the regime that ``scenario`` and the mass rule ``mass`` make, or ``custom``.

    ``real``: the real scenario with published masses (``auto`` or ``real``). ``paper``: the paper's
    scenario with a 10 N force tendon, masses from a density (any density: the paper has a light and a
    heavy protocol, and a uniform range between them is still its scale).
    """
    if scenario == REGIMES["real"].scenario and mass in ("auto", "real"):
        return "real"
    if scenario == GraspScenario(tendon=TendonForce()) and mass == "density":
        return "paper"
    return "custom"
