"""Scene sets: many scenes named by one manifest, so every stage can run over a set as over one scene.

A manifest is one of
  * a folder of scenes: every sub-folder that holds scene data (`3dgs.ply`, `sparse/`, `scene.ply`,
    `raw_pcd.ply`, `transforms.json`, `lidar/`) is a scene whose id is the folder name;
  * a list file, as Wanderland ships them (`train_scenes_v1.txt`, `eval_scenes_v1.txt`): one scene id
    a line (`#` comments and blank lines skipped), resolved against a data root (default: the list
    file's folder); the split is read from the file name prefix (`train_` / `eval_` / `val_` / `test_`);
  * the public manifest CSV: columns `scene_id`, `quality_tier` (showcase | evaluation_ready |
    training_ready), optional `manifest_version`, `data_path` (relative to the data root) and `split`.

Sets filter by quality tier and split (`SceneSet.filter`). Scene folders are not read here: a set
may name scenes that are still to be built (the demo set) or prepared (`wanderland_nav.preparation.scene_set`);
`SceneSet.missing()` lists them. Bad rows fail with the file and line named.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Iterator, Sequence

from wanderland_nav.scene.generated import make_generated_scene

TIERS = ("showcase", "evaluation_ready", "training_ready")
SCENE_MARKERS = ("3dgs.ply", "sparse", "scene.ply", "raw_pcd.ply", "transforms.json", "lidar")
_ID = re.compile(r"^[A-Za-z0-9_.\-]+$")
_SPLIT_PREFIX = re.compile(r"^(train|eval|val|test)_")


class ManifestError(ValueError):
    """A manifest row or file that cannot be read; the message names the file and line."""


@dataclass(frozen=True)
class SceneEntry:
    scene_id: str
    path: Path  # the scene folder (may not exist yet)
    quality_tier: str | None = None
    split: str | None = None
    manifest_version: str | None = None


@dataclass
class SceneSet:
    """An ordered list of scenes (manifest order, ids unique)."""

    entries: list[SceneEntry]
    source: str = ""  # where the set came from, for messages
    demo: dict = field(default_factory=dict)  # {"seeds": [...], "preset": ...} for the procedural demo set

    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self) -> Iterator[SceneEntry]:
        return iter(self.entries)

    @property
    def ids(self) -> list[str]:
        return [e.scene_id for e in self.entries]

    @property
    def paths(self) -> list[Path]:
        return [e.path for e in self.entries]

    def filter(self, *, tiers: Iterable[str] | None = None, split: str | None = None) -> "SceneSet":
        """Scenes whose tier is in `tiers` and whose split is `split` (None: no condition)."""
        tiers = None if tiers is None else set(_check_tiers(tiers, self.source))
        kept = [e for e in self.entries
                if (tiers is None or e.quality_tier in tiers) and (split is None or e.split == split)]
        return self._kept(kept)

    def restrict(self, ids: Sequence[str]) -> "SceneSet":
        """The scenes named in `ids` (e.g. a split list), in this set's order; unknown ids raise."""
        unknown = sorted(set(ids) - set(self.ids))
        if unknown:
            raise ManifestError(f"{self.source}: scene ids not in the set: {unknown[:5]}")
        wanted = set(ids)
        return self._kept([e for e in self.entries if e.scene_id in wanted])

    def _kept(self, kept: list[SceneEntry]) -> "SceneSet":
        """This set with the entries `kept` only, a procedural set's seeds kept in step with them."""
        demo = self.demo
        if demo.get("seeds"):
            seed_of = dict(zip(self.ids, demo["seeds"]))
            demo = {**demo, "seeds": [seed_of[e.scene_id] for e in kept]}
        return replace(self, entries=kept, demo=demo)

    def missing(self) -> list[SceneEntry]:
        return [e for e in self.entries if not e.path.is_dir()]


def _check_tiers(tiers: Iterable[str], where: str) -> list[str]:
    tiers = [tiers] if isinstance(tiers, str) else list(tiers)
    bad = [t for t in tiers if t not in TIERS]
    if bad:
        raise ManifestError(f"{where}: quality tier(s) {bad} not in {list(TIERS)}")
    return tiers


def _unique(entries: list[SceneEntry], where: list[str]) -> list[SceneEntry]:
    seen: dict[str, str] = {}
    for e, loc in zip(entries, where):
        if e.scene_id in seen:
            raise ManifestError(f"{loc}: scene_id {e.scene_id!r} repeated (first at {seen[e.scene_id]})")
        seen[e.scene_id] = loc
    return entries


def _check_id(scene_id: str, loc: str) -> str:
    if not _ID.match(scene_id):
        raise ManifestError(f"{loc}: scene_id {scene_id!r} is not a folder name (letters, digits, _ . -)")
    return scene_id


def is_scene_folder(path: Path) -> bool:
    return path.is_dir() and any((path / m).exists() for m in SCENE_MARKERS)


def scene_set_from_folder(folder: str | Path) -> SceneSet:
    folder = Path(folder)
    if not folder.is_dir():
        raise ManifestError(f"{folder}: not a folder")
    entries = [SceneEntry(p.name, p) for p in sorted(folder.iterdir()) if is_scene_folder(p)]
    if not entries:
        raise ManifestError(f"{folder}: no scene folders inside (a scene holds one of {list(SCENE_MARKERS)})")
    return SceneSet(entries, source=str(folder))


