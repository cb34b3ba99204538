"""Config -> a prepared `Scene` and its episodes, the same way for every entry point."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import time
from pathlib import Path

from omegaconf import OmegaConf

from planners import NavMesh
from wanderland_nav.compose.cli import CONF_DIR
from wanderland_nav.compose.schema import NavigationGroup, PrepareConfig, SceneGroup, typed_config
from wanderland_nav.episodes.generate import refresh_if_stale, write_scene_episodes
from wanderland_nav.scene import load_scene, make_demo_scene, make_generated_scene
from wanderland_nav.scene.loader import SCENE_LAYOUTS, is_scene_folder
from wanderland_nav.preparation.scene import check_navmesh_frame, prepare_scene

log = logging.getLogger(__name__)


def scene_folder(scene: SceneGroup, navigation: NavigationGroup | None = None) -> Path:
    """Where the scene lives; the demo (or a district, `scene.generator`) is made there on first use (idempotent). A
    non-default demo preset gets its own folder beside the default one (`<path>_<preset>`), and so do `navigation`
    settings other than the default ones (`<path>_nav<hash8>`): a generated scene's collision mesh, navmesh and
    episodes are products of those settings, so `debug=smoke` (coarser voxels) and the main job each keep their own
    beside the other instead of re-baking one folder in turn. A scene set is refused (`refuse_set`): the
    commands that take one scene never quietly use a set's first scene."""
    refuse_set(scene)
    path = Path(scene.path)
    if scene.demo and scene.generator != "demo":  # a district: its folder is keyed by seed and size (conf/scene)
        path = Path(f"{path}{navigation_tag(navigation)}")
        t = time.perf_counter()
        make_generated_scene(path, scene.generator, seed=scene.seed, preset=scene.size)
        log.info("%s scene (seed %d, %s) ready at %s (%.1fs)", scene.generator, scene.seed, scene.size, path,
                 time.perf_counter() - t)
    elif scene.demo:
        preset = scene.preset
        path = path if preset == "default" else Path(f"{path}_{preset}")
        path = Path(f"{path}{navigation_tag(navigation)}")
        t = time.perf_counter()
        make_demo_scene(path, seed=scene.seed, preset=preset)
        log.info("demo scene (%s) ready at %s (%.1fs)", preset, path, time.perf_counter() - t)
    elif not is_scene_folder(path):
        raise FileNotFoundError(f"scene.path={path}: not a scene folder ({SCENE_LAYOUTS})")
    return path


def names_set(scene: SceneGroup) -> bool:
    """Whether `scene` names a scene set (its `set` block) rather than one scene: the one place this is asked
    (`compose.scene_sets.scene_work` turns either into the scenes a command works on)."""
    return scene.set is not None


def refuse_set(scene: SceneGroup, what: str = "this command takes one scene") -> None:
    """Raises for a scene set, naming it and what to pass instead (`export_usd`, `fit`, `replay`, and the features
    that record one scene)."""
    if names_set(scene):
        raise ValueError(f"scene={scene.name} is a scene set; {what}: pass scene=<folder> (one of the set's, "
                         f"e.g. scene={scene.path}). prepare, make_episodes, train, evaluate, benchmark and make_env "
                         "take sets")


def navigation_tag(navigation: NavigationGroup | None) -> str:
    """"" for the default collision and navmesh settings (`conf/navigation/default.yaml`, or none given), else
    `_nav<hash8>` of them."""
    if navigation is None:
        return ""
    text = lambda n: json.dumps([dataclasses.asdict(n.collision), dataclasses.asdict(n.navmesh)],  # noqa: E731
                                sort_keys=True)
    mine = text(navigation)
    if mine == text(default_navigation()):
        return ""
    return "_nav" + hashlib.sha256(mine.encode()).hexdigest()[:8]


@functools.lru_cache(maxsize=1)
def default_navigation() -> NavigationGroup:
    """The `navigation` every entry point composes by default: `conf/navigation/default.yaml` over the dataclass
    (typed through `prepare`'s schema, the smallest that holds the group, whose node is built once)."""
    return typed_config({"navigation": OmegaConf.load(CONF_DIR / "navigation" / "default.yaml")}, PrepareConfig).navigation


def prepared_scene(scene: SceneGroup, navigation: NavigationGroup, *, force: bool = False, bake_navmesh: bool = True, prepare: bool | None = None):
    """The loaded Scene with collision mesh and navmesh built from `navigation` (skipped when up to
    date); with `prepare` (default `navigation.prepare`) false, a non-demo scene's artefacts on disk
    are used as they are."""
    path = scene_folder(scene, navigation)
    prepare = navigation.prepare if prepare is None else prepare
    if not (prepare or scene.demo or force):
        loaded = load_scene(path, up_axis=scene.up_axis)
        check_navmesh_frame(loaded)
        return loaded
    return prepare_scene(path, force=force, collision=navigation.collision, navmesh=navigation.navmesh,
                         up_axis=scene.up_axis, bake_navmesh=bake_navmesh)


def scene_episodes(scene, path: str | None, *, num: int, seed: int, generator) -> tuple[object, Path]:
    """(scene, episodes file): `path` when given, else the scene's `episodes.json`, generated with
    `generator` (`GeneratorSettings`) when missing. The returned scene records that file."""
    if path is not None:
        if not Path(path).is_file():
            raise FileNotFoundError(f"episodes={path}: no such file")
        return scene, Path(path)
    if scene.episodes_path is not None and Path(scene.episodes_path).is_file():
        # ours, on an older navmesh: rebuilt on this one
        refresh_if_stale(scene, Path(scene.episodes_path), lambda: NavMesh.load(scene.navmesh_path))
        return scene, Path(scene.episodes_path)
    if scene.navmesh_path is None:
        raise FileNotFoundError(f"{scene.root}: no navmesh.npz; prepare the scene first "
                                f"(python -m wanderland_nav.prepare scene={scene.root})")
    out = scene.products / "episodes.json"
    t = time.perf_counter()
    write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), out, num_episodes=num, seed=seed, settings=generator)
    log.info("generated %d episodes -> %s (%.1fs)", num, out, time.perf_counter() - t)
    scene.episodes_path = out
    return scene, out
