"""The Fig.-8 analogue on the SAME routes in both worlds (the paper's protocol).

Input: per-episode records keyed `(eval env, seed, trained-in env, phase)` where every degraded env
was evaluated on the grounded test routes mapped into its frame (`grounding_study/routes.py`; mapped
episodes keep the grounded `episode_id`, dropped routes are absent). The grounded records are cut to
the routes a degraded env kept, in its order, so every comparison is PAIRED over the same routes and
seeds: the change of SR / IR per policy is a paired bootstrap difference, and Kendall's tau-b between
the policies' grounded and degraded scores resamples the same routes on both sides. Each policy is
named `<trained-in env> <phase>`: the grounded-trained ones and those trained in degraded worlds, so
the ranking has as many items as policies were evaluated everywhere.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import torch

from wanderland_nav.evaluation.tables import estimate
from wanderland_nav.evaluation.stats import Estimate, paired_difference

from .crosseval import GROUNDED, kendall_tau_b, policy_label, ranking_text, scores_of


def matched_runs(records: Mapping[tuple, list[dict]], env: str, policy: tuple[str, str], seeds: Sequence[int]):
    """(grounded runs cut to `env`'s routes, `env` runs) for `policy` over `seeds`, or None when a seed is
    missing on either side. Both are S lists of the same routes in the same order."""
    g = [records.get((GROUNDED, s, *policy)) for s in seeds]
    e = [records.get((env, s, *policy)) for s in seeds]
    if any(r is None for r in g + e) or not all(e):  # not evaluated, or no route survived the mapping
        return None
    cut = []
    for gr, er in zip(g, e):
        by_id = {r["episode_id"]: r for r in gr}
        missing = [r["episode_id"] for r in er if r["episode_id"] not in by_id]
        if missing:
            raise KeyError(f"{env}: routes {missing[:5]} were not evaluated in {GROUNDED} (not the same route set)")
        cut.append([by_id[r["episode_id"]] for r in er])
    return cut, e


def _finite_interval(samples: torch.Tensor) -> tuple[float, float, int]:
    """95 % percentile interval of the finite bootstrap samples, and how many were undefined (NaN)."""
    ok = samples[torch.isfinite(samples)]
    lo, hi = (float(torch.quantile(ok, 0.025)), float(torch.quantile(ok, 0.975))) if len(ok) else (math.nan,) * 2
    return lo, hi, int(len(samples) - len(ok))


def paired_rank_agreement(ref: torch.Tensor, other: torch.Tensor, *, resamples: int = 1000, seed: int = 0) -> dict:
    """Kendall tau-b between the policies' scores in `ref` and `other` (`[P, S, N]`: the SAME N routes and
    S seeds), per seed and as the mean of the per-seed taus.

    Why per seed: seed s's P policies are one set of trained networks, i.e. the paper's experiment; the
    seeds replicate it. Per-seed intervals resample routes (jointly on both sides); the mean's interval
    resamples seeds AND routes (one route draw shared by every seed, since the routes are shared), so the
    seed-to-seed spread is in it; a single tau of seed-averaged scores would hide that spread. With S = 1
    both are the same number and interval. A resample where a drawn seed is all tied is undefined, counted."""
    if ref.shape != other.shape:
        raise ValueError(f"paired_rank_agreement: {tuple(ref.shape)} vs {tuple(other.shape)}: not the same routes")
    p, s, n = ref.shape
    gen = torch.Generator().manual_seed(seed)
    idx = torch.randint(n, (resamples, n), generator=gen)  # [R, N]
    per_seed = kendall_tau_b(ref.mean(-1).T, other.mean(-1).T)  # [S]
    boot = kendall_tau_b(ref[:, :, idx].mean(-1).permute(2, 1, 0), other[:, :, idx].mean(-1).permute(2, 1, 0))  # [R, S]
    means = boot.gather(1, torch.randint(s, (resamples, s), generator=gen)).mean(1)  # [R]: seeds drawn too
    lo, hi, undefined = _finite_interval(means)
    seeds = [dict(zip(("low", "high", "undefined"), _finite_interval(boot[:, k])), tau=float(per_seed[k]))
             for k in range(s)]
    return {"tau": float(per_seed.mean()), "low": lo, "high": hi, "undefined": undefined, "resamples": resamples,
            "policies": p, "per_seed": seeds}


def _fmt(e: Estimate) -> str:
    return f"{e.value:+.3f} [{e.low:+.3f}, {e.high:+.3f}]"


def _env_block(records, env: str, policies, seeds, metric: str, resamples: int) -> tuple[list[str], dict | None]:
    """Lines for one degraded env: per policy SR / IR in grounded vs here (paired), then tau."""
    lines, ref, other, labels, kept = [], [], [], [], []
    for pol in policies:
        m = matched_runs(records, env, pol, seeds)
        if m is None:
            continue
        g, e = m
        lab = policy_label(*pol)
        sr = paired_difference(scores_of(e, "SR"), scores_of(g, "SR"), num_resamples=resamples)
        ir = paired_difference(scores_of(e, "IR"), scores_of(g, "IR"), num_resamples=resamples)
        lines.append(f"   {lab:>22}: SR {estimate(g, 'SR').value:.3f} -> {estimate(e, 'SR').value:.3f} ({_fmt(sr)}), "
                     f"IR {estimate(g, 'IR').value:.3f} -> {estimate(e, 'IR').value:.3f} ({_fmt(ir)})")
        ref.append(scores_of(g, metric))
        other.append(scores_of(e, metric))
        labels.append(lab)
        kept.append(pol)
    if len(labels) < 2:
        return lines, None
    a = paired_rank_agreement(torch.stack(ref), torch.stack(other), resamples=resamples)
    lines.append(f"   ranking by {metric} in grounded: {ranking_text(labels, torch.stack(ref).mean(dim=(1, 2)))}")
    lines.append(f"   ranking by {metric} in {env}: {ranking_text(labels, torch.stack(other).mean(dim=(1, 2)))}")
    lines.append(f"   Kendall tau-b over {len(labels)} policies" + (f", mean of {len(seeds)} seeds' taus (bootstrap over "
                 "seeds and routes)" if len(seeds) > 1 else "") + f": {_tau_text(a, resamples)}")
    if len(seeds) > 1:
        lines.append("   per seed (bootstrap over routes): "
                     + "; ".join(f"seed {sd} {_tau_text(t, resamples)}" for sd, t in zip(seeds, a["per_seed"])))
    for i in (i for i, pol in enumerate(kept) if pol[0] == env):  # the policy trained in this world: does this world promote it (the paper's misranking)?
        g, e = (rank_of(torch.stack(x).mean(-1), i) for x in (ref, other))  # [S] ranks, 1 = best
        lines.append(f"   {labels[i]} (trained here), rank of {len(labels)} by {metric}, per seed: in grounded "
                     f"{g.tolist()} -> in {env} {e.tolist()}")
    return lines, a


def rank_of(scores: torch.Tensor, i: int) -> torch.Tensor:
    """Competition rank (1 = best; ties share the better rank) of item `i` in `scores` `[P, S]` -> `[S]`."""
    return 1 + (scores > scores[i]).sum(0)


def _tau_text(a: dict, resamples: int) -> str:
    tau = ("undefined (every policy tied on one side)" if math.isnan(a["tau"])
           else f"{a['tau']:+.2f} [{a['low']:+.2f}, {a['high']:+.2f}]")
    return tau + (f", undefined (all tied) in {a['undefined']}/{resamples} resamples" if a["undefined"] else "")


def _chart(records, envs, policies, seeds) -> dict[str, dict[str, dict[str, Estimate]]]:
    """SR / IR of the grounded-trained policies: in grounded on all its test routes, in each degraded
    env on the routes it kept (the bars of `fig8.png`)."""
    chart: dict[str, dict[str, dict[str, Estimate]]] = {"SR": {}, "IR": {}}
    for env in envs:
        for pol in (p for p in policies if p[0] == GROUNDED):
            runs = [records.get((env, s, *pol)) for s in seeds]
            if all(runs):  # evaluated, on at least one kept route
                for col in chart:
                    chart[col].setdefault(env, {})[policy_label(*pol)] = estimate(runs, col)
    return chart


def fig8_same_routes(records: Mapping[tuple, list[dict]], envs: Sequence[str], policies: Sequence[tuple[str, str]],
                     seeds: Sequence[int], routes: Mapping[str, dict], *, metric: str = "SR",
                     resamples: int = 1000) -> tuple[str, dict, dict]:
    """-> (text, chart {column: {env: {policy: Estimate}}}, tau {env: rank agreement}).
    `routes`: env -> {"asked", "kept", "dropped": {reason: n}} (the mapping's counts)."""
    lines = ["Fig. 8 analogue, SAME ROUTES: the grounded test routes mapped into each degraded environment "
             "(paired over routes and seeds; dropped routes counted)"]
    taus = {}
    for env in envs:
        if env == GROUNDED:
            continue
        r = routes.get(env)
        lines.append(f"-- in {env}" + (f": {r['kept']} of {r['asked']} grounded routes kept, dropped {r['dropped']}"
                                       if r else ""))
        block, a = _env_block(records, env, policies, seeds, metric, resamples)
        lines += block or ["   no policy evaluated on these routes in both worlds yet"]
        if a is not None:
            taus[env] = a
    return "\n".join(lines), _chart(records, envs, policies, seeds), taus
