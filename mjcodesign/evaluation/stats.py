"""Intervals and paired tests for success rates measured over objects.

The unit of every comparison is the object: poses and perturbed rollouts are nested in it, so a
design's rate over objects is the mean of its per-object success probabilities, and its interval comes
from resampling objects. Two designs are compared on the same objects, poses and perturbation draws
(common random numbers): the per-object differences carry the comparison.

- :func:`wilson`: the Wilson score interval of k successes in n trials (one object, one design);
- :func:`mean_interval`: mean and Student-t interval of a continuous outcome;
- :func:`bootstrap_mean`: mean over objects with a percentile bootstrap interval;
- :func:`paired_difference`: mean paired difference, bootstrap interval, sign-flip permutation p-value
  and the smallest difference the same number of objects detects at 80 % power.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from mjcodesign.errors import DesignError

__all__ = [
    "CONFIDENCE",
    "POWER",
    "Interval",
    "PairedDifference",
    "bootstrap_mean",
    "cluster_bootstrap_mean",
    "mean_interval",
    "paired_difference",
    "wilson",
]

CONFIDENCE = 0.95
"""Two-sided confidence of every interval, and 1 − the test's significance level."""
POWER = 0.8
"""Power at which :attr:`PairedDifference.detectable` is computed."""
N_BOOT = 4000
"""Bootstrap resamples: the percentile interval's ends move by < 0.5 points between seeds at 40+ objects."""
N_FLIPS = 20000
"""Random sign flips of the permutation test when exact enumeration (2^n) would be larger."""
_EXACT_FLIPS_MAX_N = 14  # 2^14 = 16384 sign patterns: enumerate them instead of sampling


def _z(q: float) -> float:
    from scipy.stats import norm

    return float(norm.ppf(q))


@dataclass(frozen=True)
class Interval:
    """A point estimate with its two-sided :data:`CONFIDENCE` interval, and the sample size behind it."""

    value: float
    low: float
    high: float
    n: int

    @property
    def half_width(self) -> float:
        """Half the interval's width."""
        return 0.5 * (self.high - self.low)

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def wilson(k: int, n: int, *, confidence: float = CONFIDENCE) -> Interval:
    """Success probability ``k / n`` with the Wilson score interval.

    ``p̃ = (k + z²/2) / (n + z²)``, half-width ``z √(p̂(1 − p̂)/n + z²/4n²) / (1 + z²/n)``. With ``n = 0``
    nothing is known: value 0.5, interval [0, 1].
    """
    if n < 0 or k < 0 or k > n:
        raise DesignError(f"wilson: need 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return Interval(0.5, 0.0, 1.0, 0)
    z = _z(0.5 + confidence / 2)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return Interval(p, max(0.0, centre - half), min(1.0, centre + half), n)


def mean_interval(values, *, confidence: float = CONFIDENCE) -> Interval:
    """Mean of ``values`` with a Student-t interval (the mean itself for one value, width 0)."""
    from scipy.stats import t

    v = np.asarray(values, dtype=float)
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise DesignError("mean_interval: needs one or more finite values")
    m = float(v.mean())
    if v.size == 1:
        return Interval(m, m, m, 1)
    half = float(t.ppf(0.5 + confidence / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return Interval(m, m - half, m + half, int(v.size))


def bootstrap_mean(
    values, *, seed: int = 0, n_boot: int = N_BOOT, confidence: float = CONFIDENCE
) -> Interval:
    """Mean over objects of their ``values`` with a percentile bootstrap interval (objects resampled)."""
    v = np.asarray(values, dtype=float)
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise DesignError("bootstrap_mean: needs one or more finite values")
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, v.size, size=(n_boot, v.size))].mean(axis=1)
    alpha = 1 - confidence
    lo, hi = np.quantile(means, [alpha / 2, 1 - alpha / 2])
    return Interval(float(v.mean()), float(lo), float(hi), int(v.size))


def cluster_bootstrap_mean(
    values, clusters, rng: np.random.Generator, *, n_boot: int = 2000, confidence: float = CONFIDENCE
) -> Interval:
    """Mean of ``values`` with a percentile interval from resampling their ``clusters`` (e.g. poses by object).

    Each resample draws as many clusters as there are, with replacement (sorted cluster names, indices
    from ``rng.integers``), and pools their values; the interval is over the pooled means.
    """
    v = np.asarray(values, dtype=float)
    c = np.asarray(clusters)
    if v.size == 0 or v.shape != c.shape or not np.all(np.isfinite(v)):
        raise DesignError("cluster_bootstrap_mean: needs finite values, one cluster label each")
    by = [v[c == name] for name in np.unique(c)]
    means = [np.concatenate([by[i] for i in rng.integers(0, len(by), len(by))]).mean() for _ in range(n_boot)]
    a = round((1 - confidence) / 2, 12)  # 0.95 -> percentiles 2.5 and 97.5 exactly
    lo, hi = np.percentile(means, [100 * a, 100 * (1 - a)])
    return Interval(float(v.mean()), float(lo), float(hi), int(v.size))


@dataclass(frozen=True)
class PairedDifference:
    """Design ``a`` minus design ``b`` over the same objects."""

    a: str
    b: str
    difference: Interval
    """Mean of the per-object differences with its bootstrap interval."""
    p_value: float
    """Two-sided sign-flip permutation p-value of the mean difference (H0: no difference)."""
    detectable: float
    """Smallest true mean difference detected at :data:`POWER` with this many objects and this spread:
    ``(z_{1−α/2} + z_{power}) · sd(d) / √n``."""
    wins: int
    """Objects where ``a`` is higher."""
    losses: int
    """Objects where ``b`` is higher."""

    def as_dict(self) -> dict:
        """JSON-ready fields."""
        out = asdict(self)
        out["difference"] = self.difference.as_dict()
        return out


def paired_difference(
    a,
    b,
    *,
    names: tuple[str, str] = ("a", "b"),
    seed: int = 0,
    n_boot: int = N_BOOT,
    n_flips: int = N_FLIPS,
    confidence: float = CONFIDENCE,
    power: float = POWER,
) -> PairedDifference:
    """The paired comparison of per-object values ``a`` and ``b`` (same objects, same order)."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size == 0:
        raise DesignError(f"paired_difference: two equal-length 1-D samples, got {x.shape} and {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise DesignError("paired_difference: values must be finite")
    d = x - y
    n = d.size
    diff = bootstrap_mean(d, seed=seed, n_boot=n_boot, confidence=confidence)
    observed = abs(d.mean())
    if n <= _EXACT_FLIPS_MAX_N:
        signs = 1 - 2 * ((np.arange(2**n)[:, None] >> np.arange(n)[None, :]) & 1)
        p = float(np.mean(np.abs((signs * d).mean(axis=1)) >= observed - 1e-12))
    else:
        rng = np.random.default_rng([seed, 1])
        signs = rng.choice((-1.0, 1.0), size=(n_flips, n))
        hits = int(np.sum(np.abs((signs * d).mean(axis=1)) >= observed - 1e-12))
        p = (hits + 1) / (n_flips + 1)  # the observed pattern counts as one of the flips
    sd = float(d.std(ddof=1)) if n > 1 else 0.0
    detectable = (_z(0.5 + confidence / 2) + _z(power)) * sd / math.sqrt(n)
    return PairedDifference(
        names[0], names[1], diff, p, float(detectable), int(np.sum(d > 0)), int(np.sum(d < 0))
    )
