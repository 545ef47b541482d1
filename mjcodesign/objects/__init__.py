"""Grasp objects: mesh loading and repair, named sets, and the convex decomposition cache.

Import from here (``from mjcodesign.objects import load_object``): each name has this one public path.

- :mod:`~mjcodesign.objects.mesh`: :class:`GraspObject`, loading (YCB names, OBJ/STL/PLY files,
  ``egad-like:N``), watertight repair, densities;
- :mod:`~mjcodesign.objects.repair`: watertight repair (manifold3d, pymeshfix), cached on disk;
- :mod:`~mjcodesign.objects.sweep`: the object in the fingers' sweep and the start openings it allows;
- :mod:`~mjcodesign.objects.sets`: the paper's YCB splits and the procedural ``egad-like`` shapes;
- :mod:`~mjcodesign.objects.masses`: the YCB objects' published masses, and an object at a given mass;
- :mod:`~mjcodesign.objects.decomposition`: CoACD convex pieces, cached on disk.
"""

from mjcodesign.objects.decomposition import CoacdSettings, convex_decomposition
from mjcodesign.objects.masses import (
    MASS_MODES,
    MASS_TABLE,
    MAX_MASS,
    PublishedMass,
    at_mass,
    mass_by_rule,
    mass_table,
    parse_mass,
    published_mass,
    published_mass_or_none,
    real_density,
)
from mjcodesign.objects.mesh import (
    DENSITY_PRESETS,
    MESH_SUFFIXES,
    YCB_MEDIAN_DENSITY,
    GraspObject,
    box_object,
    egad_like,
    load_folder,
    load_mesh,
    load_object,
    object_name,
    parse_density,
)
from mjcodesign.objects.repair import (
    MAX_REPAIR_DEVIATION,
    REPAIR_CHAIN,
    RepairMethod,
    repair_deviation,
    repair_mesh,
    repair_metrics,
    watertight,
)
from mjcodesign.objects.sets import (
    OBJECT_SETS,
    YCB_IN_DOMAIN,
    YCB_OOD,
    check_seed,
    egad_like_mesh,
    named_set,
    parse_egad_index,
)
from mjcodesign.objects.sweep import (
    START_CLEARANCE,
    FingerSweep,
    SweepStatus,
    slab_y_ranges,
    sweep_failure,
    sweep_starts,
)

__all__ = [
    "DENSITY_PRESETS",
    "YCB_MEDIAN_DENSITY",
    "MASS_MODES",
    "MASS_TABLE",
    "MAX_MASS",
    "MAX_REPAIR_DEVIATION",
    "MESH_SUFFIXES",
    "OBJECT_SETS",
    "REPAIR_CHAIN",
    "START_CLEARANCE",
    "YCB_IN_DOMAIN",
    "YCB_OOD",
    "CoacdSettings",
    "FingerSweep",
    "GraspObject",
    "PublishedMass",
    "RepairMethod",
    "SweepStatus",
    "at_mass",
    "box_object",
    "check_seed",
    "convex_decomposition",
    "egad_like",
    "egad_like_mesh",
    "load_folder",
    "load_mesh",
    "load_object",
    "mass_by_rule",
    "mass_table",
    "named_set",
    "object_name",
    "parse_density",
    "parse_egad_index",
    "parse_mass",
    "published_mass",
    "published_mass_or_none",
    "real_density",
    "repair_deviation",
    "repair_mesh",
    "repair_metrics",
    "slab_y_ranges",
    "sweep_failure",
    "sweep_starts",
    "watertight",
]