def scene_set_from_list(list_file: str | Path, data_root: str | Path | None = None) -> SceneSet:
    list_file = Path(list_file)
    root = Path(data_root) if data_root is not None else list_file.parent
    m = _SPLIT_PREFIX.match(list_file.name)
    split = m.group(1) if m else None
    entries, where = [], []
    for n, line in enumerate(list_file.read_text().splitlines(), 1):
        sid = line.split("#", 1)[0].strip()
        if not sid:
            continue
        loc = f"{list_file}:{n}"
        entries.append(SceneEntry(_check_id(sid, loc), root / sid, split=split))
        where.append(loc)
    if not entries:
        raise ManifestError(f"{list_file}: no scene ids")
    return SceneSet(_unique(entries, where), source=str(list_file))


def scene_set_from_csv(csv_file: str | Path, data_root: str | Path | None = None) -> SceneSet:
    csv_file = Path(csv_file)
    root = Path(data_root) if data_root is not None else csv_file.parent
    with csv_file.open(newline="") as f:
        reader = csv.DictReader(f)
        cols = reader.fieldnames or []
        for c in ("scene_id", "quality_tier"):
            if c not in cols:
                raise ManifestError(f"{csv_file}:1: column {c!r} missing (header: {cols})")
        entries, where = [], []
        for row in reader:
            loc = f"{csv_file}:{reader.line_num}"
            sid = _check_id((row.get("scene_id") or "").strip(), loc)
            tier = (row.get("quality_tier") or "").strip()
            if tier not in TIERS:
                raise ManifestError(f"{loc}: quality_tier {tier!r} not in {list(TIERS)}")
            rel = (row.get("data_path") or "").strip() or sid
            split = (row.get("split") or "").strip() or None
            entries.append(SceneEntry(sid, root / rel, quality_tier=tier, split=split,
                                      manifest_version=(row.get("manifest_version") or "").strip() or None))
            where.append(loc)
    if not entries:
        raise ManifestError(f"{csv_file}: no rows")
    return SceneSet(_unique(entries, where), source=str(csv_file))


def load_scene_set(source: str | Path, *, data_root: str | Path | None = None, tiers: Iterable[str] | None = None,
                   split: str | None = None) -> SceneSet:
    """A folder of scenes, a `.txt` list file or a `.csv` manifest, filtered by tier and split."""
    p = Path(source)
    if p.is_dir():
        s = scene_set_from_folder(p)
    elif not p.is_file():
        raise ManifestError(f"{p}: scene manifest not found (a folder of scenes, a .txt list or a .csv manifest)")
    elif p.suffix.lower() == ".csv":
        s = scene_set_from_csv(p, data_root)
    else:
        s = scene_set_from_list(p, data_root)
    return s.filter(tiers=tiers, split=split) if (tiers is not None or split is not None) else s


def demo_scene_set(root: str | Path, seeds: Sequence[int] = (0, 1, 2), preset: str = "tiny", *,
                   generator: str = "demo", seed_splits: dict | None = None) -> SceneSet:
    """A procedural generator's scenes at several seeds, `root/seed_<k>` (the demo block at `preset`, or districts
    with `generator="district"` and `preset` their size); built on demand by `build_demo_scenes`. `seed_splits`
    (`{split: [seeds]}`) gives each seed its split (default train); a seed in two splits is refused."""
    root = Path(root)
    split_of: dict[int, str] = {}
    for split, ks in (seed_splits or {}).items():
        for k in ks:
            if int(k) in split_of:
                raise ManifestError(f"scene.set.seed_splits: seed {k} is in both {split_of[int(k)]} and {split}")
            split_of[int(k)] = str(split)
    extra = sorted(set(split_of) - {int(k) for k in seeds})
    if extra:
        raise ManifestError(f"scene.set.seed_splits: seeds {extra} are not in scene.set.seeds")
    prefix = "demo" if generator == "demo" else generator
    entries = [SceneEntry(f"{prefix}_seed_{int(k)}", root / f"seed_{int(k)}", split=split_of.get(int(k), "train"))
               for k in seeds]
    return SceneSet(entries, source=f"{prefix} set {root}",
                    demo={"seeds": [int(k) for k in seeds], "preset": preset, "generator": generator})


def build_demo_scenes(scene_set: SceneSet) -> None:
    """Make the missing scenes of a procedural set (idempotent: existing builds return at once)."""
    for entry, seed in zip(scene_set.entries, scene_set.demo["seeds"]):
        make_generated_scene(entry.path, scene_set.demo.get("generator", "demo"), seed, scene_set.demo["preset"])


def scene_set_from_config(scene) -> SceneSet | None:
    """The set a `scene` group names (its `set` block, see conf/scene/demo_set.yaml; a typed
    `SceneGroup` or a mapping with attribute access), or None when it names a single scene (`scene.path`)."""
    s = getattr(scene, "set", None)
    if not s:
        return None
    if s.seeds is not None:
        generator = getattr(s, "generator", "demo") or "demo"
        preset = (getattr(s, "size", None) or "small") if generator == "district" else (s.preset or "tiny")
        out = demo_scene_set(s.root, s.seeds, preset, generator=generator, seed_splits=getattr(s, "seed_splits", None))
        return out.filter(split=s.split) if getattr(s, "split", None) else out
    if s.manifest is None:
        raise ManifestError("scene.set: neither `seeds` (demo scenes) nor `manifest` given")
    return load_scene_set(s.manifest, data_root=s.data_root, tiers=s.tiers, split=s.split)
