"""Cross-evaluation tables of the grounding study: the paper's Table 3 and Fig. 8 analogues.

Input is per-episode records keyed `(eval env, seed, trained-in env, phase)` (`grounding_study.cells`).

* Table 3: every policy (untrained; BC and BC+RL trained in each environment) evaluated in the GROUNDED
  environment on its test split, with paired differences vs the grounded-trained BC+RL policy and vs
  the untrained one (same episodes and seeds: `report.seed_table`).
* Fig. 8: the same fixed, grounded-trained policies evaluated in every environment, each on its own
  test split. Does a degraded environment change SR / IR and the ranking? Ranking agreement is
  Kendall's tau-b between the policies' scores in the grounded and in the degraded environment, with a
  percentile-bootstrap interval over episodes (each environment's episodes resampled on their own,
  paired across the policies inside it). With three policies tau takes few values (+-1, +-1/3 without
  ties), so the interval is coarse; undefined resamples (all policies tied) are counted, not dropped silently.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import torch

from wanderland_nav.evaluation.tables import FIELDS, estimate, seed_table
from wanderland_nav.evaluation.stats import Estimate

GROUNDED = "grounded"


def policy_label(env: str, phase: str) -> str:
    return "untrained" if phase == "untrained" else f"{env} {phase}"


def kendall_tau_b(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Kendall's tau-b of `x` and `y` (`[..., P]` scores of the same P items) -> `[...]`; NaN where
    either side is all tied (tau is undefined there)."""
    i, j = torch.triu_indices(x.shape[-1], x.shape[-1], offset=1)
    dx = torch.sign(x[..., i] - x[..., j])  # [..., pairs]
    dy = torch.sign(y[..., i] - y[..., j])
    n0 = float(len(i))
    denom = ((n0 - (dx == 0).sum(-1)) * (n0 - (dy == 0).sum(-1))).double().sqrt()
    s = (dx * dy).sum(-1).double()
    return torch.where(denom > 0, s / denom.clamp_min(1e-12), torch.full_like(s, float("nan")))


def _resampled_policy_means(scores: torch.Tensor, resamples: int, gen: torch.Generator) -> torch.Tensor:
    """`[P, S, N]` scores -> `[R, P]` means over seeds and N episodes drawn with replacement (same draw
    for every policy and seed: the episodes are shared)."""
    n = scores.shape[-1]
    idx = torch.randint(n, (resamples, n), generator=gen)  # [R, N]
    return scores[:, :, idx].mean(dim=(1, 3)).T  # [P, S, R, N] -> [R, P]


def rank_agreement(ref: torch.Tensor, other: torch.Tensor, *, resamples: int = 1000, seed: int = 0) -> dict:
    """Kendall tau-b between policy means of `ref` `[P, S, N_ref]` and `other` `[P, S, N_other]` (same P
    policies, same order) with a 95 % bootstrap interval over episodes of both environments."""
    gen = torch.Generator().manual_seed(seed)
    point = float(kendall_tau_b(ref.mean(dim=(1, 2)), other.mean(dim=(1, 2))))
    taus = kendall_tau_b(_resampled_policy_means(ref, resamples, gen), _resampled_policy_means(other, resamples, gen))
    ok = taus[torch.isfinite(taus)]
    lo, hi = (float(torch.quantile(ok, 0.025)), float(torch.quantile(ok, 0.975))) if len(ok) else (math.nan,) * 2
    return {"tau": point, "low": lo, "high": hi, "undefined": int(resamples - len(ok)), "resamples": resamples}


def unpaired_difference(a: torch.Tensor, b: torch.Tensor, *, resamples: int = 1000, seed: int = 0) -> Estimate:
    """mean(a) - mean(b) for `[S, N_a]` and `[S, N_b]` scores on DIFFERENT episodes (two environments'
    own test splits), with a percentile-bootstrap interval resampling each side's episodes on its own."""
    gen = torch.Generator().manual_seed(seed)
    ia = torch.randint(a.shape[-1], (resamples, a.shape[-1]), generator=gen)
    ib = torch.randint(b.shape[-1], (resamples, b.shape[-1]), generator=gen)
    d = a[:, ia].mean(dim=(0, 2)) - b[:, ib].mean(dim=(0, 2))  # [R]
    lo, hi = torch.quantile(d, torch.tensor([0.025, 0.975], dtype=d.dtype)).tolist()
    return Estimate(float(a.mean() - b.mean()), lo, hi, a.shape[-1] + b.shape[-1], a.shape[0])


def _runs(records: Mapping[tuple, list[dict]], env: str, policy: tuple[str, str], seeds: Sequence[int]):
    return [records[(env, s, *policy)] for s in seeds if (env, s, *policy) in records]


