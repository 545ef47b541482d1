"""Grasp objects: mesh loading and repair, named sets, and the convex decomposition cache.

Import from here (``from mjcodesign.objects import load_object``): each name has this one public path.

- :mod:`~mjcodesign.objects.mesh`: :class:`GraspObject`, loading (YCB names, OBJ/STL/PLY files,
  ``egad-like:N``), watertight repair, densities;
- :mod:`~mjcodesign.objects.sets`: the paper's YCB splits and the procedural ``egad-like`` shapes;
- :mod:`~mjcodesign.objects.decomposition`: CoACD convex pieces, cached on disk.
"""

from mjcodesign.objects.decomposition import CoacdSettings, convex_decomposition
from mjcodesign.objects.mesh import (
    DENSITY_PRESETS,
    MESH_SUFFIXES,
    GraspObject,
    box_object,
    egad_like,
    load_folder,
    load_mesh,
    load_object,
    parse_density,
)
from mjcodesign.objects.sets import OBJECT_SETS, YCB_IN_DOMAIN, YCB_OOD, egad_like_mesh, named_set

__all__ = [
    "DENSITY_PRESETS",
    "MESH_SUFFIXES",
    "OBJECT_SETS",
    "YCB_IN_DOMAIN",
    "YCB_OOD",
    "CoacdSettings",
    "GraspObject",
    "box_object",
    "convex_decomposition",
    "egad_like",
    "egad_like_mesh",
    "load_folder",
    "load_mesh",
    "load_object",
    "named_set",
    "parse_density",
]
