"""`make_episodes`'s composition: `scene=` (demo, folders, names, lists, folders of scenes) -> scene plans, and
one plan -> its prepared scene, `episodes.json` and top-down picture."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from wanderland_nav.compose.build import check_scene_splat, load_navmesh
from wanderland_nav.compose.scene import prepared_scene
from wanderland_nav.compose.schema import MakeEpisodesConfig, NavigationGroup, SceneGroup
from wanderland_nav.episodes.generate import write_scene_episodes
from wanderland_nav.scene.loader import SCENE_LAYOUTS, is_scene_folder
from wanderland_nav.viz.topdown import plot_topdown


@dataclass(frozen=True)
class ScenePlan:
    """One scene to process; picklable so it can cross into a worker process."""

    scene: SceneGroup
    out: str | None = None  # episodes file; None: <scene folder>/episodes.json


def _folder(path: Path, c: MakeEpisodesConfig) -> SceneGroup:
    """A scene folder, keeping `scene.up_axis` when `scene=` named a folder (not the demo)."""
    base = c.scene if not c.scene.demo else SceneGroup()
    return dataclasses.replace(base, name=path.name, path=str(path), demo=False)


def _plans_for(item: str, c: MakeEpisodesConfig) -> list[ScenePlan]:
    if item == "demo":
        demo = c.scene if c.scene.demo else SceneGroup(path=str(Path(c.scenes_root) / "demo"), demo=True)
        return [ScenePlan(demo)]
    p = Path(item).expanduser()
    if not p.exists() and (Path(c.scenes_root) / item).exists():
        p = Path(c.scenes_root) / item
    if is_scene_folder(p):
        return [ScenePlan(_folder(p, c))]
    if p.is_dir():
        subs = sorted(q for q in p.iterdir() if is_scene_folder(q))
        if not subs:
            raise FileNotFoundError(f"scene={item}: {p} is neither a scene folder ({SCENE_LAYOUTS}) "
                                    "nor a folder of scene folders")
        return [ScenePlan(_folder(q, c)) for q in subs]
    raise FileNotFoundError(f"scene={item}: no such scene folder (also looked in {c.scenes_root}/)")


def resolve_scenes(c: MakeEpisodesConfig) -> list[ScenePlan]:
    """Expand `scene` / `scenes` into scene plans, each with its episodes file."""
    items = c.scenes if c.scenes else ["demo" if c.scene.demo else c.scene.path]
    plans = [pl for item in items for pl in _plans_for(str(item), c)]
    if c.out is None:
        return plans
    if len(plans) == 1:
        return [dataclasses.replace(plans[0], out=str(c.out))]
    names = [Path(pl.scene.path).name for pl in plans]  # several: one sub-folder per scene (goal images stay apart)
    if len(set(names)) != len(names):
        raise ValueError(f"out={c.out}: several scenes share a folder name {names}; give no out= "
                         "to write each beside its scene")
    return [dataclasses.replace(pl, out=str(Path(c.out) / n / "episodes.json")) for pl, n in zip(plans, names)]


def process_scene(plan: ScenePlan, *, navigation: NavigationGroup, num_episodes: int, seed: int, settings,
                  force: bool, topdown: bool, progress: bool, position: int = 0):
    """Prepare one scene, write its episodes and top-down PNG; returns the generation summary."""

    scene = prepared_scene(plan.scene, navigation)
    navmesh = load_navmesh(scene)
    out = Path(plan.out) if plan.out else scene.products / "episodes.json"
    if settings.goal_images and scene.gaussians_path is not None and Path(scene.gaussians_path).is_file():
        check_scene_splat(scene)  # goal views of a splat nobody can see would be black
    bar = tqdm(total=num_episodes, desc=scene.name, position=position, leave=True, disable=not progress,
               unit="ep", dynamic_ncols=True)
    try:
        episodes, summary = write_scene_episodes(scene, navmesh, out, num_episodes=num_episodes, seed=seed,
                                                 settings=settings, force=force, progress=bar.update)
        if summary.skipped:
            bar.update(num_episodes - bar.n)
    finally:
        bar.close()
    png = out.with_name(out.name.split(".")[0] + "_topdown.png")
    if topdown and not (summary.skipped and png.is_file()):
        plot_topdown(png, nav_from_scene=scene.nav_from_scene, camera_centers=scene.capture_positions(),
                     episodes=episodes, navmesh=navmesh, seed=seed,
                     title=f"{scene.name}: {len(episodes)} episodes (seed {seed})")
    return summary
