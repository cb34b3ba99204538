"""Expert episodes for one prepared scene: sample -> shortest paths -> dense paths -> images -> text.

`generate_episodes(scene, navmesh, ...)` is the pure library step (returns episodes + a summary);
`write_scene_episodes(...)` adds the file side: an args hash stored in the file so that a rerun with
the same arguments is a no-op, goal-image PNGs beside the file, and an atomic write. Output is
byte-identical for a seed: every random draw comes from `np.random.default_rng(seed)` (or a
per-episode child seed) in a fixed order, numbers are rounded to `decimals` before they are
written, and nothing machine-specific (absolute paths, timings) goes into the file.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from wanderland_nav.atomic import atomic_dir
from wanderland_nav.cache import file_sha256, json_digest
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.episodes.goal_images import render_goal_images
from wanderland_nav.episodes.instructions import InstructionGenerator, Route, RuleBasedInstructions
from wanderland_nav.episodes.paths import first_heading_nav, last_heading_nav, polyline_length, resample_polyline
from wanderland_nav.episodes.sampler import REJECTION_REASONS, EndpointSampler, SamplerSettings
from wanderland_nav.episodes.schema import (
    Episode,
    EpisodeFormatError,
    Goal,
    load_episode_file,
    dump_episodes,
    rotation_from_yaw,
    write_episode_bytes,
)
from wanderland_nav.episodes.ownership import (GENERATOR_NAME, WRITTEN_DIGEST, _UNSTAMPED, _stamped, episodes_target,
                                               not_ours_because, written_by_us)
from wanderland_nav.episodes.ownership import OUR_GENERATOR_NAMES, generated_sibling  # noqa: F401  (their old home)
from wanderland_nav.geometry import wrap_angle
from wanderland_nav.render.lod import DEFAULT_LOD_PX
import shutil

log = logging.getLogger(__name__)

FORMAT_VERSION = 2  # 2: every episode carries its environment label and elevation change
HIST_EDGES = (0, 5, 10, 15, 20, 30, 50, 100, math.inf)  # metres, for the length histogram


@dataclass(frozen=True)
class GeneratorSettings:
    """Everything that shapes an episode set besides the scene, the count and the seed."""

    sampler: SamplerSettings = field(default_factory=SamplerSettings)
    step_size: float = 0.25  # metres between gt_locations (VLN-CE's forward step)
    splits: tuple[float, float, float] = (0.8, 0.1, 0.1)  # train / val / test fractions
    goal_images: bool = True
    goal_image_width: int = 320
    goal_image_height: int = 240
    goal_image_hfov_deg: float = 90.0
    goal_camera_height: float | None = None  # metres above the ground; None: median capture-camera height
    goal_image_lod_px: float | None = DEFAULT_LOD_PX  # the splat's level of detail for goal views (render/lod.py); None: all
    render_device: str = "cpu"
    render_backend: str = "fused"  # render() backend of the goal views ("torch": the reference; the same images)
    decimals: int = 4  # rounding of every written coordinate (0.1 mm)
    # a scene's `scene_meta.json` may name the sampler fields its episodes use (`episode_sampler`, e.g. a
    # district's long routes); they replace these `sampler` fields unless this is false
    scene_sampler: bool = True

    def __post_init__(self):
        if self.step_size <= 0:
            raise ValueError(f"GeneratorSettings.step_size must be > 0, got {self.step_size}")
        if len(self.splits) != 3 or min(self.splits) < 0 or not math.isclose(sum(self.splits), 1.0, abs_tol=1e-6):
            raise ValueError(f"GeneratorSettings.splits must be 3 fractions >= 0 summing to 1, got {self.splits}")
        if self.goal_camera_height is not None and self.goal_camera_height <= 0:
            raise ValueError(f"GeneratorSettings.goal_camera_height must be > 0, got {self.goal_camera_height}")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["splits"] = list(self.splits)
        d.pop("render_device")  # where and how we render does not change the result
        d.pop("render_backend")
        if self.scene_sampler:  # recorded only when off: the recorded sampler is the one used
            d.pop("scene_sampler")
        return d

    def for_scene(self, scene) -> "GeneratorSettings":
        """These settings with the sampler fields the scene's `scene_meta.json` names (`episode_sampler`) in place
        of this `sampler`'s, when `scene_sampler` is on; unknown fields are refused with the file named."""
        over = (getattr(scene, "meta", None) or {}).get("episode_sampler") if self.scene_sampler else None
        if not over:
            return self
        known = {f.name for f in dataclasses.fields(SamplerSettings)}
        bad = sorted(set(over) - known)
        if bad:
            raise WanderlandInputError(f"{getattr(scene, 'root', '?')}/scene_meta.json: episode_sampler: unknown "
                                       f"field(s) {bad} (known: {sorted(known)})")
        return dataclasses.replace(self, sampler=dataclasses.replace(self.sampler, **over))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "GeneratorSettings":
        """The settings an episode file recorded (`to_dict`)."""
        d = dict(d)
        return cls(sampler=SamplerSettings(**d.pop("sampler")), splits=tuple(d.pop("splits")), **d)


