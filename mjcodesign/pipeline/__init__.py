"""The one-command pipeline: from a user's objects to a verified, printable gripper (``mjcodesign design``).

Import from here (``from mjcodesign.pipeline import run_design``): each name has this one public path.
It composes the layers below it: pose sampling, the co-design through the surrogate, the evaluation's
re-simulation with perturbations, the print files, and a report.

- :mod:`~mjcodesign.pipeline.specs`: the objects and their masses (:func:`parse_objects`);
- :mod:`~mjcodesign.pipeline.run`: :func:`run_design` and :class:`DesignOptions`;
- :mod:`~mjcodesign.pipeline.adapt`: :func:`adapt_surrogate`, the fine-tuning of ``design --adapt``;
- :mod:`~mjcodesign.pipeline.report`: ``report.md``, ``report.html`` and their figures, the grasp
  images rendered off screen (:class:`~mjcodesign.pipeline.GraspImages`).
"""

from mjcodesign.pipeline.adapt import ADAPT_LR, adapt_surrogate
from mjcodesign.pipeline.report import (
    GL_BACKENDS,
    GRASP_IMAGE_SIZE,
    GraspImages,
    block_outline,
    png_bytes,
    write_report,
)
from mjcodesign.pipeline.run import (
    ADAPTED_DIR,
    BASELINES,
    OPTIMISED,
    SWEEP_IMPULSES,
    DesignOptions,
    run_design,
)
from mjcodesign.pipeline.specs import DEFAULT_DENSITY, ObjectSpec, parse_mass_text, parse_objects, read_masses

__all__ = [
    "ADAPTED_DIR",
    "ADAPT_LR",
    "BASELINES",
    "DEFAULT_DENSITY",
    "GL_BACKENDS",
    "GRASP_IMAGE_SIZE",
    "OPTIMISED",
    "SWEEP_IMPULSES",
    "DesignOptions",
    "adapt_surrogate",
    "GraspImages",
    "block_outline",
    "ObjectSpec",
    "parse_mass_text",
    "parse_objects",
    "png_bytes",
    "read_masses",
    "run_design",
    "write_report",
]
