"""What each study cell does (`plan.Cell`): build a degraded scene, save the untrained policy,
run one `train` run, evaluate one checkpoint on one environment's test split.

Every environment is an ordinary scene folder: the grounded source, or a degraded copy written by
`wanderland_nav.degrade`. Each gets its OWN episodes, generated on its own navmesh with the same
`episodes.*` settings (so a broken navmesh yields fewer episodes, which the `train` cell records), and
every run and evaluation in an environment uses that environment's episodes file.
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path
from typing import Callable, Sequence

import torch
import yaml

from planners import NavMesh
from wanderland_nav.atomic import atomic_write_json
from wanderland_nav.cache import Ledger
from wanderland_nav.compose.build import make_policy_from_config
from wanderland_nav.compose.checkpoints import policy_card
from wanderland_nav.compose.cli import compose_config, resolved
from wanderland_nav.compose.comparison import compare_checkpoints
from wanderland_nav.compose.episode_file import episodes_for_run, split_counts
from wanderland_nav.compose.identity import dotted_diff, identity_config
from wanderland_nav.compose.scene import prepared_scene, scene_folder
from wanderland_nav.compose.scene_sets import SceneWork
from wanderland_nav.compose.schema import SceneGroup, TrainConfig, typed_config
from wanderland_nav.compose.study_config import BC_ROUND, PROTOCOLS, StudyConfig
from wanderland_nav.degrade import build_degraded_scene, preset
from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
from wanderland_nav.episodes.sampler import SamplerSettings
from wanderland_nav.grounding_study.plan import GROUNDED, Cell, cell_digests
from wanderland_nav.grounding_study.routes import grounded_routes_file
from wanderland_nav.rl.checkpoint import save_checkpoint

log = logging.getLogger("wanderland_nav.study")

#: phase -> checkpoint file inside the producing cell's folder (and `BC-round<k>`: `phase_checkpoint`)
CHECKPOINTS = {"untrained": "untrained.pt", "BC": "checkpoints/bc.pt", "BC+RL": "checkpoints/last.pt"}


def phase_checkpoint(phase: str) -> str:
    """The checkpoint of `phase` relative to its producing cell's folder (`rl/recipe.py` names them)."""
    k = BC_ROUND.fullmatch(phase)
    return f"checkpoints/bc_round{k.group(1)}.pt" if k else CHECKPOINTS[phase]


