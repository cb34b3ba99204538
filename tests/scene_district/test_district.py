"""Procedural districts: what a seed gives, read back from disk, and what the navmesh and episodes make of it."""

from __future__ import annotations

import hashlib
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from wanderland_nav.render.gaussians import Gaussians
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.district import EPISODE_SAMPLER, MARKER, SIZES, build_district, make_district
from wanderland_nav.scene.pointcloud import read_ply_points

SEED = 3  # the seed of the shared district fixture (conftest.py)


def _digests(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.md5(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _graph(seed: int) -> tuple:
    """The street graph of a seed, as a hashable value (node positions to the centimetre, edges, kinds)."""
    p = build_district(seed).plan
    nodes = [tuple(np.round(n, 2)) for n in p.nodes]
    return tuple(sorted(tuple(sorted((nodes[a], nodes[b]))) + (k,) for a, b, k in p.edges))


def test_products_and_meta(district_scene):
    root = district_scene
    for rel in ("images", "images_mask", "depth", "sparse/0/cameras.bin", "sparse/0/images.bin",
                "sparse/0/points3D.bin", "sparse/0/images_val.bin", "nvs_split/train.txt", "nvs_split/val.txt",
                "raw_pcd.ply", "3dgs.ply", "transforms.json", "scene_meta.json", "gt_mesh.ply", MARKER):
        assert (root / rel).exists(), rel
    meta = json.loads((root / "scene_meta.json").read_text())
    gen = meta["generator"]
    assert meta["up_axis"] == "-y" and meta["environment"] == "mixed" and meta["episode_sampler"] == EPISODE_SAMPLER
    assert gen["sh_degree"] == 3 and gen["size"] == "small" and gen["seed"] == SEED
    d = gen["district"]
    assert 5000.0 <= d["area_m2"] <= 10000.0
    kinds = {b["kind"].split("_")[0] for b in d["blocks"]}
    assert {"building", "plaza", "park"} <= kinds, kinds
    assert any(b["kind"] in ("building_lobby", "building_hall", "building_arcade") for b in d["blocks"])
    assert len(meta["indoor_regions"]) >= 1 and d["parked_cars"] > 0
    scene = load_scene(root)
    assert scene.up_axis == "-y" and len(scene.cameras) == gen["counts"]["images"]
    splits = Counter(c.split for c in scene.cameras)
    assert splits["train"] == gen["counts"]["train_images"] > 0 and splits["val"] == gen["counts"]["val_images"] > 0
    g = Gaussians.load(root / "3dgs.ply")
    assert g.sh_degree == 3 and len(g) == gen["counts"]["gaussians"]
    assert len(read_ply_points(root / "raw_pcd.ply").xyz) == gen["counts"]["lidar_points"]
    # capture cameras stand inside the district, some inside a building
    cams = scene.capture_positions() @ scene.nav_from_scene.T
    W, H = d["extent_m"]
    assert (cams[:, 0] > 0).all() and (cams[:, 0] < W).all() and (cams[:, 1] > 0).all() and (cams[:, 1] < H).all()
    assert scene.is_indoor(scene.capture_positions()).sum() >= 4


def test_same_seed_same_bytes_and_refusals(district_scene, tmp_path):
    again = make_district(tmp_path / "again", seed=SEED, size="small")
    assert _digests(again) == _digests(district_scene)
    assert make_district(again, seed=SEED, size="small") == again  # a rerun finds it up to date
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="not a district"):
        make_district(foreign, seed=0)
    with pytest.raises(ValueError, match="size must be one of"):
        make_district(tmp_path / "x", seed=0, size="huge")


def test_seeds_give_different_street_graphs_and_blocks():
    graphs = [_graph(s) for s in range(12)]
    assert len(set(graphs)) == len(graphs)
    topologies = {tuple(sorted(Counter(k for e in g for k in e[:2]).values())) for g in graphs}
    assert len(topologies) >= 3, "seeds differ only in street positions, not in how the streets connect"
    # every seed has the walkable kinds, and the plaza's terraces give 0.5-4 m of elevation
    for s in range(12):
        d = build_district(s)
        kinds = {k.split("_")[0] for k in d.block_kinds}
        assert {"building", "plaza", "park"} <= kinds or {"building", "park"} <= kinds, (s, d.block_kinds)
        z = d.layout.walk_height.z
        assert 0.5 <= float(z.max() - z.min()) <= 4.0, s
    assert SIZES["paper"].splat_spacing < SIZES["small"].splat_spacing


def test_navmesh_connected_with_levels_and_a_reachable_indoor(prepared_district):
    scene, nm, _ = prepared_district
    isl = sorted(nm.islands, key=lambda i: -i.area)
    assert nm.area > 4000.0 and isl[0].area >= 0.9 * nm.area, [i.area for i in isl]
    R = scene.nav_from_scene
    local = np.concatenate([nm.verts_xy, nm.verts_z[:, None]], -1)
    import torch

    v = nm.to_scene(torch.as_tensor(local, dtype=torch.float64)).numpy() @ R.T
    assert np.ptp(v[:, 2]) >= 0.5, "no elevation change on the navmesh"
    reg = scene.indoor_regions[0]
    c = np.asarray(reg["polygon_xy"]).mean(0)
    inside = np.array([[c[0], c[1], 0.15]]) @ R  # nav -> scene
    outside = scene.capture_positions()[~scene.is_indoor(scene.capture_positions())][:1]
    assert np.isfinite(float(nm.geodesic_distance(nm.snap_point(outside, max_distance=3.0), nm.snap_point(inside))[0]))


def test_episodes_of_the_papers_kind(prepared_district):
    scene, _, episodes = prepared_district
    assert len(episodes) == 60
    labels = Counter(e.extras["environment"] for e in episodes)
    assert set(labels) <= {"indoor", "outdoor", "mixed"} and labels["indoor"] >= 1 and labels["outdoor"] >= 1
    for e in episodes:
        inside = scene.is_indoor(np.asarray(e.gt_locations))
        want = "indoor" if inside.all() else "outdoor" if not inside.any() else "mixed"
        assert e.extras["environment"] == want
        assert e.gt_steps < 1000 and "goal_image" in e.extras and e.instruction_text
    geo = np.array([e.geodesic_distance for e in episodes])
    assert geo.min() >= EPISODE_SAMPLER["min_geodesic"] and geo.max() >= 80.0
    assert max(e.extras["elevation_change"] for e in episodes) >= 0.5


def test_district_configs_key_folders_and_split_seeds():
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config
    from wanderland_nav.preparation.scene_set import jobs_for
    from wanderland_nav.scene.sets import scene_set_from_config

    a = typed_config(compose_config("prepare", ["scene=district", "scene.seed=7", "scene.size=paper"]), PrepareConfig)
    b = typed_config(compose_config("prepare", ["scene=district"]), PrepareConfig)
    assert (a.scene.generator, a.scene.path, b.scene.path) == ("district", "data/scenes/district/s7_paper",
                                                               "data/scenes/district/s0_small")
    full = scene_set_from_config(typed_config(compose_config("prepare", ["scene=district_set"]), PrepareConfig).scene)
    test = scene_set_from_config(typed_config(compose_config("prepare", ["scene=district_test"]), PrepareConfig).scene)
    split_seeds = {sp: {s for e, s in zip(full, full.demo["seeds"]) if e.split == sp} for sp in ("train", "val", "test")}
    assert [len(split_seeds[s]) for s in ("train", "val", "test")] == [8, 2, 4]
    assert not (split_seeds["train"] & split_seeds["test"]) and not (split_seeds["train"] & split_seeds["val"])
    assert set(test.demo["seeds"]) == split_seeds["test"] and {e.split for e in test} == {"test"}
    jobs = jobs_for(test)
    assert [(j.demo_generator, j.demo_preset, j.demo_seed) for j in jobs] == [
        ("district", "small", s) for s in test.demo["seeds"]]
    with pytest.raises(ValueError, match="generator"):
        typed_config(compose_config("prepare", ["scene=district", "scene.generator=city"]), PrepareConfig)


def test_blocked_lidar_and_chunked_shading_change_no_byte(monkeypatch):
    """The paper size casts its LiDAR a block of scans at a time and shades in chunks (memory); both only
    regroup per-ray work, so any block size gives the same cloud."""
    from wanderland_nav.scene.demo import lidar, textures
    from wanderland_nav.scene.demo.layout import build_layout
    from wanderland_nav.scene.demo.raycast import RayCaster

    lay = build_layout(0)
    caster = RayCaster(lay.vertices, lay.faces)
    sensors = np.array([[x, -9.0, 1.9] for x in np.linspace(-20.0, 20.0, 9)])
    ref = lidar.scan(caster, lay, sensors, lidar.ScanPattern(rays=300), 20.0, 0.01, seed=1)
    monkeypatch.setattr(lidar, "CAST_BLOCK_RAYS", 700)
    monkeypatch.setattr(textures, "SHADE_CHUNK", 257)
    out = lidar.scan(caster, lay, sensors, lidar.ScanPattern(rays=300), 20.0, 0.01, seed=1)
    for a, b in zip(ref, out):
        np.testing.assert_array_equal(a, b)
