"""The episode file a training run uses, so that `episodes.num` is never silently ignored.

A scene without episodes gets its `episodes.json` generated. A scene may ship one (the demo scene
does, with 100 episodes); when the run asks for
another count (or other split fractions), the scene's file is left untouched (released files are never
overwritten) and a sibling `episodes_n<num>_s<seed>_<splits>.json` is generated once with the expert's
generator and reused afterwards (the generator's args hash makes reruns free). Either way the log says
which file and how many episodes per split the run uses.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch

from planners import NavMesh
from wanderland_nav.episodes import load_episodes
from wanderland_nav.episodes.generate import GeneratorSettings, refresh_if_stale, write_scene_episodes
from wanderland_nav.episodes.schema import load_episode_file

log = logging.getLogger(__name__)


def split_counts(path: Path) -> dict[str, int]:
    eps = load_episode_file(path).episodes
    return {s: sum(e.split == s for e in eps)
            for s in ("train", "val", "test")}


def run_episodes_file(scene, *, num: int | None, seed: int, splits, goal_images: bool) -> Path:
    """`train`'s episodes file for a single scene when `episodes.path` is unset (`episodes_for_run` over the scene's
    own file: `episodes.num` is honoured); recorded on the scene."""
    own = scene.episodes_path if scene.episodes_path is not None else scene.products / "episodes.json"
    scene.episodes_path = episodes_for_run(scene, Path(own), num=num, seed=seed, splits=tuple(splits),
                                           goal_images=goal_images)
    return scene.episodes_path


def episodes_for_run(scene, existing: Path | None, *, num: int | None, seed: int,
                     splits: tuple[float, float, float], goal_images: bool) -> Path:
    """`existing` when it matches `num` and `splits` (or `num` is None), else a generated sibling file.

    splits: train / val / test fractions of `num`.
    """
    if existing is not None and Path(existing).is_file():
        # ours, on an older navmesh: rebuilt on this one
        refresh_if_stale(scene, Path(existing), lambda: NavMesh.load(scene.navmesh_path))
        counts = split_counts(Path(existing))
        total = sum(counts.values())
        if num is None:
            log.info("episodes: %s (%s, episodes.num=null: the scene's own file)", existing, counts)
            return Path(existing)
        want = {"val": round(splits[1] * num), "test": round(splits[2] * num)}
        if total == num and all(counts[s] == want[s] for s in want):
            log.info("episodes: %s (%s)", existing, counts)
            return Path(existing)
        log.warning("episodes: %s has %d episodes %s; episodes.num=%d with splits %s requested: using a generated "
                    "sibling file instead (the scene's file is left as it is)", existing, total, counts, num,
                    list(splits))
    if num is None:
        raise FileNotFoundError(f"{scene.root}: no episodes.json and episodes.num=null: set episodes.num")
    if scene.navmesh_path is None:
        raise FileNotFoundError(f"{scene.root}: no navmesh.npz; prepare the scene first "
                                f"(python -m wanderland_nav.prepare scene={scene.root})")
    tag = "-".join(f"{f:g}" for f in splits)
    fresh = existing is not None and not Path(existing).exists()  # no file yet: make the scene's own
    out = Path(existing) if fresh else scene.products / f"episodes_n{num}_s{seed}_{tag}.json"
    # point-goal training needs no goal views; rendering them costs seconds each on a CPU
    settings = GeneratorSettings(goal_images=goal_images, splits=tuple(splits))
    _, summary = write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), out, num_episodes=int(num),
                                      seed=int(seed), settings=settings)
    what = "reused" if summary.skipped else f"generated in {summary.seconds:.0f}s"
    log.info("episodes: %s (%d episodes %s, %s)", out, summary.kept, summary.splits, what)
    if summary.kept != num:
        log.warning("episodes: the generator kept %d of the %d requested episodes (%s)", summary.kept, num,
                    summary.rejections)
    return out


def ppo_route_file(scene, base: Path, *, num: int, seed: int, base_seed: int, goal_images: bool) -> Path:
    """A train-only file of `num` more routes for PPO (`episodes.ppo_routes`), drawn with its own `seed`.

    The evaluation episodes stay those of `base`: the new file has no val/test split. The same seed as
    `base`'s would redraw `base`'s endpoints (val and test among them), so it is refused. Routes that
    start and end within 1 m of a val/test route of `base` are counted in the log (near-copies).
    """
    if seed == base_seed:
        raise ValueError(f"episodes.ppo_routes_seed={seed} equals episodes.seed: the extra PPO routes would redraw "
                         f"{base}'s endpoints, val and test among them; choose another ppo_routes_seed")
    out = episodes_for_run(scene, None, num=num, seed=seed, splits=(1.0, 0.0, 0.0), goal_images=goal_images)
    held_out = [e for s in ("val", "test") for e in load_episodes(base, split=s)]
    near = _near_copies(load_episodes(out), held_out) if held_out else 0
    log.info("episodes: PPO also trains on %s (%d train-only routes, seed %d); %d of them start and end within 1 m "
             "of one of %s's %d val/test routes", out, num, seed, near, base.name, len(held_out))
    return out


def _near_copies(routes, held_out, radius: float = 1.0) -> int:
    """How many of `routes` have start and goal both within `radius` m of one held-out route's."""
    ends = lambda eps: torch.as_tensor(np.stack([np.r_[e.start_position, e.goal_position] for e in eps]))  # noqa: E731
    a, b = ends(routes), ends(held_out)  # [E, 6], [H, 6]: start, goal (scene frame, m)
    close = (torch.cdist(a[:, :3], b[:, :3]) < radius) & (torch.cdist(a[:, 3:], b[:, 3:]) < radius)  # [E, H]
    return int(close.any(1).sum())
