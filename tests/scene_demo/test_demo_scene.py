"""The procedural demo scene: what every other component relies on being true of it.

All checks read the files back from disk (in the -Y-up scene frame) rather than trusting the
generator's in-memory state, and compare them with independent computations (ray casts on the
written gt_mesh.ply, the loader, geometry helpers).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from wanderland_nav.geometry import nav_from_scene_rotation
from wanderland_nav.scene import load_scene
from wanderland_nav.scene.demo import MARKER, PRESETS, make_demo_scene
from wanderland_nav.scene.demo import layout as L
from wanderland_nav.scene.demo.raycast import RayCaster
from wanderland_nav.scene.pointcloud import read_ply_points

NAV = nav_from_scene_rotation("-y")  # scene -> nav (z up)


def _digests(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.md5(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scene(tiny_demo_scene):
    return load_scene(tiny_demo_scene)


@pytest.fixture(scope="module")
def gt_nav(tiny_demo_scene):
    """The written ground-truth mesh, rotated to the nav frame, with a ray caster."""
    m = trimesh.load(tiny_demo_scene / "gt_mesh.ply", process=False)
    v = np.asarray(m.vertices) @ NAV.T
    return v, np.asarray(m.faces), RayCaster(v, np.asarray(m.faces))


def _ground_z(caster, xy, z_from=30.0):
    """Height of the first surface below (x, y, z_from) (nav frame)."""
    xy = np.atleast_2d(np.asarray(xy, float))
    o = np.column_stack([xy, np.full(len(xy), z_from)])
    t, tri = caster.cast(o, np.tile([0.0, 0.0, -1.0], (len(xy), 1)))
    assert (tri >= 0).all(), f"no surface under {xy[tri < 0]}"
    return z_from - t


# --------------------------------------------------------------------------- build behaviour


def test_folder_layout_and_meta(tiny_demo_scene):
    root = tiny_demo_scene
    for rel in ("images", "images_mask", "depth", "sparse/0/cameras.bin", "sparse/0/images.bin",
                "sparse/0/points3D.bin", "sparse/0/images_val.bin", "nvs_split/train.txt", "nvs_split/val.txt",
                "raw_pcd.ply", "3dgs.ply", "transforms.json", "scene_meta.json", "gt_mesh.ply", MARKER):
        assert (root / rel).exists(), rel
    meta = json.loads((root / "scene_meta.json").read_text())
    assert meta["up_axis"] == "-y" and meta["environment"] == "mixed"
    (reg,) = meta["indoor_regions"]
    assert len(reg["polygon_xy"]) == 4 and reg["z_min"] < L.SIDEWALK_Z < L.LOBBY_TOP <= reg["z_max"]
    tj = json.loads((root / "transforms.json").read_text())
    assert {"fl_x", "fl_y", "cx", "cy", "w", "h", "frames"} <= set(tj)
    assert tj["w"] == PRESETS["tiny"].image_size and len(tj["frames"]) == meta["generator"]["counts"]["images"]
    assert not list(root.parent.glob(f".{root.name}.*")), "temporary build folders left behind"


def test_deterministic_idempotent_and_replaces_other_builds(tiny_demo_scene, tmp_path):
    ref = _digests(tiny_demo_scene)
    out = tmp_path / "copy"
    shutil.copytree(tiny_demo_scene, out)
    stamp = (out / "3dgs.ply").stat().st_mtime_ns
    t0 = time.perf_counter()
    assert make_demo_scene(out, seed=0, preset="tiny") == out
    assert time.perf_counter() - t0 < 0.5 and (out / "3dgs.ply").stat().st_mtime_ns == stamp  # cached, untouched
    # pretend the folder holds another build: it is rebuilt whole, byte-identical to the reference,
    # and files derived from the old build (a navmesh) do not survive
    marker = json.loads((out / MARKER).read_text())
    (out / MARKER).write_text(json.dumps({**marker, "args_hash": "something-else"}))
    (out / "navmesh.npz").write_bytes(b"stale")
    (out / "images" / "left" / "00000.png").write_bytes(b"garbage")
    make_demo_scene(out, seed=0, preset="tiny")
    assert _digests(out) == ref
    assert not list(tmp_path.glob(".copy.*")), "temporary build folders left behind"


def test_seed_changes_details_not_structure():
    a, b = L.build_layout(0), L.build_layout(1)
    assert a.faces.shape == b.faces.shape and (a.face_material == b.face_material).all()
    assert not np.allclose(a.vertices, b.vertices)  # trees, furniture and the car move a little
    assert np.abs(a.vertices - b.vertices).max() < 2.0


def test_refuses_foreign_folder_and_bad_preset(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep me")
    with pytest.raises(FileExistsError, match="notes|demo scene"):
        make_demo_scene(tmp_path / "mine", preset="tiny")
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep me"
    with pytest.raises(ValueError, match="preset"):
        make_demo_scene(tmp_path / "x", preset="huge")


# --------------------------------------------------------------------------- geometry and frames


def test_levels_kerb_stairs_ramp_and_canopy(gt_nav):
    _, _, c = gt_nav
    z = _ground_z(c, [(0.0, -16.0), (0.0, -9.0), (-15.0, 10.0), (15.0, 2.0)], z_from=3.0)
    np.testing.assert_allclose(z, [L.STREET_Z, L.SIDEWALK_Z, L.PLAZA_Z, L.SIDEWALK_Z], atol=1e-5)  # float32 PLY
    assert L.PLAZA_Z - L.SIDEWALK_Z >= 1.0  # an elevation change a navmesh must route around
    # stairs: every riser 0.15..0.18 m (walkable with max climb 0.9), monotone up to the plaza
    y = np.linspace(-1.0, 2.5, 400)
    zs = _ground_z(c, np.column_stack([np.full_like(y, -11.0), y]), z_from=5.0)
    steps = np.diff(zs)[np.abs(np.diff(zs)) > 1e-4]
    assert len(steps) == L.N_RISERS and (steps > 0.15).all() and (steps < 0.18).all()
    # ramp: a constant slope under 12 degrees, joining both levels
    y = np.linspace(-4.9, 1.9, 50)
    zr = _ground_z(c, np.column_stack([np.full_like(y, -24.0), y]), z_from=5.0)
    slope = np.degrees(np.arctan(np.diff(zr) / np.diff(y)))
    assert np.ptp(slope) < 1e-3 and 5.0 < slope[0] < 12.0
    # tree canopy: the first surface above a walker near a trunk is more than 2.5 m up
    o = np.array([[-6.0 + 1.0, -10.7, L.SIDEWALK_Z + 0.1]])
    t, tri = c.cast(o, np.array([[0.0, 0.0, 1.0]]))
    assert tri[0] >= 0 and t[0] > 2.5
    # lobby: a ceiling at LOBBY_TOP over the indoor region, open sky over the street
    t, tri = c.cast(np.array([[15.0, 2.0, 1.0], [0.0, -16.0, 1.0]]), np.array([[0.0, 0.0, 1.0]] * 2))
    assert tri[0] >= 0 and abs(1.0 + t[0] - L.LOBBY_TOP) < 1e-5 and tri[1] < 0


def test_up_axis_is_minus_y_on_disk(scene, tiny_demo_scene):
    assert scene.up_axis == "-y"
    pts = scene.points
    assert np.median(pts[:, 1]) < 0.5  # heights are -y: most points at or above the ground (y <= ~0)
    q = pts @ NAV.T
    assert q[:, 2].min() > -0.2 and np.quantile(q[:, 2], 0.01) > -0.05  # nothing under the street
    # camera image "down" (OpenCV +y) points along scene +y, i.e. gravity, within the rig's tilt
    down = np.stack([c.world_from_cam[:3, 1] for c in scene.cameras])
    assert (down[:, 1] > np.cos(np.radians(10))).all()
    # rig height 1.5 m above the walked surface (the rig follows stairs and ramp)
    cc = scene.camera_centers() @ NAV.T
    h = cc[:, 2] - L.walk_height(cc[:, :2])
    assert np.all(np.abs(h - 1.5) < 0.2)


# --------------------------------------------------------------------------- images, depth, split


def test_images_carry_texture_detail(scene):
    for cam in scene.cameras[::7]:
        img = np.asarray(Image.open(cam.image_path)).astype(np.float32) / 255
        mask = np.asarray(Image.open(cam.mask_path)) > 0
        assert img.shape == (cam.height, cam.width, 3) and mask.mean() > 0.3
        g = img.mean(-1)
        lap = np.abs(4 * g[1:-1, 1:-1] - g[:-2, 1:-1] - g[2:, 1:-1] - g[1:-1, :-2] - g[1:-1, 2:])
        assert g[mask].std() > 0.04, cam.name
        assert lap[mask[1:-1, 1:-1]].mean() > 0.02, cam.name  # local contrast, not flat material colours


def test_depth_matches_mesh(scene, gt_nav):
    _, _, c = gt_nav
    for cam in scene.cameras[::11]:
        dep = np.asarray(Image.open(cam.depth_path)).astype(np.float64) / 1000.0
        mask = np.asarray(Image.open(cam.mask_path)) > 0
        np.testing.assert_array_equal(dep > 0, mask)
        rng = np.random.default_rng(0)
        v, u = rng.integers(0, cam.height, 300), rng.integers(0, cam.width, 300)
        d_cam = np.linalg.solve(cam.K, np.stack([u + 0.5, v + 0.5, np.ones(300)]))  # [3, 300], z = 1
        T = cam.world_from_cam
        dirs = (NAV @ T[:3, :3] @ d_cam).T
        n = np.linalg.norm(dirs, axis=1)
        t, tri = c.cast(np.tile(NAV @ T[:3, 3], (300, 1)), dirs / n[:, None])
        z = np.where(tri >= 0, t / n, 0.0)
        np.testing.assert_allclose(dep[v, u], z, atol=2e-3)


def test_val_path_is_extrapolation_with_stereo_pairs(scene, tiny_demo_scene):
    tr, va = scene.camera_centers("train"), scene.camera_centers("val")
    assert len(tr) and len(va)
    dmin = np.linalg.norm(va[:, None] - tr[None], axis=-1).min(1)
    assert dmin.min() > 3.0  # little overlap: every val view is metres from every training view
    names = {c.name: c for c in scene.cameras}
    val_txt = (tiny_demo_scene / "nvs_split" / "val.txt").read_text().split()
    assert sorted(val_txt) == sorted(c.name for c in scene.cameras if c.split == "val")
    for c in scene.cameras:
        assert c.side in ("left", "right")
        if c.side == "left":
            r = names[c.name.replace("left/", "right/")]
            np.testing.assert_allclose(np.linalg.norm(r.world_from_cam[:3, 3] - c.world_from_cam[:3, 3]), 0.3, atol=1e-9)
            # the right camera is on the camera's +x side
            assert (r.world_from_cam[:3, 3] - c.world_from_cam[:3, 3]) @ c.world_from_cam[:3, 0] > 0.29


# --------------------------------------------------------------------------- LiDAR cloud, splats, regions


def test_lidar_cloud_on_surface_near_trajectory_and_only_seen(scene, tiny_demo_scene, gt_nav):
    v, f, _ = gt_nav
    pc = read_ply_points(tiny_demo_scene / "raw_pcd.ply", require_color=True)
    assert len(pc) == json.loads((tiny_demo_scene / "scene_meta.json").read_text())["generator"]["counts"]["lidar_points"]
    q = pc.xyz.astype(np.float64) @ NAV.T
    cc = scene.camera_centers() @ NAV.T
    sub = q[np.random.default_rng(0).choice(len(q), 3000, replace=False)]
    d_traj = np.linalg.norm(sub[:, None] - cc[None], axis=-1).min(1)
    assert d_traj.max() < PRESETS["tiny"].lidar_range + 3.0  # range-limited around the rig path
    _, dist, _ = trimesh.proximity.closest_point(trimesh.Trimesh(v, f, process=False), sub[:1000])
    assert np.median(dist) < 0.012 and np.quantile(dist, 0.99) < 0.05  # ~1 cm range noise
    roof = (q[:, 0] > L.BUILDING[0] + 0.5) & (q[:, 0] < L.BUILDING[1] - 0.5) & (q[:, 1] > L.BUILDING[2] + 0.5) \
        & (q[:, 1] < L.BUILDING[3] - 0.5) & (q[:, 2] > L.BUILDING_TOP - 0.1)
    assert not roof.any()  # the roof is never seen from the ground
    assert len(np.unique(pc.rgb, axis=0)) > 100  # coloured from textures


def test_splats_are_flat_on_the_surface_inria_format(tiny_demo_scene, gt_nav):
    from wanderland_nav.render import Gaussians
    from wanderland_nav.geometry import quat_to_rotmat

    g = Gaussians.load(tiny_demo_scene / "3dgs.ply")
    assert len(g) > 1000 and g.sh_degree == 0
    s = g.log_scales.exp()
    assert (s.min(1).values < 0.005).all() and (s.max(1).values > 0.05).all()  # flat discs
    rgb = g.sh_dc * 0.28209479177387814 + 0.5
    assert rgb.min() >= -1e-4 and rgb.max() <= 1 + 1e-4 and rgb.std() > 0.05
    v, f, c = gt_nav
    idx = np.random.default_rng(1).choice(len(g), 500, replace=False)
    means = g.means[idx].double().numpy() @ NAV.T
    R = quat_to_rotmat(g.quats[idx].double()).numpy()
    n = np.einsum("ij,njk->nik", NAV, R)[:, :, int(s[0].argmin())]  # the thin axis, nav frame
    _, dist, tri = trimesh.proximity.closest_point(trimesh.Trimesh(v, f, process=False), means)
    assert dist.max() < 1e-3  # centres on the ground-truth surface
    fn = c.normals[tri]
    assert np.quantile(np.abs(np.einsum("ni,ni->n", n, fn)), 0.02) > 0.99  # aligned with the face


def test_indoor_region(scene, tiny_demo_scene):
    SN = NAV.T  # nav -> scene
    pts_nav = np.array([[15.0, 2.0, L.SIDEWALK_Z], [24.0, 12.0, 1.0], [0.0, -9.0, L.SIDEWALK_Z],
                        [-15.0, 10.0, L.PLAZA_Z], [15.0, 2.0, 8.0], [11.2, -7.0, L.SIDEWALK_Z]])
    np.testing.assert_array_equal(scene.is_indoor(pts_nav @ SN.T), [True, True, False, False, False, False])
    # cameras of the lobby loop that are inside the building footprint are indoor; street ones are not
    cc = scene.camera_centers()
    ind = scene.is_indoor(cc)
    q = cc @ NAV.T
    assert ind.any() and (~ind).any()
    assert not ind[q[:, 1] < L.BUILDING[2]].any()


@pytest.mark.slow
def test_splat_render_looks_like_the_raycast_images(scene):
    """The splats reproduce the ray-cast views (PSNR on geometry pixels; tiny splats are 0.35 m apart)."""
    import torch

    from wanderland_nav.render import Gaussians, render

    g = Gaussians.load(scene.gaussians_path)
    cams = [c for c in scene.cameras if c.split == "val"][::6]
    cfw = torch.tensor(np.stack([np.linalg.inv(c.world_from_cam) for c in cams]), dtype=torch.float32)
    K = torch.tensor(np.stack([c.K for c in cams]), dtype=torch.float32)
    with torch.no_grad():
        out = render(g, cfw, K, cams[0].width, cams[0].height, render_mode="RGB")
    gt = np.stack([np.asarray(Image.open(c.image_path)) for c in cams]).astype(np.float32) / 255
    m = np.stack([np.asarray(Image.open(c.mask_path)) for c in cams]) > 0
    mse = ((out.rgb.numpy() - gt) ** 2).mean(-1)[m].mean()
    assert -10 * np.log10(mse) > 17.0
    assert (out.alpha[..., 0].numpy()[m] > 0.5).mean() > 0.95


def test_raycast_backends_agree():
    """Embree's hits against the dependency-free numpy reference, on rays from the capture rig."""
    from wanderland_nav.scene.demo import capture

    lay = L.build_layout(0)
    fast, ref = RayCaster(lay.vertices, lay.faces), RayCaster(lay.vertices, lay.faces, backend="numpy")
    assert fast.backend == "embree"  # the demo build relies on it (pip install embreex)
    rng = np.random.default_rng(0)
    rig = capture.make_rig(6.0, 0, 8.0)
    o = rig.position[rng.integers(0, len(rig.position), 1500)]
    d = rng.normal(size=(1500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t1, i1 = fast.cast(o, d)
    t2, i2 = ref.cast(o, d)
    assert (i1 == i2).mean() > 0.995 and ((i1 >= 0) == (i2 >= 0)).mean() > 0.998
    both = (i1 == i2) & (i1 >= 0)
    np.testing.assert_allclose(t1[both], t2[both], atol=1e-9)


def test_transforms_json_poses_match_colmap(scene, tiny_demo_scene, tmp_path):
    """transforms.json (nerfstudio, OpenGL camera axes) and the COLMAP model describe the same cameras."""
    dst = tmp_path / "no_sparse"
    shutil.copytree(tiny_demo_scene, dst, ignore=shutil.ignore_patterns("sparse", "3dgs.ply"))
    tj = load_scene(dst)
    a = {c.name: c for c in scene.cameras}
    assert len(tj.cameras) == len(a)
    for c in tj.cameras:
        np.testing.assert_allclose(c.world_from_cam, a[c.name].world_from_cam, atol=1e-6)
        np.testing.assert_allclose(c.K, a[c.name].K)
