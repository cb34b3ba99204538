"""Interval estimates with known answers: Wilson by hand, bootstrap coverage, paired shifts, IQM, seeds."""

from __future__ import annotations

import pytest
import torch

from wanderland_nav.evaluation.stats import (bootstrap_interval, interquartile_mean, normal_quantile, paired_difference,
                                  rate_interval, seed_aggregate, wilson_interval)


def test_wilson_matches_hand_computation():
    # 8 / 10, z = 1.959964: centre (0.8 + z^2/20) / (1 + z^2/10) = 0.716740,
    # half-width z / (1 + z^2/10) * sqrt(0.016 + z^2/400) = 0.226577
    e = wilson_interval(8, 10)
    assert e.value == pytest.approx(0.8)
    assert (e.low, e.high) == pytest.approx((0.490163, 0.943317), abs=1e-5)
    zero = wilson_interval(0, 10)  # not degenerate at the boundary, unlike p +- z sqrt(p(1-p)/n)
    assert zero.low == 0.0 and zero.high == pytest.approx(0.277533, abs=1e-5)
    assert normal_quantile(0.95) == pytest.approx(1.959964, abs=1e-6)
    with pytest.raises(ValueError, match="11/10"):
        wilson_interval(11, 10)


def test_bootstrap_interval_covers_the_true_mean_at_about_the_nominal_rate():
    g = torch.Generator().manual_seed(0)
    samples = torch.randn(200, 60, generator=g, dtype=torch.float64) + 3.0  # 200 data sets, true mean 3
    hits = sum(e.low <= 3.0 <= e.high for e in (bootstrap_interval(s, seed=i, num_resamples=1000)
                                                 for i, s in enumerate(samples)))
    assert 0.89 <= hits / 200 <= 0.99
    e = bootstrap_interval(samples[0])
    assert e.n == 60 and e.low < e.value < e.high and e.value == pytest.approx(float(samples[0].mean()))
    assert bootstrap_interval(samples[0], seed=5) == bootstrap_interval(samples[0], seed=5)  # seeded
    with pytest.raises(ValueError, match="non-finite"):
        bootstrap_interval([1.0, float("nan")])


def test_paired_difference_excludes_zero_for_a_constant_shift_unpaired_does_not():
    g = torch.Generator().manual_seed(1)
    base = torch.rand(50, generator=g, dtype=torch.float64) * 20  # widely varying episode difficulty
    new = base - 0.5                                               # every episode 0.5 m better
    d = paired_difference(new, base)
    assert d.value == pytest.approx(-0.5) and d.low == pytest.approx(-0.5) and d.high == pytest.approx(-0.5)
    assert d.excludes_zero()
    # the two separate intervals overlap heavily: only pairing shows the shift
    a, b = bootstrap_interval(new), bootstrap_interval(base)
    assert a.high > b.low
    with pytest.raises(ValueError, match="same episodes"):
        paired_difference(new[:10], base)


def test_iqm_and_seed_aggregate():
    x = torch.tensor([[1.0, 2.0, 3.0, 100.0], [4.0, 5.0, 6.0, 7.0]], dtype=torch.float64)
    # 8 scores sorted 1..7, 100: drop 2 at each end -> mean(3, 4, 5, 6) = 4.5 (scipy.stats.trim_mean(., 0.25))
    agg = seed_aggregate(x)
    assert agg["iqm"].value == pytest.approx(4.5) and agg["mean"].value == pytest.approx(128 / 8)
    assert agg["mean"].seeds == 2 and agg["mean"].n == 4 and agg["mean"].low < agg["mean"].high
    assert float(interquartile_mean(torch.arange(8.0))) == pytest.approx(3.5)
    single = rate_interval([1, 0, 1, 1])
    assert single == wilson_interval(3, 4)
    multi = rate_interval([[1, 1, 1, 1], [0, 0, 0, 0]])  # seeds disagree completely: the interval shows it
    assert multi.value == 0.5 and multi.low == 0.0 and multi.high == 1.0


def test_rate_interval_over_seeds_is_never_narrower_than_wilson_on_the_pooled_outcomes():
    # 3 seeds x 1 route, all successes: the bootstrap alone gives the zero-width [1, 1]
    est = rate_interval([[1], [1], [1]])
    pooled = wilson_interval(3, 3)
    assert est.value == 1.0 and est.high == 1.0
    assert est.low == pytest.approx(pooled.low) and est.low < 0.5
    assert (est.n, est.seeds) == (1, 3)
