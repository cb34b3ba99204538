"""The study's RL half again with another PPO recipe, from the study's OWN BC checkpoints (BC is not re-run).

    python experiments/geometry_grounding/ppo_rerun.py --ppo-out <ppo out> -- +study=grounding \
        out=<study out> source.path=<source scene> threads=1

Why a script and not study cells: the study's `train` cell is BC then PPO in one run; when only PPO's
recipe changes (here `algo.ppo.action_dist=tracked`, now the default), re-running
BC would cost ~3x the PPO time and change the BC policies the comparison is paired against. So for each
seed and each environment the study trained in, this runs `train` (library call, the study's composed
recipe under the CURRENT code and config) with `init_checkpoint=<the study's train cell>/checkpoints/bc.pt`
(which switches BC off), into `<ppo-out>/train/<env>_seed<s>`, then evaluates its last checkpoint in the
GROUNDED environment on the same 60 test episodes and seed as the study's Table-3 cells
(`<ppo-out>/eval/<env>_seed<s>.json`). Both steps resume. It prints the Table-3 analogue: per
environment BC (the study's cell), BC+RL with the study's old PPO (its cell) and with the new PPO, paired
over the same episodes and seeds, and the new BC+RL of each world against the new grounded BC+RL.

With `--routes-in drift scale_1.2 ...` the new BC+RL policies are also evaluated on the grounded test routes
mapped into those degraded worlds (the study's Fig.-8 protocol) and `misranking.txt` holds the study's
misranking test with them (`<env> BC+RL tracked`): in place of the old PPO's BC+RL, and beside them.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

import torch

from wanderland_nav.atomic import atomic_write_json, atomic_write_text
from wanderland_nav.compose.cli import compose_config
from wanderland_nav.compose.schema import study_config
from wanderland_nav.grounding_study.cells import StudyCells
from wanderland_nav.cache import Ledger
from wanderland_nav.grounding_study.plan import GROUNDED, MANIFEST, plan_cells
from wanderland_nav.evaluation.tables import seed_table


TRACKED = "BC+RL tracked"  # the phase label of the new (tracked-target) PPO's policies in the misranking grid


def _train_and_eval(ex: StudyCells, env: str, seed: int, root: Path) -> Path:
    from wanderland_nav.train import run as train_run

    result = root / "eval" / f"{env}_seed{seed}.json"
    if result.is_file():
        return result
    bc = ex.cell_dir(f"train/{env}/seed{seed}") / "checkpoints" / "bc.pt"
    run_dir = root / "train" / f"{env}_seed{seed}"
    train_run(ex.train_config(env, seed, run_dir=run_dir, more=[f"init_checkpoint={bc}"]))
    scene, episodes, _ = ex.env_episodes(GROUNDED, seed)
    res = _evaluate(ex, run_dir / "checkpoints" / "last.pt", scene, episodes, ex.c.study.eval_episodes, seed)
    atomic_write_json(result, {"env": env, "seed": seed, "init_checkpoint": str(bc), "records": res.records,
                               "summary": res.summary})
    return result


def _evaluate(ex: StudyCells, ckpt: Path, scene, episodes: Path, n: int, seed: int):
    """One checkpoint on the first `n` episodes of the study's eval split (the study's eval cells' call)."""
    from wanderland_nav.compose.comparison import compare_checkpoints
    from wanderland_nav.compose.scene_sets import SceneWork

    s = ex.c.study
    _, results, _ = compare_checkpoints([ckpt], SceneWork.of(scene, episodes), split=s.eval_split,
                                        num_episodes=n, batch_size=min(s.eval_batch_size, n), device=ex.c.device,
                                        seed=seed)
    return next(iter(results.values()))


def _eval_routes(ex: StudyCells, env: str, seed: int, world: str, root: Path) -> Path:
    """The new-PPO BC+RL trained in `env` on the grounded test routes mapped into degraded `world`: the
    study's Fig.-8 protocol with the routes file its own cells use (`<ppo-out>/eval_routes/<world>/`)."""
    from wanderland_nav.grounding_study.routes import grounded_routes_file

    result = root / "eval_routes" / world / f"{env}_seed{seed}.json"
    if result.is_file():
        return result
    s = ex.c.study
    scene = ex.env_episodes(world, seed)[0]
    episodes, routes = grounded_routes_file(ex.env_episodes(GROUNDED, seed)[1], s.eval_split, s.eval_episodes, scene,
                                            ex.out / "routes")
    ckpt = root / "train" / f"{env}_seed{seed}" / "checkpoints" / "last.pt"
    records = _evaluate(ex, ckpt, scene, episodes, routes["kept"], seed).records if routes["kept"] else []
    atomic_write_json(result, {"env": env, "seed": seed, "world": world, "checkpoint": str(ckpt), "records": records,
                               "routes": {k: v for k, v in routes.items() if k != "dropped_ids"}})
    return result