@dataclass
class GenerationSummary:
    """What happened for one scene. `to_dict()` is deterministic (no timings) and goes into the file."""

    scene: str
    requested: int
    kept: int
    candidates: int
    rounds: int
    rejections: dict[str, int]
    length_hist: dict[str, int]  # "0-5": n, ...
    splits: dict[str, int]
    seconds: float = 0.0
    skipped: bool = False  # True when a rerun found an up-to-date file
    out: str | None = None  # the episodes file, when one was written (or found up to date)

    @property
    def episodes_per_second(self) -> float:
        return self.kept / self.seconds if self.seconds > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {"requested": self.requested, "kept": self.kept, "candidates": self.candidates,
                "rounds": self.rounds, "rejections": dict(self.rejections),
                "length_hist_m": dict(self.length_hist), "splits": dict(self.splits)}

    def format(self) -> str:
        """A few human-readable lines for the console."""
        rej = ", ".join(f"{k}={v}" for k, v in self.rejections.items() if v) or "none"
        hist = " ".join(f"[{k}]:{v}" for k, v in self.length_hist.items() if v)
        head = f"{self.scene}: kept {self.kept}/{self.requested}"
        if self.skipped:
            return head + f" (up to date, nothing regenerated: {self.out})"
        lines = [f"{head} from {self.candidates} candidate pairs in {self.seconds:.1f}s "
                 f"({self.episodes_per_second:.1f} episodes/s)",
                 f"  rejected: {rej}", f"  geodesic length histogram (m): {hist}",
                 f"  splits: {self.splits}"] + ([f"  wrote {self.out}"] if self.out else [])
        if self.kept < self.requested:
            lines.append(f"  WARNING: only {self.kept} of {self.requested} episodes found; loosen the sampler "
                         "settings (camera_radius, min/max_geodesic, min_separation) or ask for fewer")
        return "\n".join(lines)


def length_histogram(lengths: np.ndarray) -> dict[str, int]:
    counts, _ = np.histogram(np.asarray(lengths, dtype=np.float64), bins=np.asarray(HIST_EDGES, dtype=np.float64))
    names = [f"{a:g}-{b:g}" if math.isfinite(b) else f"{a:g}+" for a, b in zip(HIST_EDGES[:-1], HIST_EDGES[1:])]
    return {n: int(c) for n, c in zip(names, counts)}


def assign_splits(n: int, fractions: tuple[float, float, float], rng: np.random.Generator) -> list[str]:
    """A random but seed-determined split per episode with exactly round(f * n) val and test episodes."""
    n_val, n_test = int(round(fractions[1] * n)), int(round(fractions[2] * n))
    n_val, n_test = min(n_val, n), min(n_test, n - min(n_val, n))
    labels = np.array(["train"] * (n - n_val - n_test) + ["val"] * n_val + ["test"] * n_test)
    return labels[rng.permutation(n)].tolist() if n else []


