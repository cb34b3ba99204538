"""COLMAP readers/writers: round trips in both encodings, every model, corrupt files."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from wanderland_nav.scene import colmap as C


def _model(rng) -> C.ColmapModel:
    cams = {
        1: C.ColmapCamera(1, "PINHOLE", 640, 480, np.array([500.0, 510.0, 320.0, 240.0])),
        2: C.ColmapCamera(2, "OPENCV_FISHEYE", 1920, 1080, np.array([600.0, 601.0, 960.0, 540.0, 0.1, -0.02, 0.003, -0.0004])),
        3: C.ColmapCamera(3, "SIMPLE_PINHOLE", 100, 80, np.array([90.0, 50.0, 40.0])),
        4: C.ColmapCamera(4, "OPENCV", 100, 80, np.array([90.0, 91.0, 50.0, 40.0, 0.1, 0.01, 0.001, 0.002])),
        5: C.ColmapCamera(5, "SIMPLE_RADIAL", 100, 80, np.array([90.0, 50.0, 40.0, -0.05])),
    }
    imgs = {}
    for i in range(1, 5):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        p = 3 * i
        imgs[i] = C.ColmapImage(i, q, rng.normal(size=3), (i % 5) + 1, f"cam{i % 2}/frame_{i:05d}.jpg",
                                rng.uniform(0, 500, size=(p, 2)), rng.integers(-1, 10, size=p))
    imgs[7] = C.ColmapImage(7, np.array([1.0, 0, 0, 0]), np.zeros(3), 1, "empty.png")  # no 2D points
    n = 10
    tl = rng.integers(0, 4, size=n)
    offs = np.concatenate([[0], np.cumsum(tl)])
    pts = C.ColmapPoints3D(np.arange(n, dtype=np.int64) * 7 + 1, rng.normal(size=(n, 3)),
                           rng.integers(0, 256, size=(n, 3)).astype(np.uint8), rng.uniform(0, 2, n), offs,
                           rng.integers(1, 5, size=offs[-1]).astype(np.int32),
                           rng.integers(0, 30, size=offs[-1]).astype(np.int32))
    return C.ColmapModel(cams, imgs, pts)


def _assert_same(a: C.ColmapModel, b: C.ColmapModel):
    assert a.cameras.keys() == b.cameras.keys()
    for k in a.cameras:
        ca, cb = a.cameras[k], b.cameras[k]
        assert (ca.model, ca.width, ca.height) == (cb.model, cb.width, cb.height)
        np.testing.assert_array_equal(ca.params, cb.params)
    assert a.images.keys() == b.images.keys()
    for k in a.images:
        ia, ib = a.images[k], b.images[k]
        assert (ia.name, ia.camera_id) == (ib.name, ib.camera_id)
        np.testing.assert_array_equal(ia.qvec, ib.qvec)
        np.testing.assert_array_equal(ia.tvec, ib.tvec)
        np.testing.assert_array_equal(ia.xys, ib.xys)
        np.testing.assert_array_equal(ia.point3D_ids, ib.point3D_ids)
    pa, pb = a.points3D, b.points3D
    for f in ("ids", "xyz", "rgb", "error", "track_offsets", "track_image_ids", "track_point2D_idxs"):
        np.testing.assert_array_equal(getattr(pa, f), getattr(pb, f), err_msg=f)


@pytest.mark.parametrize("ext", [".bin", ".txt"])
def test_model_round_trip(tmp_path, ext):
    m = _model(np.random.default_rng(0))
    C.write_model(tmp_path, m, ext=ext)
    assert C.detect_model_ext(tmp_path) == ext
    _assert_same(m, C.read_model(tmp_path))


def test_bin_and_txt_agree(tmp_path):
    m = _model(np.random.default_rng(1))
    C.write_model(tmp_path / "b", m, ".bin")
    C.write_model(tmp_path / "t", m, ".txt")
    _assert_same(C.read_model(tmp_path / "b"), C.read_model(tmp_path / "t"))


def test_bin_layout_matches_colmap_spec(tmp_path):
    """Byte layout written by hand from the spec, so reader and writer cannot share a mistake."""
    buf = struct.pack("<Q", 1) + struct.pack("<iiQQ", 3, 1, 640, 480) + struct.pack("<4d", 500, 500, 320, 240)
    (tmp_path / "cameras.bin").write_bytes(buf)
    cam = C.read_cameras_bin(tmp_path / "cameras.bin")[3]
    assert cam.model == "PINHOLE" and (cam.width, cam.height) == (640, 480)
    img = (struct.pack("<Q", 1) + struct.pack("<I", 9) + struct.pack("<4d", 1, 0, 0, 0) + struct.pack("<3d", 1, 2, 3)
           + struct.pack("<I", 3) + b"a/b.jpg\x00" + struct.pack("<Q", 2) + struct.pack("<ddq", 1.5, 2.5, -1)
           + struct.pack("<ddq", 3.5, 4.5, 42))
    (tmp_path / "images.bin").write_bytes(img)
    im = C.read_images_bin(tmp_path / "images.bin")[9]
    assert im.name == "a/b.jpg" and im.camera_id == 3
    np.testing.assert_array_equal(im.point3D_ids, [-1, 42])
    np.testing.assert_array_equal(im.xys, [[1.5, 2.5], [3.5, 4.5]])
    # cam_from_world t = (1,2,3), R = I  ->  camera centre at -t
    np.testing.assert_allclose(im.world_from_cam()[:3, 3], [-1, -2, -3])
    pts = (struct.pack("<Q", 2) + struct.pack("<Q3d3Bd", 5, 1, 2, 3, 10, 20, 30, 0.5) + struct.pack("<Q", 1)
           + struct.pack("<ii", 9, 0) + struct.pack("<Q3d3Bd", 6, 4, 5, 6, 1, 2, 3, 0.25) + struct.pack("<Q", 0))
    (tmp_path / "points3D.bin").write_bytes(pts)
    p = C.read_points3D_bin(tmp_path / "points3D.bin")
    np.testing.assert_array_equal(p.ids, [5, 6])
    np.testing.assert_array_equal(p.rgb, [[10, 20, 30], [1, 2, 3]])
    np.testing.assert_array_equal(p.track_offsets, [0, 1, 1])
    np.testing.assert_array_equal(p.track_image_ids, [9])


def test_every_model_known_and_intrinsics():
    assert set(C.CAMERA_MODELS) == set(range(12))
    for m in C.CAMERA_MODELS.values():
        assert len(m.param_names) == m.num_params
        cam = C.ColmapCamera(1, m.name, 10, 10, np.arange(1, m.num_params + 1, dtype=float))
        K, d = cam.intrinsics()
        assert K.shape == (3, 3) and d.shape == (4,)
    K, d = C.ColmapCamera(1, "OPENCV_FISHEYE", 10, 10, np.array([5, 6, 7, 8, .1, .2, .3, .4])).intrinsics()
    np.testing.assert_array_equal(K, [[5, 0, 7], [0, 6, 8], [0, 0, 1]])
    np.testing.assert_array_equal(d, [.1, .2, .3, .4])
    assert C.camera_model("opencv_fisheye").model_id == 5


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        np.testing.assert_allclose(C.rotmat_to_qvec(C.qvec_to_rotmat(q)), q, atol=1e-12)
    im = C.ColmapImage(1, q, rng.normal(size=3), 1, "x")
    np.testing.assert_allclose(im.world_from_cam() @ im.cam_from_world(), np.eye(4), atol=1e-12)


@pytest.mark.parametrize("fname", ["cameras.bin", "images.bin", "points3D.bin"])
def test_truncated_bin_names_file_and_field(tmp_path, fname):
    C.write_model(tmp_path, _model(np.random.default_rng(2)), ".bin")
    p = tmp_path / fname
    p.write_bytes(p.read_bytes()[:-5])
    with pytest.raises(C.ColmapFormatError, match=fname.replace(".", r"\.")) as e:
        C.read_model(tmp_path)
    assert "truncated" in str(e.value) or "corrupt" in str(e.value)


def test_garbage_count_and_trailing_bytes(tmp_path):
    C.write_model(tmp_path, _model(np.random.default_rng(3)), ".bin")
    p = tmp_path / "images.bin"
    p.write_bytes(struct.pack("<Q", 10**12) + p.read_bytes()[8:])
    with pytest.raises(C.ColmapFormatError, match="num_reg_images"):
        C.read_images_bin(p)
    p2 = tmp_path / "cameras.bin"
    p2.write_bytes(p2.read_bytes() + b"xx")
    with pytest.raises(C.ColmapFormatError, match="trailing"):
        C.read_cameras_bin(p2)


def test_text_errors(tmp_path):
    (tmp_path / "cameras.txt").write_text("# c\n1 PINHOLE 640 480 500 500 320\n")
    with pytest.raises(C.ColmapFormatError, match=r"cameras\.txt:2: field PARAMS"):
        C.read_cameras_txt(tmp_path / "cameras.txt")
    (tmp_path / "cameras.txt").write_text("1 WEIRD 640 480 1\n")
    with pytest.raises(C.ColmapFormatError, match="field MODEL"):
        C.read_cameras_txt(tmp_path / "cameras.txt")
    (tmp_path / "images.txt").write_text("1 1 0 0 0 0 0 0 1 a.jpg\n1.0 2.0\n")
    with pytest.raises(C.ColmapFormatError, match="POINTS2D"):
        C.read_images_txt(tmp_path / "images.txt")
    with pytest.raises(C.ColmapFormatError, match="file not found"):
        C.read_points3D_txt(tmp_path / "nope.txt")


def test_image_with_unknown_camera(tmp_path):
    m = _model(np.random.default_rng(4))
    m.images[1].camera_id = 99
    C.write_model(tmp_path, m, ".txt")
    with pytest.raises(C.ColmapFormatError, match="camera_id = 99"):
        C.read_model(tmp_path)


def test_missing_model(tmp_path):
    with pytest.raises(C.ColmapFormatError, match="no COLMAP model"):
        C.read_model(tmp_path)