def misranking(ex: StudyCells, manifest: Ledger, envs: list[str], worlds: list[str], seeds: list[int],
               root: Path) -> str:
    """The study's misranking test (same routes, Kendall tau-b per seed and mean of seeds) with the new-PPO
    policies (`<env> BC+RL tracked`): once in place of the old PPO's BC+RL, once beside them."""
    from wanderland_nav.grounding_study.cells import eval_records
    from wanderland_nav.degrade.crosseval_routes import fig8_same_routes

    s = ex.c.study
    seeds = [sd for sd in seeds if all((root / "eval_routes" / w / f"{env}_seed{sd}.json").is_file()
                                       for w in worlds for env in envs)]  # whole seeds only
    if not seeds:
        return "no seed has every new-PPO evaluation on the mapped routes yet"
    cells = list(ex.cells.values())
    records = dict(eval_records(manifest, cells, ex.digests)["grounded_routes"])
    for env in envs:
        for seed in seeds:
            for world in [GROUNDED, *worlds]:
                p = root / ("eval" if world == GROUNDED else f"eval_routes/{world}") / f"{env}_seed{seed}.json"
                if p.is_file():
                    records[world, seed, env, TRACKED] = json.loads(p.read_text())["records"]
    routes = {c.env: manifest.entry(c.key, ex.digests[c.key])["info"]["routes"] for c in cells
              if c.protocol == "grounded_routes" and manifest.status(c.key, ex.digests[c.key]) == "done"}
    fixed = [(GROUNDED, ph) for ph in s.fixed_policies]
    old = [(e, "BC+RL") for e in envs[1:]]
    new = [(e, TRACKED) for e in envs]
    out = []
    for title, pols in (("the old PPO's BC+RL policies REPLACED by the tracked PPO's",
                         [p for p in fixed if p[1] != "BC+RL"] + new),
                        ("both PPOs' BC+RL policies", fixed + old + new)):
        text, _, _ = fig8_same_routes(records, [GROUNDED, *worlds], pols, seeds, routes, metric=s.rank_metric,
                                      resamples=s.bootstrap_resamples)
        out.append(f"[misranking test with {title}; {len(pols)} policies, seeds {seeds}]\n{text}")
    return "\n\n".join(out)


def _records(ex: StudyCells, manifest: Ledger, key: str):
    """The records of the study's eval cell `key` made with this study config's hash (another config's
    evaluation under the same key, e.g. `grounding_recipe`'s BC+RL, is not this one's)."""
    e = manifest.entry(key, ex.digests[key])
    return None if e is None or e["status"] != "done" else json.loads((Path(e["dir"]) / "result.json").read_text())["records"]


def tables(ex: StudyCells, manifest: Ledger, envs: list[str], seeds: list[int], root: Path) -> str:
    new = {(env, s): json.loads(p.read_text())["records"] for env in envs for s in seeds
           if (p := root / "eval" / f"{env}_seed{s}.json").is_file()}
    done = [s for s in seeds if all((env, s) in new for env in envs)]
    if not done:
        return "no seed has every environment's new-PPO evaluation yet"
    out = [f"seeds with every environment done: {done}; evaluated in the GROUNDED world, test split"]
    for env in envs:
        runs = {"BC": [_records(ex, manifest, f"eval/{GROUNDED}/seed{s}/{env}:BC") for s in done],
                "BC+RL old PPO": [_records(ex, manifest, f"eval/{GROUNDED}/seed{s}/{env}:BC+RL") for s in done],
                "BC+RL new PPO": [new[env, s] for s in done]}
        out += [f"-- trained in {env}", seed_table(runs, baseline="BC", pairs=[("BC+RL new PPO", "BC+RL old PPO")])]
    cross = {f"{env} BC+RL new PPO": [new[env, s] for s in done] for env in envs}
    out += ["-- Table 3 with the new PPO: BC+RL trained in <env> vs trained in grounded (paired)",
            seed_table(cross, baseline=f"{GROUNDED} BC+RL new PPO")]
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ppo-out", type=Path, required=True)
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--routes-in", nargs="*", default=[], metavar="WORLD",
                    help="degraded worlds whose mapped grounded routes the new-PPO policies are evaluated on, for "
                         "the misranking test (misranking.txt)")
    args, overrides = ap.parse_known_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stdout)
    c = study_config(compose_config("study", [o for o in overrides if o != "--"]))
    if c.threads:
        torch.set_num_threads(c.threads)
    ex = StudyCells(c, Path(c.out), None, plan_cells(c.study))
    manifest = Ledger(Path(c.out) / MANIFEST)
    envs = [GROUNDED, *(p for p in c.study.presets if c.study.trained_presets is None or p in c.study.trained_presets)]
    for seed in ([] if args.report_only else c.study.seeds):  # whole seeds first: a run cut short has whole rows
        for env in envs:
            _train_and_eval(ex, env, seed, args.ppo_out)
    text = tables(ex, manifest, envs, list(c.study.seeds), args.ppo_out)
    atomic_write_text(args.ppo_out / "table.txt", text + "\n")
    print(text)
    if args.routes_in:
        for seed in ([] if args.report_only else c.study.seeds):
            for world in args.routes_in:
                for env in envs:
                    _eval_routes(ex, env, seed, world, args.ppo_out)
        text = misranking(ex, manifest, envs, args.routes_in, list(c.study.seeds), args.ppo_out)
        atomic_write_text(args.ppo_out / "misranking.txt", text + "\n")
        print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
