"""The press comparison: per routing, the contact force distribution of every model on the plate.

The FEM (linear tets: contact acts at corner vertices) is the reference. The flex-quadratic model runs
the linear static contact solve (its dynamics runs at 3.4 steps/s); chain and flex run to a settled
press.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mjcodesign.crosscheck.rows import pick, row
from mjcodesign.crosscheck.shapes import Shapes
from mjcodesign.crosscheck.tensions import press_tension

__all__ = ["press_rows"]


def press_rows(
    models: list[str],
    design_name: str,
    stiffness,
    fem_options,
    tensions: list[float] | None,
    shapes: Shapes,
    on_note: Callable[[str], None] | None = None,
) -> list[dict]:
    """Press rows per routing and model at ``tensions[0]`` [N] (default :func:`press_tension`).

    A MuJoCo model that gives no rest state is left out of its routing's rows and reported to
    ``on_note`` as one line.
    """
    from dataclasses import replace

    from mjcodesign.design.finger import FingerDesign, Routing
    from mjcodesign.scenarios.press import PRESS_METRICS
    from mjcodesign.sim.fem import FemOptions

    tension = tensions[0] if tensions else press_tension(stiffness)
    fem_options = replace(fem_options or FemOptions(), order=1)
    rows = []
    for routing in Routing:
        design = FingerDesign(routing=routing)
        res = {}
        if "fem" in models:
            res["fem"] = _press_fem(design, stiffness, fem_options, tension, shapes)
        for m in models:
            if m != "fem":
                r = _press_mujoco(design, stiffness, m, tension, shapes, on_note)
                if r is not None:
                    res[m] = r
        for m in res:
            for metric in PRESS_METRICS:
                ref = res["fem"][metric] if "fem" in res else None
                name = f"{metric}[{routing.value}]@{tension:.4g}N"
                rows.append(row("press", m, design_name, name, res[m][metric], ref))
    return rows


def _press_fem(design, stiffness, fem_options, tension: float, shapes: Shapes) -> dict:
    """The FEM's press as a dict of metrics; its rest shape, contact forces and plate go to ``shapes``."""
    from dataclasses import asdict

    from mjcodesign.scenarios.press import PRESS_METRICS, plate_pose
    from mjcodesign.sim.fem import FemFinger, press_fem

    fem = FemFinger(design, stiffness, options=fem_options)
    rest: dict = {}
    res = asdict(press_fem(fem, tension, observe=lambda x, f: rest.update(x=x, f=f)))
    on = np.linalg.norm(rest["f"], axis=1) > 0
    shapes.fem(
        f"press/{design.routing.value}/fem",
        fem,
        rest["x"],
        pick(res, PRESS_METRICS),
        forces=(rest["x"][on], rest["f"][on]),
        obstacle=plate_pose(design),
    )
    return res


def _press_mujoco(design, stiffness, model: str, tension: float, shapes: Shapes, on_note) -> dict | None:
    """A MuJoCo model's press (None if it gave no rest state: ``on_note`` hears why)."""
    from mjcodesign.errors import SimulationDiverged
    from mjcodesign.models.types import FingerModel
    from mjcodesign.scenarios.press import PRESS_METRICS, press_linear, press_mujoco

    label = f"press/{design.routing.value}/{model}"
    try:
        if FingerModel(model) is FingerModel.FLEX_QUADRATIC:  # its dynamics: 3.4 steps/s
            r = press_linear(design, stiffness, model, tension, observe=shapes.mujoco(label))
        else:
            r = press_mujoco(design, stiffness, model, tension, observe=shapes.mujoco(label, plate=True))
        shapes.set_metrics(label, pick(r, PRESS_METRICS))
    except SimulationDiverged as exc:
        if on_note is not None:
            on_note(f"note: {model} press ({design.routing.value}) gave no rest state: {exc}")
        return None
    return r