def table3(records: Mapping[tuple, list[dict]], envs: Sequence[str], seeds: Sequence[int]) -> str:
    """Every policy in the grounded env's test split; paired deltas vs the grounded-trained policy (BC+RL,
    else BC) and vs untrained, and each world's RL gain (`<env> BC+RL - <env> BC`).
    Rows appear for the (env, phase) pairs that were evaluated, on the seeds that have every such row
    (whole seeds, so every difference is paired); the seeds left out are named."""
    policies = [(GROUNDED, "untrained")] + [(e, ph) for e in envs for ph in ("BC", "BC+RL")]
    present = [p for p in policies if _runs(records, GROUNDED, p, seeds)]
    whole = [sd for sd in seeds if all((GROUNDED, sd, *p) in records for p in present)]
    runs = {policy_label(*p): r for p in present if (r := _runs(records, GROUNDED, p, whole))}
    if not runs:
        return ("Table 3: no policy was evaluated in the grounded environment yet" if not present else
                f"Table 3: no seed of {list(seeds)} has every row ({[policy_label(*p) for p in present]}) yet")
    parts = ["Table 3 analogue: trained in <env>, evaluated in the GROUNDED environment (its test split)"
             + (f"; seeds {whole} (every row done; seeds {[sd for sd in seeds if sd not in whole]} are not)"
                if len(whole) < len(seeds) else "")]
    trained = next((lab for ph in ("BC+RL", "BC") if (lab := policy_label(GROUNDED, ph)) in runs), None)
    rl_gain = [(f"{e} BC+RL", f"{e} BC") for e in envs if f"{e} BC+RL" in runs and f"{e} BC" in runs]
    for base in (trained, "untrained"):  # the grounded-trained policy (its last phase evaluated), the random init
        if base in runs and len(runs) > 1:
            parts += [f"-- paired differences vs {base}" + (", and each world's BC+RL - BC" if rl_gain else ""),
                      seed_table(runs, baseline=base, pairs=rl_gain)]
            rl_gain = []  # once
    if len(parts) == 1:
        parts.append(seed_table(runs))
    return "\n".join(parts)


def scores_of(runs: list[list[dict]], column: str) -> torch.Tensor:
    """S seeds of N records -> `[S, N]` float scores of `column`."""
    f = FIELDS.get(column, column)
    return torch.tensor([[float(r[f]) for r in rec] for rec in runs], dtype=torch.float64)


def ranking_text(labels: Sequence[str], means: torch.Tensor) -> str:
    """`a > b = c`: best first, equal means joined by `=` (a tie is not an order)."""
    idx = torch.argsort(means, descending=True, stable=True).tolist()
    out = labels[idx[0]]
    for prev, i in zip(idx, idx[1:]):
        out += (" = " if means[i] == means[prev] else " > ") + labels[i]
    return out


def _change_lines(records, envs: Sequence[str], fixed: Sequence[str], seeds: Sequence[int], resamples: int) -> list[str]:
    """SR and IR of each fixed policy in each degraded env minus in the grounded env (unpaired: each env
    has its own episodes), with bootstrap intervals."""
    lines = []
    for col in ("SR", "IR"):
        for env in envs[1:]:
            cells = []
            for ph in fixed:
                r, g = _runs(records, env, (GROUNDED, ph), seeds), _runs(records, GROUNDED, (GROUNDED, ph), seeds)
                if r and g and len(r) == len(g):
                    e = unpaired_difference(scores_of(r, col), scores_of(g, col), resamples=resamples)
                    cells.append(f"{policy_label(GROUNDED, ph)} {e.value:+.3f} [{e.low:+.3f}, {e.high:+.3f}]")
            if cells:
                lines.append(f"{col} in {env} - in grounded (own episodes each, bootstrap): " + "; ".join(cells))
    return lines


def fig8(records: Mapping[tuple, list[dict]], envs: Sequence[str], fixed: Sequence[str], seeds: Sequence[int], *,
         metric: str = "SR", resamples: int = 1000) -> tuple[str, dict]:
    """-> (text, chart data {column: {env: {policy: Estimate}}}) for the fixed grounded-trained policies."""
    labels = [policy_label(GROUNDED, ph) for ph in fixed]
    chart: dict[str, dict[str, dict[str, Estimate]]] = {"SR": {}, "IR": {}}
    scores: dict[str, torch.Tensor] = {}
    lines = [f"Fig. 8 analogue: fixed grounded-trained policies evaluated in each environment (its own test split)"]
    for env in envs:
        runs = {lab: r for lab, ph in zip(labels, fixed) if (r := _runs(records, env, (GROUNDED, ph), seeds))}
        if not runs:
            lines.append(f"-- {env}: no evaluation finished")
            continue
        lines += [f"-- in {env}", seed_table(runs)]
        for col in chart:
            chart[col][env] = {lab: estimate(r, col) for lab, r in runs.items()}
        if len(runs) == len(labels) and len({len(r) for r in runs.values()}) == 1:
            scores[env] = torch.stack([scores_of(runs[lab], metric) for lab in labels])  # [P, S, N]
    lines.append("-- change of SR / IR when the same policy is evaluated in the degraded environment")
    lines += _change_lines(records, envs, fixed, seeds, resamples)
    lines.append(f"-- ranking by {metric} (best first) and agreement with the grounded ranking "
                 f"(Kendall tau-b, 95 % bootstrap over episodes, {resamples} resamples)")
    for env, sc in scores.items():
        means = sc.mean(dim=(1, 2))
        order = ranking_text(labels, means)
        row = f"{env:>12}: {order}  ({metric} {', '.join(f'{lab} {m:.2f}' for lab, m in zip(labels, means.tolist()))})"
        if env != GROUNDED and GROUNDED in scores:
            a = rank_agreement(scores[GROUNDED], sc, resamples=resamples)
            row += (f"  tau {a['tau']:+.2f} [{a['low']:+.2f}, {a['high']:+.2f}]"
                    + (f", undefined (all tied) in {a['undefined']}/{resamples}" if a["undefined"] else ""))
        lines.append(row)
    return "\n".join(lines), chart
