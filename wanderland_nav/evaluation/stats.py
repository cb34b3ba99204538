"""Interval estimates for evaluation tables: how sure is a number measured on N episodes and S seeds?

* `wilson_interval`: success rates (a binomial proportion); unlike the normal approximation it stays
  inside [0, 1] and is not degenerate at 0 / N or N / N successes (Wilson 1927; Brown, Cai, DasGupta 2001).
* `bootstrap_interval`: percentile bootstrap of the mean over episodes, for NE, SPL, IR, ...
* `paired_difference`: new - base over the SAME episodes, resampling episodes jointly, so the episode
  difficulty shared by both runs cancels (much tighter than comparing two independent intervals).
* `seed_aggregate`: several training seeds evaluated on the same episodes, `[S, N]` scores: mean and
  interval resampling seeds and episodes (two-level bootstrap), plus the interquartile mean (IQM) of
  the per-seed scores' pooled `[S, N]` matrix as rliable defines it (Agarwal et al. 2021: the mean of
  the middle 50 % of all run x task scores, robust to one outlier seed).

All bootstraps are seeded (`torch.Generator`) and vectorised: one gather of `[R, N]` indices, no
Python loop over resamples. Intervals are two-sided at `confidence` (0.95 by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

NUM_RESAMPLES = 2000


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its interval and the sample it came from (`n` episodes, `seeds` runs)."""

    value: float
    low: float
    high: float
    n: int
    seeds: int = 1

    def excludes_zero(self) -> bool:
        return self.low > 0 or self.high < 0

    def as_dict(self) -> dict:
        return {"value": self.value, "low": self.low, "high": self.high, "n": self.n, "seeds": self.seeds}


def normal_quantile(confidence: float) -> float:
    """Two-sided z for `confidence` (0.95 -> 1.95996...)."""
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    return math.sqrt(2.0) * float(torch.special.erfinv(torch.tensor(confidence, dtype=torch.float64)))


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> Estimate:
    """Wilson score interval of a success rate: `successes` of `n` trials."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"wilson_interval: need 0 <= successes <= n and n >= 1, got {successes}/{n}")
    z = normal_quantile(confidence)
    p, z2n = successes / n, z * z / n
    centre = (p + z2n / 2) / (1 + z2n)
    half = z / (1 + z2n) * math.sqrt(p * (1 - p) / n + z2n / (4 * n))
    return Estimate(p, max(0.0, centre - half), min(1.0, centre + half), n)


def _as_matrix(values) -> torch.Tensor:
    x = torch.as_tensor(values, dtype=torch.float64)
    if x.dim() == 1:
        x = x[None]
    if x.dim() != 2 or x.shape[-1] < 1:
        raise ValueError(f"expected [N] or [S, N] scores with N >= 1, got shape {tuple(x.shape)}")
    if not torch.isfinite(x).all():
        raise ValueError(f"{int((~torch.isfinite(x)).sum())} non-finite scores: drop or count them explicitly first")
    return x


def _percentiles(samples: torch.Tensor, confidence: float) -> tuple[float, float]:
    a = (1 - confidence) / 2
    q = torch.quantile(samples, torch.tensor([a, 1 - a], dtype=samples.dtype))
    return float(q[0]), float(q[1])


def _resampled_means(x: torch.Tensor, num_resamples: int, seed: int, statistic=None) -> torch.Tensor:
    """`[S, N]` -> `[R]` statistic of (seeds resampled, then episodes resampled) copies of x.

    With S = 1 only episodes are resampled. Episodes are resampled as whole columns, so paired
    scores (differences over the same episodes) keep their pairing.
    """
    s, n = x.shape
    g = torch.Generator().manual_seed(seed)
    rows = torch.randint(0, s, (num_resamples, s, 1), generator=g) if s > 1 else torch.zeros(num_resamples, 1, 1,
                                                                                               dtype=torch.long)
    cols = torch.randint(0, n, (num_resamples, 1, n), generator=g)
    boot = x[rows, cols]  # [R, S, N]
    return boot.flatten(1).mean(-1) if statistic is None else statistic(boot.flatten(1))


def bootstrap_interval(values, confidence: float = 0.95, *, num_resamples: int = NUM_RESAMPLES,
                       seed: int = 0) -> Estimate:
    """Mean of `[N]` (episodes) or `[S, N]` (seeds x the same episodes) with a percentile-bootstrap interval."""
    x = _as_matrix(values)
    lo, hi = _percentiles(_resampled_means(x, num_resamples, seed), confidence)
    return Estimate(float(x.mean()), lo, hi, x.shape[1], x.shape[0])


def paired_difference(new, base, confidence: float = 0.95, *, num_resamples: int = NUM_RESAMPLES,
                      seed: int = 0) -> Estimate:
    """Mean of `new - base` over the same episodes (`[N]` or `[S, N]`, same order) with its bootstrap interval."""
    a, b = _as_matrix(new), _as_matrix(base)
    if a.shape != b.shape:
        raise ValueError(f"paired_difference: new {tuple(a.shape)} and base {tuple(b.shape)} must be the same "
                         "episodes (and seeds) in the same order")
    return bootstrap_interval(a - b, confidence, num_resamples=num_resamples, seed=seed)


def interquartile_mean(x: torch.Tensor) -> torch.Tensor:
    """IQM over the last dim: mean of the scores between the 25th and 75th percentile (rliable's trimmed mean).

    As `scipy.stats.trim_mean(x, 0.25)`: drop floor(0.25 n) scores at each end after sorting.
    """
    n = x.shape[-1]
    cut = int(0.25 * n)
    return x.sort(-1).values[..., cut:n - cut].mean(-1)


def seed_aggregate(scores, confidence: float = 0.95, *, num_resamples: int = NUM_RESAMPLES,
                   seed: int = 0) -> dict[str, Estimate]:
    """`[S, N]` scores of S seeds on the same N episodes -> {"mean", "iqm"} with two-level bootstrap intervals."""
    x = _as_matrix(scores)
    out = {}
    for name, stat in (("mean", None), ("iqm", interquartile_mean)):
        lo, hi = _percentiles(_resampled_means(x, num_resamples, seed, stat), confidence)
        point = x.mean() if stat is None else stat(x.flatten())
        out[name] = Estimate(float(point), lo, hi, x.shape[1], x.shape[0])
    return out


def rate_interval(successes, confidence: float = 0.95, *, seed: int = 0) -> Estimate:
    """Success rate of `[N]` (Wilson) or `[S, N]` 0/1 outcomes (two-level bootstrap: seeds differ as runs).

    For `[S, N]` the interval is the envelope of the bootstrap's and Wilson's on the S*N pooled outcomes:
    a bootstrap cannot show uncertainty it never resamples (3 seeds x 1 route, all successes, gave the
    zero-width [1.0, 1.0]), while Wilson keeps the width that S*N coin flips must have.
    """
    x = _as_matrix(successes)
    if x.shape[0] == 1:
        return wilson_interval(int(x.sum()), x.shape[1], confidence)
    boot = bootstrap_interval(x, confidence, seed=seed)
    pooled = wilson_interval(int(x.sum()), x.numel(), confidence)
    return Estimate(boot.value, min(boot.low, pooled.low), max(boot.high, pooled.high), boot.n, boot.seeds)