class StudyCells:
    """`execute(cell, folder) -> info` for `plan.run_cells`. `train_fn(cfg) -> rows` runs one
    composed `train` config (the `train` entry point's `run`), so a cell is exactly that command."""

    def __init__(self, c: StudyConfig, out: Path, train_fn: Callable, cells: list[Cell]):
        self.c, self.out, self.train_fn = c, Path(out), train_fn
        self.digests = cell_digests(c, cells)
        self.cells = {cell.key: cell for cell in cells}
        self._envs: dict[tuple[str, int], tuple] = {}
        self._study_episodes: dict[str, tuple[Path, int]] = {}  # env -> (study episodes file, episodes asked)

    # ------------------------------------------------------------------ where things are
    def source(self) -> Path:
        """The grounded scene's folder. The demo's is the one `train` prepares with the recipe's `navigation`
        (`compose.scene.scene_folder`: a non-default one, e.g. `debug=smoke`'s voxels, has its own folder), so
        the study's train cells never re-bake the main job's demo in place."""
        if getattr(self, "_source", None) is None:
            s = self.c.source
            navigation = (typed_config(compose_config("train", list(self.c.study.train)), TrainConfig).navigation
                          if s.demo else None)
            self._source = scene_folder(SceneGroup(name="source", path=s.path, demo=s.demo, seed=s.demo_seed,
                                                   preset=s.demo_preset, generator=s.generator, size=s.size),
                                        navigation=navigation).resolve()
        return self._source

    def env_path(self, env: str) -> Path:
        return self.source() if env == GROUNDED else (self.out / "scenes" / f"{env}_s{self.c.study.degrade_seed}")

    def cell_dir(self, key: str) -> Path:
        cell = self.cells[key]
        return self.out / "cells" / cell.kind / cell.folder_name(self.digests[key])

    def train_config(self, env: str, seed: int, run_dir: Path | None = None, more: Sequence[str] = (), *,
                     study_episodes: bool = True):
        """`train`'s composed config for `env`: the study's recipe overrides + scene, seed, folder (+ `more`),
        and `episodes.path` when `study.episode_sampler` makes the env's episodes (`study_episodes_file`)."""
        extra = [f"scene={self.env_path(env)}", f"seed={seed}", f"device={self.c.device}",
                 f"exp_name=study_{self.c.study.name}_{env}", "progress=false", *more]
        own = self.study_episodes_file(env) if study_episodes else None
        extra += [f"episodes.path={own}", "episodes.num=null"] if own is not None else []
        extra += [f"threads={self.c.threads}"] if self.c.threads else []
        extra += [f"run_dir={run_dir}"] if run_dir is not None else []
        return compose_config("train", [*self.c.study.train, *extra])

    def study_episodes_file(self, env: str) -> Path | None:
        """With `study.episode_sampler`: `env`'s episodes generated on its own navmesh with those sampler
        settings and the recipe's `episodes.num/seed/splits` (`episodes_study_<hash8>.json` in its folder;
        a rerun reuses it by the generator's args hash); None without (the recipe's own file, as before)."""
        overrides = dict(self.c.study.episode_sampler)
        if not overrides:
            return None
        if env not in self._study_episodes:
            t = typed_config(self.train_config(env, 0, study_episodes=False), TrainConfig)
            scene = prepared_scene(t.scene, t.navigation)
            settings = GeneratorSettings(sampler=SamplerSettings(**overrides), splits=tuple(t.episodes.splits),
                                         goal_images=t.episodes.goal_images)
            tag = hashlib.sha256(json.dumps([settings.to_dict(), t.episodes.num, t.episodes.seed],
                                            sort_keys=True).encode()).hexdigest()[:8]
            _, summary = write_scene_episodes(scene, NavMesh.load(scene.navmesh_path),
                                              scene.products / f"episodes_study_{tag}.json",
                                              num_episodes=t.episodes.num, seed=t.episodes.seed, settings=settings)
            log.info("%s episodes (study.episode_sampler %s): %s, %d kept %s", env, overrides, summary.out,
                     summary.kept, summary.splits)
            self._study_episodes[env] = (Path(summary.out), t.episodes.num)
        return self._study_episodes[env][0]

    def episodes_asked(self, env: str, recipe_num: int | None) -> int | None:
        """How many episodes `env`'s file was generated for: the recipe's `episodes.num`, or with
        `study.episode_sampler` the number its own file was asked for (the recipe then says null)."""
        return recipe_num if recipe_num is not None else self._study_episodes.get(env, (None, None))[1]

    def cell_train_config(self, cell: Cell, folder: Path):
        """The composed `train` config a train or ppo cell runs: the study's recipe, and for a ppo cell
        `study.ppo_stage` from its train cell's BC checkpoint (which switches `train`'s BC phase off)."""
        more = []
        if cell.kind == "ppo":
            bc = self.cell_dir(cell.needs[0]) / CHECKPOINTS["BC"]
            more = [*self.c.study.ppo_stage, f"init_checkpoint={bc}"]
        return self.train_config(cell.env, cell.seed, run_dir=folder, more=more)

    def env_episodes(self, env: str, seed: int):
        """(prepared scene, its episodes file, typed train config) exactly as `train` in `env` uses them.
        Kept per (env, seed) for the process: loading and checking a scene costs tens of seconds on a
        loaded box, and nothing else writes it while the study runs."""
        if (env, seed) not in self._envs:
            self._envs[env, seed] = self._load_env_episodes(env, seed)
        return self._envs[env, seed]

    def _load_env_episodes(self, env: str, seed: int):
        t = typed_config(self.train_config(env, seed), TrainConfig)
        scene = prepared_scene(t.scene, t.navigation)
        if t.episodes.path is not None:  # study.episode_sampler's file, used as it is (as `train` does)
            scene.episodes_path = Path(t.episodes.path)
            return scene, Path(t.episodes.path), t
        own = scene.episodes_path if scene.episodes_path is not None else scene.products / "episodes.json"
        path = episodes_for_run(scene, Path(own), num=t.episodes.num, seed=t.episodes.seed,
                                splits=tuple(t.episodes.splits), goal_images=t.episodes.goal_images)
        return scene, path, t

    def check_trained_recipes(self, manifest: Ledger) -> None:
        """Refuse to reuse a done `train` cell whose recorded config (`config.yaml`, resolved) differs from
        what `study.train` composes now. A cell's hash covers the `study.train` overrides, not the config
        defaults and code they resolve against: after e.g. a PPO fix changes `conf/algo`, the same overrides
        would otherwise reuse the old policies silently. Paths inside the study are compared as the study's own
        (`_portable`), so a copied study still matches; `study.accept_recipe_changes` names the keys a user has
        checked do not matter (listed in the table)."""
        accepted = tuple(self.c.study.accept_recipe_changes)
        for key, cell in self.cells.items():
            folder = self.cell_dir(key)
            if cell.kind not in ("train", "ppo") or manifest.status(key, self.digests[key]) != "done":
                continue
            recorded = yaml.safe_load((folder / "config.yaml").read_text())
            now = resolved(self.cell_train_config(cell, folder))
            diff = dotted_diff(_portable(recorded), _portable(now), skip=accepted)
            if diff:
                raise RuntimeError(f"{folder}: cell {key} was trained with another recipe than study.train composes "
                                   "now:\n  " + "\n  ".join(diff) + "\nstart the study in a new out= folder (a cell's "
                                   "hash covers the overrides, not the defaults they resolve against), or list keys "
                                   "that do not change results in study.accept_recipe_changes")

    # ------------------------------------------------------------------ the cells
    def __call__(self, cell: Cell, folder: Path) -> dict:
        # a ppo cell is a train run whose config (`cell_train_config`) starts at its train cell's bc.pt
        run = {"build": self._build, "init": self._init, "train": self._train, "ppo": self._train,
               "eval": self._eval}
        if cell.kind not in run:
            raise ValueError(f"cell {cell.key}: unknown kind {cell.kind!r}; known: {sorted(run)}")
        return run[cell.kind](cell, folder)

    def _build(self, cell: Cell, folder: Path) -> dict:
        path = build_degraded_scene(self.source(), self.env_path(cell.env), preset(cell.env, cell.seed),
                                    device=self.c.device)
        meta = json.loads((path / "scene_meta.json").read_text())["degradation"]
        return {"scene": str(path), "figures": meta["figures"]}

    def _init(self, cell: Cell, folder: Path) -> dict:
        """The untrained policy of seed s: `train`'s policy config, initialised after `torch.manual_seed(s)`."""
        cfg = self.train_config(GROUNDED, cell.seed)
        conf = resolved(cfg)
        torch.manual_seed(cell.seed)
        policy = make_policy_from_config(conf["policy"], self.c.device)
        save_checkpoint(folder / CHECKPOINTS["untrained"], policy=policy, optimizer=None, counters={}, config=conf,
                        card=policy_card(conf, policy), phase="untrained")
        return {"checkpoint": str(folder / CHECKPOINTS["untrained"])}

    def _train(self, cell: Cell, folder: Path) -> dict:
        """One `train` run in the cell's env: BC then PPO (a train cell), or PPO alone from the train cell's
        BC checkpoint (a ppo cell, `study.ppo_stage`)."""
        _, episodes, t = self.env_episodes(cell.env, cell.seed)  # made here so a too-broken navmesh fails clearly
        counts = split_counts(episodes)
        asked = self.episodes_asked(cell.env, t.episodes.num)
        if counts.get("train", 0) < 1 or counts.get(self.c.study.eval_split, 0) < 1:
            raise RuntimeError(f"{episodes}: only {counts} episodes on this navmesh (asked for {asked}); "
                               "too few to train and evaluate")
        cfg = self.cell_train_config(cell, folder)
        ppo = typed_config(cfg, TrainConfig).algo.ppo
        # recorded beside the rows (a budget with no policy update is refused by PPOConfig before we get here)
        updates = ppo.num_iterations - ppo.critic_warmup_iters if ppo.enabled else 0
        rows = self.train_fn(cfg)
        return {"episodes_file": str(episodes), "episodes": counts, "asked": asked, "ppo_frames": ppo.total_frames,
                "ppo_policy_updates": updates,
                "rows": {k: {m: v[m] for m in ("SR", "IR", "NE", "SPL") if m in v} for k, v in rows.items()}}

    def _eval(self, cell: Cell, folder: Path) -> dict:
        s = self.c.study
        ckpt = self.cell_dir(self.needs_producer(cell)) / phase_checkpoint(cell.policy[1])
        if not ckpt.is_file():  # a train cell never deletes its checkpoints: its folder was changed by hand
            raise FileNotFoundError(f"{ckpt}: the {cell.policy[1]} checkpoint of {self.needs_producer(cell)} is missing; "
                                    "delete that cell's folder to train it again")
        scene, episodes, _ = self.env_episodes(cell.env, cell.seed)
        routes = {}
        if cell.protocol == "grounded_routes":  # the grounded test routes mapped into this env (counted drops)
            grounded = self.env_episodes(GROUNDED, cell.seed)[1]
            episodes, routes = grounded_routes_file(grounded, s.eval_split, s.eval_episodes, scene, self.out / "routes")
            n = routes["kept"]
            if n == 0:  # a finding (every grounded route is infeasible here), counted in the table, not a failure
                atomic_write_json(folder / "result.json", {"cell": cell.key, "checkpoint": str(ckpt), "records": [],
                                                           "routes": routes})
                return {"episodes": 0, "routes": {k: v for k, v in routes.items() if k != "dropped_ids"}}
        else:
            n = _episodes_to_run(episodes, s.eval_split, s.eval_episodes)
        _, results, table = compare_checkpoints([ckpt], SceneWork.of(scene, episodes), split=s.eval_split,
                                                num_episodes=n, batch_size=min(s.eval_batch_size, n),
                                                device=self.c.device, seed=cell.seed)
        res = next(iter(results.values()))
        atomic_write_json(folder / "result.json", {"cell": cell.key, "checkpoint": str(ckpt), "episodes_file":
                                                   str(episodes), "records": res.records, "summary": res.summary})
        log.info("%s:\n%s", cell.key, table)
        info = {m: res.summary["overall"][m] for m in ("SR", "IR", "NE", "SPL", "episodes")}
        return {**info, "routes": {k: v for k, v in routes.items() if k != "dropped_ids"}} if routes else info

    def needs_producer(self, cell: Cell) -> str:
        return cell.needs[0]  # plan._eval puts the policy's producer first