# --------------------------------------------------------------------------- library entry


@dataclass
class _RouteGeometry:
    """The per-episode geometry every later stage reads, rounded once to `decimals` so the file,
    the instructions and the summary all see the same numbers."""

    corners: list[np.ndarray]  # E x [K, 3] shortest-path corners, scene frame, rounded
    corners_nav: list[np.ndarray]  # E x [K, 3] the same corners in the nav frame (z up)
    geodesic: np.ndarray  # [E] path length in metres, rounded
    yaw0: np.ndarray  # [E] start heading (nav frame, radians)
    yaw_goal: np.ndarray  # [E] heading along the last segment (nav frame), for the goal image
    q_wxyz: np.ndarray  # [E, 4] start rotation in the scene frame, rounded to 7 places
    radius: np.ndarray  # [E] success radius around the goal, rounded to mm


def _dense_expert_locations(scene, navmesh, paths, R_ns: np.ndarray,
                            step_size: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Dense, on-surface expert locations (E x [S_i, 3], scene frame) and their indoor flags (E x [S_i]).

    One snap and one indoor query for all episodes together, because both are per-call expensive.
    """
    E = len(paths)
    # dense, on-surface expert locations for every episode in one snap call
    # every step_size metres on the ground plane (nav frame), back to the scene frame
    dense = [resample_polyline(p @ R_ns.T, step_size, horizontal=True) @ R_ns for p in paths]
    counts = np.array([len(d) for d in dense], dtype=np.int64)
    flat = np.concatenate(dense, 0) if E else np.zeros((0, 3))
    if len(flat):
        # heights from the navmesh floor under each sample, xy kept: the linear interpolation between corners
        # is on the mesh horizontally (the funnel path stays inside its corridor) but not vertically on slopes
        # and steps; a 3D-nearest snap would pull samples beside a step onto its edge (bunched, then a gap)
        flat = np.asarray(navmesh.floor_points(flat), dtype=np.float64)
        indoor_flat = np.asarray(scene.is_indoor(flat), dtype=bool).reshape(-1)
    else:
        indoor_flat = np.zeros(0, dtype=bool)
    offs = np.concatenate([[0], np.cumsum(counts)])
    dense = [flat[a:b] for a, b in zip(offs[:-1], offs[1:])]
    indoor = [indoor_flat[a:b] for a, b in zip(offs[:-1], offs[1:])]
    return dense, indoor


def _route_geometry(paths, R_ns: np.ndarray, up: str, settings: GeneratorSettings) -> _RouteGeometry:
    """Corners, lengths, headings, start rotations and goal radii of the sampled shortest paths."""
    E, dec = len(paths), settings.decimals
    corners = [np.round(p, dec) for p in paths]
    corners_nav = [c @ R_ns.T for c in corners]
    geodesic = np.array([round(polyline_length(c), dec) for c in corners])
    yaw0 = np.array([first_heading_nav(c) for c in corners_nav])
    yaw_goal = np.array([last_heading_nav(c) for c in corners_nav])
    q_wxyz = np.round(rotation_from_yaw(yaw0, up).reshape(E, 4), 7)
    radius = np.round(settings.sampler.goal_radius_for(geodesic), 3)
    return _RouteGeometry(corners=corners, corners_nav=corners_nav, geodesic=geodesic, yaw0=yaw0,
                          yaw_goal=yaw_goal, q_wxyz=q_wxyz, radius=radius)


def _point_goal_polar(pairs, R_ns: np.ndarray, yaw0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Point goal in polar form relative to the start pose (nav frame): rho [E] horizontal metres,
    phi [E] radians counter-clockwise from the start heading (left > 0)."""
    E = len(pairs.starts)
    d_nav = (pairs.goals - pairs.starts) @ R_ns.T if E else np.zeros((0, 3))
    rho = np.linalg.norm(d_nav[:, :2], axis=-1)
    phi = wrap_angle(np.arctan2(d_nav[:, 1], d_nav[:, 0]) - yaw0)
    return rho, phi


def _goal_images(scene, sampler: EndpointSampler, geo: _RouteGeometry, R_ns: np.ndarray,
                 settings: GeneratorSettings, goal_image_dir: Path) -> list[Path | None]:
    """Render one goal view per episode (at the goal, facing along the last path segment) into
    `goal_image_dir/<i:05d>.png`; -> the E written paths. Caller checks that images are wanted.

    The folder is written as one set (`atomic_dir`): a killed run leaves the earlier set or none, never
    some new views beside old ones."""
    E = len(geo.corners)
    if scene.gaussians_path is None:  # a LiDAR-only scene: episodes are valid, they just carry no goal view
        log.warning("no 3dgs.ply in the scene: %d goal image(s) skipped (episodes get no goal_image)", E)
        return [None] * E
    height = settings.goal_camera_height or float(np.clip(np.median(sampler.camera_heights), 0.3, 3.0))
    names = [f"{i:05d}.png" for i in range(E)]
    with atomic_dir(goal_image_dir) as tmp:
        render_goal_images(
            scene.gaussians_path, np.stack([c[-1] for c in geo.corners_nav]), geo.yaw_goal, R_ns,
            [tmp / n for n in names], height=height,
            width=settings.goal_image_width, image_height=settings.goal_image_height,
            hfov_deg=settings.goal_image_hfov_deg, lod_px=settings.goal_image_lod_px, device=settings.render_device,
            backend=settings.render_backend)
    return [goal_image_dir / n for n in names]


def _instruction_texts(scene, instructions: InstructionGenerator, geo: _RouteGeometry, dense, indoor,
                       R_ns: np.ndarray, goal_paths: list[Path | None], seed: int) -> list[str]:
    """One instruction per route. Each route gets its own child seed of `seed`, so a generator's
    randomness does not depend on how many episodes came before it."""
    E = len(geo.corners)
    child_seeds = np.random.SeedSequence(seed).spawn(E) if E else []
    routes = [Route(corners_nav=geo.corners_nav[i], dense_nav=dense[i] @ R_ns.T, indoor=indoor[i],
                    geodesic_distance=float(geo.geodesic[i]), seed=int(child_seeds[i].generate_state(1)[0]),
                    goal_image=goal_paths[i], scene_name=scene.name) for i in range(E)]
    texts = instructions(routes) if E else []
    if len(texts) != E:
        raise ValueError(f"instruction generator {getattr(instructions, 'name', instructions)!r} returned "
                         f"{len(texts)} texts for {E} routes")
    return texts


def environment_label(indoor: np.ndarray) -> str:
    """"indoor" when every expert location of a route is inside an indoor region, "outdoor" when none is, else
    "mixed" (the route goes through a door)."""
    indoor = np.asarray(indoor, dtype=bool)
    return "indoor" if indoor.all() else "outdoor" if not indoor.any() else "mixed"


def _assemble_episodes(scene, pairs, geo: _RouteGeometry, dense, indoor, splits: list[str], rho, phi,
                       goal_paths: list[Path | None], goal_image_base: Path | None, texts: list[str],
                       dec: int, R_ns: np.ndarray) -> list[Episode]:
    """Build and validate the `Episode` records (every written number rounded to `dec` places)."""
    episodes = []
    for i in range(len(geo.corners)):
        z = (np.asarray(dense[i]) @ R_ns.T)[:, 2] if len(dense[i]) else np.zeros(1)
        extras: dict[str, Any] = {
            "split": splits[i],
            "up_axis": scene.up_axis,
            "euclidean_distance": round(float(pairs.euclidean[i]), dec),
            "island": int(pairs.island[i]),
            "point_goal_polar": [round(float(rho[i]), dec), round(float(phi[i]), 6)],
            "environment": environment_label(indoor[i]),
            "elevation_change": round(float(z.max() - z.min()), 3),  # metres between the route's lowest and highest
        }
        if goal_paths[i] is not None:
            extras["goal_image"] = goal_paths[i].relative_to(goal_image_base).as_posix()
        ep = Episode(
            episode_id=i, scene_id=scene.name,
            start_position=geo.corners[i][0], start_rotation_wxyz=geo.q_wxyz[i],
            geodesic_distance=float(geo.geodesic[i]),
            goals=[Goal(position=geo.corners[i][-1], radius=float(geo.radius[i]))],
            instruction_text=texts[i],
            reference_path=geo.corners[i], gt_locations=np.round(dense[i], dec), gt_steps=int(len(dense[i]) - 1),
            extras=extras,
        )
        ep.validate(where=f"{scene.name}: episodes[{i}]")
        episodes.append(ep)
    return episodes


def generate_episodes(scene, navmesh, *, num_episodes: int, seed: int,
                      settings: GeneratorSettings | None = None,
                      instructions: InstructionGenerator | None = None,
                      goal_image_dir: Path | None = None, goal_image_base: Path | None = None,
                      progress: Callable[[int], None] | None = None) -> tuple[list[Episode], GenerationSummary]:
    """Sample `num_episodes` expert episodes on `navmesh` for `scene` (a `Scene`).

    Goal images are rendered into `goal_image_dir` (named `<episode_id:05d>.png`, replacing the folder
    as one set; the episode's `goal_image` extra is the path relative to `goal_image_base`, by default
    the folder above it) when it is given and `settings.goal_images` is on. `progress(n)` is called as episodes are accepted.
    Returns fewer episodes than asked if the sampler runs out of rounds (the summary says why).
    """
    settings = (settings or GeneratorSettings()).for_scene(scene)
    instructions = instructions or RuleBasedInstructions()
    if num_episodes < 0:
        raise ValueError(f"num_episodes must be >= 0, got {num_episodes}")
    t0 = time.perf_counter()
    # the draws from `rng` are, in this order: endpoint sampling, then the split permutation
    rng = np.random.default_rng(seed)
    R_ns = np.asarray(scene.nav_from_scene, dtype=np.float64)  # [3, 3]
    cams = scene.capture_positions()
    sampler = EndpointSampler(navmesh, cams, R_ns, settings.sampler,
                              camera_indoor=scene.is_indoor(cams) if settings.sampler.indoor_fraction > 0 else None)
    pairs = sampler.sample(num_episodes, rng, progress=progress)
    E = len(pairs.starts)

    dense, indoor = _dense_expert_locations(scene, navmesh, pairs.paths, R_ns, settings.step_size)
    geo = _route_geometry(pairs.paths, R_ns, scene.up_axis, settings)
    splits = assign_splits(E, settings.splits, rng)
    rho, phi = _point_goal_polar(pairs, R_ns, geo.yaw0)

    goal_paths: list[Path | None] = [None] * E
    if goal_image_dir is not None and settings.goal_images and E:
        goal_image_dir = Path(goal_image_dir)
        goal_paths = _goal_images(scene, sampler, geo, R_ns, settings, goal_image_dir)

    texts = _instruction_texts(scene, instructions, geo, dense, indoor, R_ns, goal_paths, seed)
    base = Path(goal_image_base) if goal_image_base is not None else \
        Path(goal_image_dir).parent if goal_image_dir is not None else None
    episodes = _assemble_episodes(scene, pairs, geo, dense, indoor, splits, rho, phi, goal_paths, base,
                                  texts, settings.decimals, R_ns)

    rej = {r: int(pairs.rejections.get(r, 0)) for r in REJECTION_REASONS}
    summary = GenerationSummary(
        scene=scene.name, requested=num_episodes, kept=E, candidates=pairs.candidates, rounds=pairs.rounds,
        rejections=rej, length_hist=length_histogram(geo.geodesic),
        splits={s: splits.count(s) for s in ("train", "val", "test")}, seconds=time.perf_counter() - t0)
    return episodes, summary


# --------------------------------------------------------------------------- file side


def navmesh_fingerprint(navmesh_path: Path | None) -> str:
    """sha256 over the navmesh arrays, not the .npz bytes: zip headers carry timestamps and the
    planner's `meta` record carries the bake time, neither of which changes a single episode."""
    h = hashlib.sha256()
    if navmesh_path is None or not Path(navmesh_path).is_file():
        return "none"
    with np.load(navmesh_path, allow_pickle=False) as z:
        for k in sorted(z.files):
            a = np.ascontiguousarray(z[k])
            if k == "meta" and a.dtype.kind == "U":
                try:
                    meta = json.loads(str(z[k][()]))
                except ValueError:
                    meta = None
                if isinstance(meta, dict):
                    meta = {mk: mv for mk, mv in meta.items() if "seconds" not in mk and "time" not in mk}
                    a = np.asarray(json.dumps(meta, sort_keys=True))
            h.update(k.encode()); h.update(str(a.dtype).encode()); h.update(str(a.shape).encode()); h.update(a.tobytes())
    return h.hexdigest()


def splat_fingerprint(scene, settings: GeneratorSettings) -> str:
    """sha256 of `3dgs.ply` when goal views are rendered from it ("none" otherwise): a changed splat
    changes every goal view, so it is part of the episodes' key."""
    path = getattr(scene, "gaussians_path", None)
    if not settings.goal_images or path is None or not Path(path).is_file():
        return "none"
    return file_sha256(path)


def args_hash(scene_name: str, num_episodes: int, seed: int, settings: GeneratorSettings,
              instruction_source: str, navmesh_hash: str, splat_hash: str = "none") -> str:
    payload = {"format": FORMAT_VERSION, "scene": scene_name, "num_episodes": int(num_episodes), "seed": int(seed),
               "settings": settings.to_dict(), "instructions": instruction_source, "navmesh": navmesh_hash,
               "splat": splat_hash}
    return json_digest(payload)


def goal_images_digest(root: Path, episodes) -> str | None:
    """One hash over every goal view the episodes name (their bytes, in episode order); None when one is
    missing or none is named."""
    h = hashlib.sha256()
    named = [e.extras["goal_image"] for e in episodes if "goal_image" in e.extras]
    for name in named:
        p = root / name
        if not p.is_file():
            return None
        h.update(name.encode()); h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()[:16] if named else None


def _up_to_date(out: Path, digest: str) -> list[Episode] | None:
    """The episodes of `out` if it was written with the same args hash and its goal views are the ones
    it was written with (same bytes), so a view replaced or left by another run is never taken."""
    if not out.is_file():
        return None
    try:
        f = load_episode_file(out)
    except (EpisodeFormatError, OSError):
        return None
    gen = f.extras.get("generator", {})
    if gen.get("args_hash") != digest:
        return None
    if goal_images_digest(out.parent, f.episodes) != gen.get("goal_images_digest"):
        return None
    return f.episodes


class EmptyEpisodeSetError(WanderlandInputError):
    """No episode survived: nothing is written (an empty episodes file would train and evaluate on nothing)."""


#: what to change when one rejection reason took every candidate (the navmesh, not the sampler, is the
#: usual cause: an agent radius that erodes every walkway leaves only crumbs off which nothing reaches)
_REMEDY = {
    "off_mesh": "the drawn points fall off the navmesh",
    "not_near_camera": "no navmesh lies within generator.sampler.camera_radius of a capture camera",
    "different_island": "start and goal never share a navmesh island",
    "unreachable": "the planner finds no path between candidates",
    "too_short": "no route reaches generator.sampler.min_geodesic",
    "too_long": "every route exceeds generator.sampler.max_geodesic",
}


def _why_no_episodes(scene, navmesh, summary: GenerationSummary | None, settings: GeneratorSettings,
                     requested: int) -> str:
    """One sentence with the navmesh's figures and the rejection that dominated (summary None: nothing was
    drawn, the navmesh has no walkable area)."""
    islands = sorted(navmesh.islands, key=lambda i: -i.area)
    ns = navmesh.settings
    nav = (f"the navmesh has {len(islands)} island(s), {navmesh.area:.1f} m^2 walkable"
           + (f", the largest {islands[0].area:.1f} m^2 reaching {islands[0].radius:.1f} m from its centre"
              if islands else "") + f" (agent_radius {ns.agent_radius:g} m, agent_max_climb {ns.agent_max_climb:g} m)")
    rej = summary.rejections if summary is not None else {}
    top = max(rej, key=rej.get) if any(rej.values()) else None
    why = (f"{_REMEDY.get(top, top)} ({top}: {rej[top]} of {summary.candidates} candidates)" if top else
           f"{summary.candidates} candidates were drawn" if summary is not None else "no walkable area to draw from")
    return (f"0 of {requested} episodes for scene {scene.name!r}, nothing written: {why}; {nav}. "
            "Small or scattered islands come from an agent radius too large for the walkways "
            "(navigation.navmesh.agent_radius) or a collision mesh without ground; else loosen generator.sampler "
            f"(camera_radius {settings.sampler.camera_radius:g}, min_geodesic {settings.sampler.min_geodesic:g})")


def _image_set(out: Path) -> Path | None:
    """The goal-view folder the episodes file at `out` names now (None: no file, no views, not ours)."""
    if not written_by_us(out):
        return None
    names = [e.extras["goal_image"] for e in load_episode_file(out).episodes if "goal_image" in e.extras]
    return (out.parent / names[0]).parent if names else None


def _drop_unused_image_set(out: Path, folder: Path | None, *, keep: Path) -> None:
    """Remove the views an earlier version of `out` used, unless another episodes file beside it names them."""

    if folder is None or folder == keep or not folder.is_dir() or folder.parent.parent != out.parent:
        return
    for other in out.parent.glob("*.json*"):
        if other != out and written_by_us(other) and _image_set(other) == folder:
            return
    shutil.rmtree(folder)
    log.info("%s: removed %s (the goal views of the file's previous version)", out, folder)


def refresh_if_stale(scene, path: Path, load_navmesh: Callable[[], Any]) -> bool:
    """Regenerate `path`, an episode file this project wrote, when the scene's navmesh (or, for goal views,
    its splat) is no longer the one it was generated on: same count, seed and recorded settings, new routes.
    A file someone else wrote, or one without a complete record, is left as it is. `load_navmesh()` gives the
    scene's navmesh (loaded only when the file is stale). -> whether it was rebuilt.

    Why: a changed navmesh (another navigation agent, a re-prepared scene) makes old routes wrong (a goal on
    another island, a path through a new wall), and the file's size alone cannot tell."""
    why = not_ours_because(path)
    if why is not None and not why.startswith("its "):  # not ours at all (no block, not an episodes file)
        return False
    gen = load_episode_file(path).extras.get("generator", {})
    try:
        settings = GeneratorSettings.from_dict(gen["settings"])
        num, seed, source = int(gen["num_episodes"]), int(gen["seed"]), gen["instructions"]
    except (KeyError, TypeError, ValueError):
        return False
    digest = args_hash(scene.name, num, seed, settings, source, navmesh_fingerprint(getattr(scene, "navmesh_path", None)),
                       splat_fingerprint(scene, settings))
    if gen.get("args_hash") == digest:
        return False
    if why is not None:  # our block survived a hand edit: the user's file now, kept; said, since its routes are stale
        log.warning("%s: %s was generated on another navmesh or splat, but %s; it is used as it is, never "
                    "regenerated in place (make_episodes writes fresh episodes beside it)", scene.name, path, why)
        return False
    if source != RuleBasedInstructions.name:  # instructions from a source this process cannot rebuild: said, kept
        log.warning("%s: %s was generated on another navmesh or splat, with instructions from %r, which this "
                    "process cannot regenerate; it is used as it is (regenerate it with that source)",
                    scene.name, path, source)
        return False
    log.warning("%s: %s was generated on another navmesh or splat; regenerating it (%d episodes, seed %d, "
                "its recorded settings)", scene.name, path, num, seed)
    write_scene_episodes(scene, load_navmesh(), path, num_episodes=num, seed=seed, settings=settings)
    return True


def write_scene_episodes(scene, navmesh, out: Path, *, num_episodes: int, seed: int,
                         settings: GeneratorSettings | None = None,
                         instructions: InstructionGenerator | None = None, force: bool = False,
                         progress: Callable[[int], None] | None = None) -> tuple[list[Episode], GenerationSummary]:
    """Generate and write `out` (atomic) with goal images in `out.parent / "goal_images"`.

    A rerun with the same scene navmesh, count, seed and settings finds the stored args hash and
    returns the file's episodes without regenerating (`summary.skipped`), unless `force`. A file at
    `out` that this project did not write is never replaced (unless `force`): the episodes go to
    `episodes.generated.json` beside it, goal images to `goal_images.generated/`, and
    `summary.out` (also logged) names the file used.
    """
    settings = (settings or GeneratorSettings()).for_scene(scene)
    instructions = instructions or RuleBasedInstructions()
    requested = Path(out)
    out = episodes_target(requested, force=force)
    digest = args_hash(scene.name, num_episodes, seed, settings, getattr(instructions, "name", type(instructions).__name__),
                       navmesh_fingerprint(getattr(scene, "navmesh_path", None)), splat_fingerprint(scene, settings))
    # one folder per episode set, named by its key: two episode files beside one scene, or a run killed
    # half-way, can never share or mix views
    image_dir = out.parent / ("goal_images" if out == requested else "goal_images.generated") / digest
    if not force:
        existing = _up_to_date(out, digest)
        if existing is not None:
            split_counts = {s: sum(e.split == s for e in existing) for s in ("train", "val", "test")}
            log.info("%s: episodes up to date in %s", scene.name, out)
            return existing, GenerationSummary(
                scene=scene.name, requested=num_episodes, kept=len(existing), candidates=0, rounds=0,
                rejections={}, length_hist=length_histogram([e.geodesic_distance for e in existing]),
                splits=split_counts, skipped=True, out=str(out))
    if num_episodes > 0 and navmesh.area <= 0:
        raise EmptyEpisodeSetError(_why_no_episodes(scene, navmesh, None, settings, num_episodes), path=out)
    episodes, summary = generate_episodes(
        scene, navmesh, num_episodes=num_episodes, seed=seed, settings=settings, instructions=instructions,
        goal_image_dir=image_dir, goal_image_base=out.parent, progress=progress)
    extras = {
        "generator": {"name": GENERATOR_NAME, "format": FORMAT_VERSION, "args_hash": digest,
                      "num_episodes": num_episodes, "seed": seed, "instructions": instructions.name,
                      "settings": settings.to_dict(), "goal_images_digest": goal_images_digest(out.parent, episodes)},
        "summary": summary.to_dict(),
    }
    if num_episodes > 0 and not episodes:
        raise EmptyEpisodeSetError(_why_no_episodes(scene, navmesh, summary, settings, num_episodes), path=out)
    extras["generator"][WRITTEN_DIGEST] = _UNSTAMPED
    previous = _image_set(out)
    write_episode_bytes(out, _stamped(dump_episodes(episodes, extras, source=str(out))))
    _drop_unused_image_set(out, previous, keep=image_dir)
    summary.out = str(out)
    log.info("%s: %d episodes written to %s", scene.name, len(episodes), out)
    return episodes, summary
