"""Readers and their frame conventions (COLMAP world-to-camera, transforms.json camera-to-world OpenGL,
TUM camera-to-world, scene folders), matching and completeness, and degenerate inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wanderland_nav.recon import PoseSet, ReconInputError, evaluate_poses, read_poses
from wanderland_nav.recon.associate import match_names, match_stamps
from wanderland_nav.recon.readers import detect_kind
from wanderland_nav.scene import colmap as C

GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def _world_from_cam(n=12, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    T[:, :3, 3] = rng.normal(scale=3.0, size=(n, 3))
    return T


def _write_colmap(folder, T, names, ext):
    ims = {}
    for i, (Ti, name) in enumerate(zip(T, names), 1):
        E = np.linalg.inv(Ti)  # COLMAP stores world-to-camera
        ims[i] = C.ColmapImage(i, C.rotmat_to_qvec(E[:3, :3]), E[:3, 3], 1, name)
    cams = {1: C.ColmapCamera(1, "PINHOLE", 64, 48, np.array([50.0, 50.0, 32.0, 24.0]))}
    C.write_model(folder, C.ColmapModel(cams, ims, C.ColmapPoints3D.empty()), ext=ext)


def _write_tum(path, stamps, T):
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()  # xyzw, the TUM order
    rows = np.concatenate([np.asarray(stamps)[:, None], T[:, :3, 3], q], 1)
    path.write_text("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(" ".join(f"{v:.9f}" for v in r) for r in rows))


@pytest.mark.parametrize("ext", [".bin", ".txt"])
def test_colmap_is_read_as_world_to_camera(tmp_path, ext):
    T = _world_from_cam()
    names = [f"seq/{i:03d}.jpg" for i in range(len(T))]
    _write_colmap(tmp_path / "sparse" / "0", T, names, ext)
    ps = read_poses(tmp_path / "sparse" / "0")
    assert ps.kind == "colmap" and list(ps.names) == names
    np.testing.assert_allclose(ps.world_from_cam, T, atol=1e-9)
    np.testing.assert_allclose(read_poses(tmp_path / "sparse" / "0" / f"images{ext}").world_from_cam, T, atol=1e-9)


def test_transforms_json_is_read_as_camera_to_world_opengl(tmp_path):
    T = _world_from_cam(seed=1)
    A = np.eye(4)
    A[:3, :3] = Rotation.from_euler("x", 90, degrees=True).as_matrix()  # nerfstudio's re-orientation
    frames = [{"file_path": f"images/{i:03d}.jpg", "transform_matrix": (A @ Ti @ GL_TO_CV).tolist()}
              for i, Ti in enumerate(T)]
    (tmp_path / "transforms.json").write_text(json.dumps({"applied_transform": A[:3].tolist(), "frames": frames}))
    ps = read_poses(tmp_path / "transforms.json")
    assert ps.names[0] == "000.jpg" and detect_kind(tmp_path) == "transforms"
    np.testing.assert_allclose(ps.world_from_cam, T, atol=1e-9)


def test_colmap_prediction_against_transforms_ground_truth_both_conventions(tmp_path):
    """Same cameras written in the two conventions: zero error. Reading world-to-camera as camera-to-world
    (the classic mistake) is caught: the errors are large."""
    T = _world_from_cam(seed=2)
    _write_colmap(tmp_path / "model", T, [f"{i:03d}.jpg" for i in range(len(T))], ".bin")
    frames = [{"file_path": f"./images/{i:03d}.jpg", "transform_matrix": (Ti @ GL_TO_CV).tolist()} for i, Ti in enumerate(T)]
    (tmp_path / "transforms.json").write_text(json.dumps({"frames": frames}))
    m = evaluate_poses(read_poses(tmp_path / "model"), read_poses(tmp_path / "transforms.json")).metrics
    assert m["matched"] == len(T) and m["matched_by"] == "name"
    assert m["t_ate_se3"] < 1e-9 and m["r_rte_deg"] < 1e-5 and m["auc30"] == pytest.approx(1.0)
    swapped = PoseSet(np.linalg.inv(T), "swapped", "colmap", names=tuple(f"{i:03d}.jpg" for i in range(len(T))))
    bad = evaluate_poses(swapped, read_poses(tmp_path / "transforms.json")).metrics
    assert bad["t_ate_sim3"] > 0.5 and bad["r_rte_deg"] > 20


def test_scene_folder_against_its_own_files_and_completeness(tiny_demo_scene):
    """The demo writes sparse/0 (world-to-camera; train cameras only) and transforms.json (camera-to-world,
    OpenGL; every camera). The scene's grounded poses agree with both; the sparse model covers only the
    train split, which is reported as completeness, never hidden."""
    gt = read_poses(tiny_demo_scene)
    assert gt.kind == "scene" and len(gt) == 80 and gt.up_axis == "-y"
    tj = evaluate_poses(read_poses(tiny_demo_scene / "transforms.json"), gt).metrics
    assert tj["matched"] == 80 and tj["t_ate_se3"] < 1e-6 and tj["r_ate_deg"] < 1e-4
    sp = evaluate_poses(read_poses(tiny_demo_scene / "sparse" / "0"), gt).metrics
    n_val = len((tiny_demo_scene / "nvs_split" / "val.txt").read_text().split())
    assert sp["matched"] == 80 - n_val and sp["unmatched_gt"] == n_val
    assert sp["completeness"] == pytest.approx((80 - n_val) / 80) and sp["t_ate_se3"] < 1e-6


def test_tum_round_trip_and_timestamp_association(tmp_path):
    T = _world_from_cam(20, seed=3)
    stamps = 100.0 + 0.1 * np.arange(20)
    _write_tum(tmp_path / "gt.txt", stamps, T)
    _write_tum(tmp_path / "est.txt", stamps[::2] + 0.004, T[::2])  # every other frame, 4 ms late
    gt, est = read_poses(tmp_path / "gt.txt"), read_poses(tmp_path / "est.txt")
    np.testing.assert_allclose(gt.world_from_cam, T, atol=1e-8)
    m = evaluate_poses(est, gt).metrics
    assert (m["matched"], m["n_gt"], m["completeness"]) == (10, 20, 0.5) and m["t_ate_se3"] < 1e-7
    with pytest.raises(ReconInputError, match="only 0 of 20"):
        evaluate_poses(est, gt, max_time_diff=0.003)
    assert evaluate_poses(est, gt, max_time_diff=0.001, time_offset=-0.004).metrics["matched"] == 10


def test_stamp_matching_is_nearest_within_tolerance():
    m = match_stamps([0.0, 1.0, 2.004, 5.0], [0.001, 0.998, 1.003, 2.0, 3.0, 4.0], max_diff=0.01)
    assert m.pred_idx.tolist() == [0, 1, 2] and m.gt_idx.tolist() == [0, 1, 3]
    assert m.summary()["unmatched_pred"] == 1 and m.completeness == pytest.approx(3 / 6)


def test_name_matching_falls_back_to_stems_and_counts_unmatched():
    m = match_names(["a.png", "b.png", "zz.png"], ["a.jpg", "b.jpg", "c.jpg", "d.jpg"])
    assert m.by == "stem" and m.pred_idx.tolist() == [0, 1] and m.gt_idx.tolist() == [0, 1]
    assert m.summary()["unmatched_gt"] == 2 and m.summary()["unmatched_pred"] == 1
    flat = match_names(["0001.png", "0002.png"], ["seq/0001.jpg", "seq/0002.jpg", "seq/0003.jpg"])
    assert flat.by == "basename" and flat.gt_idx.tolist() == [0, 1]
    rig = match_names(["0001.png"], ["left/0001.jpg", "right/0001.jpg"])  # ambiguous stems: no guess
    assert len(rig) == 0 and rig.completeness == 0.0


def test_degenerate_and_malformed_inputs(tmp_path):
    T = _world_from_cam(6, seed=4)
    bad = T.copy()
    bad[2, 0, 3] = np.nan
    with pytest.raises(ReconInputError, match="non-finite.*'0002.jpg'"):
        PoseSet(bad, "x", "colmap", names=tuple(f"{i:04d}.jpg" for i in range(6)))
    with pytest.raises(ReconInputError, match="'a.jpg' appears twice"):
        PoseSet(T[:2], "x", "colmap", names=("a.jpg", "a.jpg"))
    with pytest.raises(ReconInputError, match="3 poses but 2"):
        PoseSet(T[:3], "x", "colmap", names=("a.jpg", "b.jpg"))
    (tmp_path / "nan.txt").write_text("1.0 0 0 0 0 0 0 1\n2.0 nan 0 0 0 0 0 1\n")
    with pytest.raises(ReconInputError, match=r"nan.txt: row 1 \(stamp 2.000000\) field tx"):
        read_poses(tmp_path / "nan.txt")
    (tmp_path / "short.txt").write_text("1.0 0 0 0 0 0 1\n")
    with pytest.raises(ReconInputError, match="need 8 numbers"):
        read_poses(tmp_path / "short.txt")
    (tmp_path / "zeroq.txt").write_text("1.0 0 0 0 0 0 0 0\n")
    with pytest.raises(ReconInputError, match="zero quaternion"):
        read_poses(tmp_path / "zeroq.txt")
    (tmp_path / "dup.txt").write_text("1.0 0 0 0 0 0 0 1\n1.0 5 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n")
    dup = read_poses(tmp_path / "dup.txt")  # first pose of a repeated stamp kept, the repeat counted
    assert len(dup) == 2 and dup.duplicates_dropped == 1 and dup.world_from_cam[0, 0, 3] == 0.0
    named = PoseSet(T, "x", "colmap", names=tuple(f"{i}.jpg" for i in range(6)))
    with pytest.raises(ReconInputError, match="only be compared with another TUM"):
        evaluate_poses(dup, named)
    with pytest.raises(ReconInputError, match="only 2 of 6"):
        evaluate_poses(named.subset(np.arange(2)), named)
    with pytest.raises(ReconInputError, match="not a COLMAP model"):
        read_poses(tmp_path)  # a folder of text files is none of the inputs
    with pytest.raises(ReconInputError, match="no such file or folder"):
        read_poses(tmp_path / "missing")
