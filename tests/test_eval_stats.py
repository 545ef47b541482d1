"""The evaluation's statistics: Wilson intervals, bootstrap over objects, the paired test's size and power."""

import numpy as np
import pytest

from mjcodesign.errors import DesignError
from mjcodesign.evaluation.stats import bootstrap_mean, mean_interval, paired_difference, wilson

_REPEATS = 400  # simulated experiments per rate check: a rate's standard error is then <= 0.025
_RATE_TOL = 3 * 0.5 / np.sqrt(_REPEATS)  # three standard errors of a rate near 0.5 (0.075)


def test_wilson_matches_the_closed_form():
    # 8 of 10 at 95 %: Wilson (1927) score interval [0.4902, 0.9433] (z = 1.95996)
    iv = wilson(8, 10)
    assert iv.value == 0.8
    assert iv.low == pytest.approx(0.4902, abs=1e-4) and iv.high == pytest.approx(0.9433, abs=1e-4)
    assert wilson(0, 8).low == 0.0 and wilson(8, 8).high == 1.0
    assert wilson(0, 0).low == 0.0 and wilson(0, 0).high == 1.0
    with pytest.raises(DesignError):
        wilson(3, 2)


def test_mean_interval_is_student_t():
    v = [1.0, 2.0, 3.0, 4.0]
    iv = mean_interval(v)
    # t_{0.975, 3} = 3.1824; sd = 1.2910; half = t sd / sqrt(4)
    assert iv.value == 2.5 and iv.half_width == pytest.approx(3.1824 * 1.2910 / 2, rel=1e-3)


def test_bootstrap_interval_covers_the_mean_at_its_level():
    rng = np.random.default_rng(0)
    hits = 0
    for i in range(_REPEATS):
        v = rng.uniform(0, 1, size=46)
        iv = bootstrap_mean(v, seed=i, n_boot=1000)
        hits += iv.low <= 0.5 <= iv.high
    # A percentile bootstrap of a mean of 46 is slightly narrow: coverage a little under 0.95.
    assert abs(hits / _REPEATS - 0.95) < _RATE_TOL


def test_planted_failure_is_found_at_its_size():
    """Design a fails a fixed subset of objects that design b holds: the difference is that subset's share."""
    rng = np.random.default_rng(1)
    b = rng.uniform(0.3, 1.0, size=46)
    a = b.copy()
    a[:9] = 0.0  # fails 9 objects
    res = paired_difference(a, b, names=("a", "b"))
    planted = -b[:9].sum() / 46
    assert res.difference.value == pytest.approx(planted)
    assert res.difference.low <= planted <= res.difference.high
    assert res.p_value < 0.05 and res.losses == 9 and res.wins == 0


def _binomial_pair(rng, p_true, n_rollouts, shift=0.0):
    a = rng.binomial(n_rollouts, np.clip(p_true + shift, 0, 1)) / n_rollouts
    b = rng.binomial(n_rollouts, p_true) / n_rollouts
    return a, b


def test_false_positive_rate_near_the_level():
    """The same design twice under independent draws: H0 true; rejections ~5 %."""
    rng = np.random.default_rng(2)
    rejected = 0
    for i in range(_REPEATS):
        p_true = rng.beta(0.5, 0.5, size=46)  # most objects always or never held, as measured
        a, b = _binomial_pair(rng, p_true, 80)
        rejected += paired_difference(a, b, seed=i, n_boot=200, n_flips=2000).p_value < 0.05
    assert abs(rejected / _REPEATS - 0.05) < 0.03


def test_power_at_the_detectable_difference_is_80_percent():
    rng = np.random.default_rng(3)
    sigma, n = 0.2, 46
    delta = paired_difference(rng.normal(0, sigma, n), np.zeros(n), n_boot=200).detectable
    # detectable = (z_0.975 + z_0.8) sigma_hat / sqrt(n) ~ 2.8016 * 0.2 / 6.78 = 0.0826
    assert delta == pytest.approx(2.8016 * sigma / np.sqrt(n), rel=0.25)
    delta = 2.8016 * sigma / np.sqrt(n)
    rejected = 0
    for i in range(_REPEATS):
        d = rng.normal(delta, sigma, n)
        rejected += paired_difference(d, np.zeros(n), seed=i, n_boot=200, n_flips=2000).p_value < 0.05
    assert abs(rejected / _REPEATS - 0.8) < _RATE_TOL


def test_exact_permutation_p_value_for_few_objects():
    # 5 objects all positive: only the all-positive and all-negative sign patterns reach |mean| -> 2/32.
    res = paired_difference([1, 1, 1, 1, 1.0], [0, 0, 0, 0, 0.0])
    assert res.p_value == pytest.approx(2 / 32)


def test_bad_samples_are_refused():
    with pytest.raises(DesignError):
        paired_difference([1.0, 2.0], [1.0])
    with pytest.raises(DesignError):
        bootstrap_mean([np.nan])


def test_cluster_bootstrap_resamples_clusters_and_refuses_bad_input():
    import numpy as np

    from mjcodesign.evaluation.stats import cluster_bootstrap_mean

    # cluster a: 9 values at +1, cluster b: one at -1. The pooled mean is 0.8; a resample of b alone
    # gives -1, of a alone +1: the interval spans both, as a pose-level bootstrap's would not.
    v = np.array([1.0] * 9 + [-1.0])
    iv = cluster_bootstrap_mean(v, np.array(["a"] * 9 + ["b"]), np.random.default_rng(0))
    assert iv.value == pytest.approx(0.8) and iv.low == pytest.approx(-1.0) and iv.high == pytest.approx(1.0)
    for values, clusters in (([], []), ([1.0, np.nan], ["a", "b"]), ([1.0, 2.0], ["a"])):
        with pytest.raises(DesignError):
            cluster_bootstrap_mean(np.array(values), np.array(clusters), np.random.default_rng(0))
