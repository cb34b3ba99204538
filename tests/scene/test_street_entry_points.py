"""Real LiDAR-only streets (KITTI, Argoverse 2) through every entry point, as a user would type them.

A LiDAR-only v2 folder (`lidar/*.bin` + `lidar/poses.txt`) runs `prepare`, `make_episodes`, `evaluate
reference=expert` (with rollouts), `replay` and `export_usd`; the entry points that need camera images
refuse with a message that says so: `train` (the policies look through the splat camera: no `3dgs.ply`),
`fit` (Gaussians are fitted to photographs) and `recon_eval` (it scores camera poses and novel views).
KITTI (3 scans, 10 m crop) and av2 (2 sweeps) at smoke sizes: seconds each.
"""

from __future__ import annotations

import shutil

import pytest

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.recon.poses import ReconInputError


def _kitti_street(root, shared_data):
    (root / "lidar").mkdir(parents=True)
    for i in range(3):
        shutil.copy(shared_data / f"lidar/kitti/00000{i}.bin", root / "lidar" / f"{i:06d}.bin")
    lines = (shared_data / "lidar/kitti/gicp_poses_kitti_format.txt").read_text().splitlines()
    (root / "lidar" / "poses.txt").write_text("\n".join(lines[:4]) + "\n")  # comment + 3 poses
    return root  # no scene_meta.json: the vehicle-sweep default drops the car's own returns (2.7 m)


def _every_entry_point(entry_point, root, out, *navigation):
    scene = f"scene={root}"
    prepared = entry_point("prepare", scene, "debug=smoke", *navigation)
    assert prepared["collision_mesh"]["lidar_filter"]["min_range_m"] == 2.7
    assert prepared["collision_mesh"]["ground_fill"]["sheet_area_m2"] > 0
    entry_point("make_episodes", scene, "debug=smoke", *navigation)
    assert (root / "episodes.json").is_file()
    res = entry_point("evaluate", scene, "debug=smoke", "reference=expert", *navigation, f"out={out}",
                      f"save_rollouts={out / 'expert.npz'}")
    assert res.summary["overall"]["episodes"] == 4 and res.summary["overall"]["SR"] == 1.0, res.table
    replayed = entry_point("replay", f"rollout={out / 'expert.npz'}", "debug=smoke", f"out={out / 'expert.rrd'}")
    assert (out / "expert.rrd").stat().st_size > 0 and replayed["out"] == str(out / "expert.rrd")
    usd = entry_point("export_usd", scene, "debug=smoke", *navigation)
    assert usd["up_axis"] == "+z" and usd["navmesh_faces"] > 0 and usd["episodes"] == 4 and "gaussians" not in usd
    with pytest.raises(FileNotFoundError, match="3dgs.ply missing, and the camera needs it"):
        entry_point("train", "+exp=citywalker_rl", scene, "debug=smoke", *navigation, f"run_dir={out / 'train'}")
    with pytest.raises(WanderlandInputError, match="fit needs posed camera images"):
        entry_point("fit", scene, "debug=smoke", f"out_dir={out / 'fit'}")
    with pytest.raises(ReconInputError, match="a LiDAR-only scene"):
        entry_point("recon_eval", f"gt={root}", f"pred={root}", f"out={out / 'recon'}")


def test_kitti_street_through_every_entry_point(shared_data, tmp_path, entry_point):
    root = _kitti_street(tmp_path / "kitti_street", shared_data)
    _every_entry_point(entry_point, root, tmp_path / "out", "navigation.collision.crop_radius=10.0")


def test_av2_street_through_every_entry_point(shared_data, tmp_path, entry_point):
    root = tmp_path / "av2_street"
    shutil.copytree(shared_data / "av2" / "scene", root, copy_function=shutil.copyfile)
    for d in (root, *[p for p in root.rglob("*") if p.is_dir()]):  # the copy is the test's: writable, unlike shared/
        d.chmod(0o755)
    _every_entry_point(entry_point, root, tmp_path / "out")
