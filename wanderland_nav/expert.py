"""Expert episodes for one or many scenes: `python -m wanderland_nav.expert scene=... num_episodes=N seed=S`.

`scene=` takes `demo` (built and prepared on first use), a scene folder, a name under
`scenes_root`, a folder whose sub-folders are scenes, or a list of those (`scene=[a,b]`).
Several scenes run in parallel processes, each with its own progress bar; at the end a summary
per scene (kept, rejection reasons, length histogram). Per scene it writes `episodes.json`,
`goal_images/*.png` and `episodes_topdown.png` (by default in the scene folder).

This module is a thin Hydra shell: it turns the config into typed settings and calls
`wanderland_nav.episodes.generate.write_scene_episodes` and `wanderland_nav.viz.topdown`.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import hydra
from omegaconf import DictConfig, ListConfig, OmegaConf

from wanderland_nav.scene.loader import scene_layout

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
#: files whose presence marks a folder as a scene folder (any one of them)
SCENE_MARKERS = ("scene_meta.json", "navmesh.npz", "sparse", "transforms.json", "raw_pcd.ply", "3dgs.ply")


@dataclass(frozen=True)
class ScenePlan:
    """One scene to process; picklable so it can cross into a worker process."""

    path: str
    demo: bool = False
    demo_seed: int = 0
    demo_preset: str = "default"
    out: str | None = None  # episodes file; None: <scene folder>/episodes.json


def is_scene_folder(p: Path) -> bool:
    return scene_layout(p) is not None or (p.is_dir() and any((p / m).exists() for m in SCENE_MARKERS))


def resolve_scenes(cfg: DictConfig) -> list[ScenePlan]:
    """Expand the `scene`/`scenes` config into scene plans (demo, folders, names, lists)."""
    demo_path = str(cfg.scene.path) if cfg.scene.get("demo", False) else str(Path(cfg.scenes_root) / "demo")
    demo_seed = int(cfg.scene.get("seed", 0) or 0)
    demo_preset = str(cfg.scene.get("preset", "default") or "default")
    if cfg.scenes is None:
        items = ["demo"] if cfg.scene.get("demo", False) else [str(cfg.scene.path)]
    elif isinstance(cfg.scenes, (list, ListConfig)):
        items = [str(s) for s in cfg.scenes]
    else:
        items = [str(cfg.scenes)]
    plans: list[ScenePlan] = []
    for item in items:
        if item == "demo":
            plans.append(ScenePlan(path=demo_path, demo=True, demo_seed=demo_seed, demo_preset=demo_preset))
            continue
        p = Path(item).expanduser()
        if not p.exists() and (Path(cfg.scenes_root) / item).exists():
            p = Path(cfg.scenes_root) / item
        if is_scene_folder(p):
            plans.append(ScenePlan(path=str(p)))
        elif p.is_dir():
            subs = sorted(q for q in p.iterdir() if is_scene_folder(q))
            if not subs:
                raise FileNotFoundError(f"scene={item}: {p} is neither a scene folder (none of {SCENE_MARKERS}) "
                                        "nor a folder of scene folders")
            plans.extend(ScenePlan(path=str(q)) for q in subs)
        else:
            raise FileNotFoundError(f"scene={item}: no such scene folder (also looked in {cfg.scenes_root}/)")
    names = [Path(pl.path).name for pl in plans]
    if cfg.out is not None:
        out = Path(str(cfg.out))
        if len(plans) == 1:
            plans = [ScenePlan(**{**plans[0].__dict__, "out": str(out)})]
        else:  # several scenes: `out` is a folder with one sub-folder per scene (goal images stay apart)
            if len(set(names)) != len(names):
                raise ValueError(f"out={out}: several scenes share a folder name {names}; give no out= "
                                 "to write each beside its scene")
            plans = [ScenePlan(**{**pl.__dict__, "out": str(out / n / "episodes.json")}) for pl, n in zip(plans, names)]
    return plans


def settings_from_cfg(cfg: DictConfig):
    from wanderland_nav.episodes.generate import GeneratorSettings
    from wanderland_nav.episodes.sampler import SamplerSettings

    gen = OmegaConf.to_container(cfg.generator, resolve=True)
    gen["splits"] = tuple(gen["splits"])
    return GeneratorSettings(sampler=SamplerSettings(**OmegaConf.to_container(cfg.sampler, resolve=True)), **gen)


def process_scene(plan: ScenePlan, *, num_episodes: int, seed: int, settings, force: bool, prepare: bool,
                  topdown: bool, progress: bool, position: int = 0):
    """Load (or build) one scene, write its episodes and top-down PNG; returns the summary."""
    from tqdm import tqdm

    from planners import NavMesh
    from wanderland_nav.episodes.generate import write_scene_episodes
    from wanderland_nav.scene import load_scene

    if plan.demo:
        from wanderland_nav.pipeline import ensure_demo_scene

        scene = ensure_demo_scene(plan.path, seed=plan.demo_seed, preset=plan.demo_preset)
    elif prepare:
        from wanderland_nav.pipeline import prepare_scene

        scene = prepare_scene(plan.path)
    else:
        scene = load_scene(plan.path)
    if scene.navmesh_path is None or not Path(scene.navmesh_path).is_file():
        raise FileNotFoundError(f"{plan.path}: navmesh.npz missing; run `python -m wanderland_nav.prepare` "
                                "or leave prepare=true")
    navmesh = NavMesh.load(scene.navmesh_path)
    out = Path(plan.out) if plan.out else Path(scene.root) / "episodes.json"
    bar = tqdm(total=num_episodes, desc=scene.name, position=position, leave=True, disable=not progress,
               unit="ep", dynamic_ncols=True)
    try:
        episodes, summary = write_scene_episodes(scene, navmesh, out, num_episodes=num_episodes, seed=seed,
                                                 settings=settings, force=force, progress=bar.update)
        if summary.skipped:
            bar.update(num_episodes - bar.n)
    finally:
        bar.close()
    if topdown:
        from wanderland_nav.viz.topdown import plot_topdown

        png = out.with_name(out.name.split(".")[0] + "_topdown.png")
        if not (summary.skipped and png.is_file()):
            plot_topdown(png, nav_from_scene=scene.nav_from_scene, camera_centers=scene.capture_positions(),
                         episodes=episodes, navmesh=navmesh, seed=seed,
                         title=f"{scene.name}: {len(episodes)} episodes (seed {seed})")
    return summary


def _worker(args):
    import torch

    torch.set_num_threads(1)  # one process per scene: no thread oversubscription
    plan, kw, position = args
    return process_scene(plan, position=position, **kw)


def run(cfg: DictConfig):
    """Everything `main` does, callable without Hydra's runtime (tests compose the config)."""
    plans = resolve_scenes(cfg)
    kw = dict(num_episodes=int(cfg.num_episodes), seed=int(cfg.seed), settings=settings_from_cfg(cfg),
              force=bool(cfg.force), prepare=bool(cfg.prepare), topdown=bool(cfg.topdown),
              progress=bool(cfg.progress))
    workers = int(cfg.workers) if cfg.workers is not None else min(len(plans), os.cpu_count() or 1)
    if len(plans) == 1 or workers <= 1:
        summaries = [process_scene(pl, position=i, **kw) for i, pl in enumerate(plans)]
    else:
        # spawn: no fork of a process that already holds torch threads / open files
        with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as ex:
            summaries = list(ex.map(_worker, [(pl, kw, i) for i, pl in enumerate(plans)]))
    print("\n".join(s.format() for s in summaries), flush=True)
    total = sum(s.kept for s in summaries)
    print(f"total: {total} episodes in {len(summaries)} scene(s)", flush=True)
    return summaries


@hydra.main(version_base="1.3", config_path="../conf", config_name="expert")
def main(cfg: DictConfig) -> None:
    run(cfg)


def rewrite_scene_override(argv: list[str], conf_dir: Path = CONF_DIR) -> list[str]:
    """`scene=X` -> `scenes=X` unless X names a config in conf/scene/.

    Why: `scene` is a Hydra config group, so Hydra would reject a path or a list there; the
    README's `scene=<path>` spelling is kept by moving such values to the plain `scenes` key.
    """
    out = []
    for a in argv:
        if a.startswith("scene="):
            val = a[len("scene="):]
            if not (conf_dir / "scene" / f"{val}.yaml").is_file():
                a = "scenes=" + val
        out.append(a)
    return out


if __name__ == "__main__":
    sys.argv = [sys.argv[0]] + rewrite_scene_override(sys.argv[1:])
    main()
