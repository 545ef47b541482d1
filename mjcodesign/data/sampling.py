"""Randomness of a dataset, keyed by position so that it does not depend on who computes what, or when.

Every random draw comes from ``SeedSequence(seed, spawn_key=key)`` (what ``SeedSequence(seed).spawn``
hands out) with a key made of the object's and the pose's index in the dataset: the pose sampler of
object ``o`` from key ``(o,)``; the density, designs, point cloud and perturbation draws of pose ``p``
from the four children of key ``(o, p)``. So a shard's numbers are the same whichever worker, process or Ray node
draws them, in any order, and a resumed run draws them again identically.
"""

from __future__ import annotations

import warnings

import numpy as np

from mjcodesign.design.stiffness import LOG_E_MAX, LOG_E_MIN, N_LOG_E

__all__ = ["PoseStreams", "object_pose_seed", "sample_designs"]


def object_pose_seed(seed: int, object_index: int) -> int:
    """The pose sampler's integer seed for object ``object_index`` of a dataset seeded ``seed``."""
    ss = np.random.SeedSequence(seed, spawn_key=(object_index,))
    return int(ss.generate_state(1, np.uint32)[0])


class PoseStreams:
    """Independent generators of one (object, pose): ``density``, ``designs``, ``cloud``, ``perturbations``.

    A new instance draws the same numbers again. ``perturbations`` (the fourth child) feeds the draws
    every design of the pose shares; the first three children are those of a pose before it existed.
    ``replicate`` r >= 1 replaces ``perturbations`` by an independent stream of the same pose (a
    test-retest of its labels: the same cells under fresh draws); 0, the dataset's own.
    """

    def __init__(self, seed: int, object_index: int, pose_index: int, replicate: int = 0):
        ss = np.random.SeedSequence(seed, spawn_key=(object_index, pose_index))
        density, designs, cloud, perturbations = ss.spawn(4)
        if replicate:  # the r-th child of the draws' stream: independent of it and of each other
            perturbations = perturbations.spawn(replicate)[-1]
        self.density = np.random.default_rng(density)
        self.designs = np.random.default_rng(designs)
        self.cloud = np.random.default_rng(cloud)
        self.perturbations = np.random.default_rng(perturbations)


def sample_designs(rng: np.random.Generator, n: int, sampler: str = "uniform") -> np.ndarray:
    """``n`` designs of ln(E / Pa), each block in [LOG_E_MIN, LOG_E_MAX], shape (n, 22).

    ``uniform``: i.i.d. per block, as in the paper. ``sobol``: a scrambled Sobol sequence (scipy.stats.qmc)
    seeded from ``rng``; its balance holds best when ``n`` is a power of two (scipy's warning about
    other ``n`` is silenced; the points are valid either way).
    """
    if sampler == "uniform":
        u = rng.random((n, N_LOG_E))
    elif sampler == "sobol":
        from scipy.stats import qmc

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "balance properties ... power of 2"
            u = qmc.Sobol(d=N_LOG_E, scramble=True, seed=rng).random(n)
    else:
        raise ValueError(f"unknown sampler {sampler!r}")
    return LOG_E_MIN + (LOG_E_MAX - LOG_E_MIN) * u