def _portable(config: dict) -> dict:
    """A train / ppo cell's identity config without what is the cell's own: scene path, seed, threads, the
    ppo cell's init_checkpoint (its train cell's bc.pt, whose hash is in the ppo cell's) and the folder of a
    `study.episode_sampler` episodes file (its name carries the generator's settings hash, kept)."""
    out = {k: v for k, v in identity_config(config).items() if k not in ("scene", "seed", "threads", "init_checkpoint")}
    if (out.get("episodes") or {}).get("path"):
        out["episodes"] = {**out["episodes"], "path": Path(out["episodes"]["path"]).name}
    return out


def _episodes_to_run(episodes: Path, split: str, wanted: int | None) -> int:
    """`wanted` episodes of `split`, or all it has when fewer (logged): a broken navmesh yields fewer
    episodes, and evaluating one twice would count it twice."""
    have = split_counts(episodes).get(split, 0)
    if have < 1:
        raise RuntimeError(f"{episodes}: no {split!r} episodes on this navmesh; nothing to evaluate")
    if wanted is not None and have < wanted:
        log.warning("%s: only %d %r episodes (study.eval_episodes=%d): evaluating those", episodes, have, split, wanted)
    return have if wanted is None else min(have, wanted)


def eval_records(manifest: Ledger, cells: list[Cell], digests: dict[str, str]) -> dict[str, dict[tuple, list[dict]]]:
    """protocol -> (eval env, seed, trained-in env, phase) -> per-episode records of every eval cell done
    with its hash. The grounded env has one episode set, so its records also stand in the
    "grounded_routes" protocol."""
    out: dict[str, dict[tuple, list[dict]]] = {p: {} for p in PROTOCOLS}
    for cell in cells:
        if cell.kind == "eval" and manifest.status(cell.key, digests[cell.key]) == "done":
            e = manifest.entry(cell.key, digests[cell.key])
            recs = json.loads((Path(e["dir"]) / "result.json").read_text())["records"]
            out[cell.protocol][(cell.env, cell.seed, *cell.policy)] = recs
            if cell.env == GROUNDED:
                out["grounded_routes"][(cell.env, cell.seed, *cell.policy)] = recs
    return out
