"""Episodes (with their expert shortest paths) for one or many scenes: `python -m wanderland_nav.make_episodes scene=... num_episodes=N seed=S`.

`scene=` takes `demo` (built and prepared on first use), a scene folder, a name under `scenes_root`, a
folder whose sub-folders are scenes, or a list of those (`scene=[a,b]`). Several scenes run in parallel
processes, each with its own progress bar; at the end a summary per scene (kept, rejection reasons,
length histogram). Per scene: `episodes.json`, `goal_images/*.png` and `episodes_topdown.png`.

A scene set (`scene=demo_set`, or any `scene.set`: a manifest) runs through the set's resumable jobs
(`compose.scene_sets.run_set_jobs`): each scene is prepared with the composed `navigation` settings and
gets `episodes.json` beside it (no top-down picture); scenes done with the same settings are skipped,
failures are listed at the end and the exit status is 1.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from functools import partial
import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor

import torch
from omegaconf import DictConfig

from wanderland_nav.compose import scene_overrides, typed_config
from wanderland_nav.compose.episode_sets import process_scene, resolve_scenes
from wanderland_nav.compose.scene import names_set
from wanderland_nav.compose.scene_sets import run_set_jobs
from wanderland_nav.compose.schema import MakeEpisodesConfig


def _worker(args):
    torch.set_num_threads(1)  # one process per scene: no thread oversubscription
    plan, kw, position = args
    return process_scene(plan, position=position, **kw)


def run(cfg: DictConfig):
    """Everything `main` does, callable without Hydra's runtime (tests compose the config)."""
    c: MakeEpisodesConfig = typed_config(cfg, MakeEpisodesConfig)
    if names_set(c.scene):  # a set: its resumable batch jobs, one report row per scene
        if c.scenes or c.out is not None:
            raise ValueError(f"scene={c.scene.name} is a scene set: its episodes go beside each scene; "
                             "give no scene list and no out=")
        return run_set_jobs(c.scene, c.navigation, generator=c.generator, num_episodes=c.num_episodes, seed=c.seed,
                            force=c.force, workers=c.workers)
    plans = resolve_scenes(c)
    kw = dict(navigation=c.navigation, num_episodes=c.num_episodes, seed=c.seed, settings=c.generator, force=c.force,
              topdown=c.topdown, progress=c.progress)
    workers = c.workers if c.workers is not None else min(len(plans), os.cpu_count() or 1)
    if len(plans) == 1 or workers <= 1:
        summaries = [process_scene(pl, position=i, **kw) for i, pl in enumerate(plans)]
    else:
        # spawn: no fork of a process that already holds torch threads / open files
        with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as ex:
            summaries = list(ex.map(_worker, [(pl, kw, i) for i, pl in enumerate(plans)]))
    print("\n".join(s.format() for s in summaries), flush=True)
    print(f"total: {sum(s.kept for s in summaries)} episodes in {len(summaries)} scene(s)", flush=True)
    return summaries


main = entry_point("make_episodes", run, argv=partial(scene_overrides, list_key="scenes"))


if __name__ == "__main__":
    main()
