"""PLY / KITTI point-cloud I/O: round trips, by-name reading, truncation errors, real KITTI scans."""

from __future__ import annotations

import numpy as np
import pytest

from wanderland_nav.scene import pointcloud as P


def _cloud(n=50, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)).astype(np.float32), rng.integers(0, 256, size=(n, 3)).astype(np.uint8)


@pytest.mark.parametrize("binary", [True, False])
def test_round_trip(tmp_path, binary):
    xyz, rgb = _cloud()
    inten = np.linspace(0, 1, 50).astype(np.float32)
    P.write_ply_points(tmp_path / "a.ply", xyz, rgb, binary=binary, extra={"intensity": inten})
    pc = P.read_ply_points(tmp_path / "a.ply")
    np.testing.assert_allclose(pc.xyz, xyz, rtol=1e-6 if not binary else 0)
    np.testing.assert_array_equal(pc.rgb, rgb)
    np.testing.assert_allclose(pc.extra["intensity"], inten, rtol=1e-6)


def test_reads_by_name_any_order_and_endianness(tmp_path):
    xyz, rgb = _cloud(7)
    body = np.empty(7, dtype=[("blue", "u1"), ("nx", ">f4"), ("z", ">f8"), ("red", "u1"), ("y", ">f8"),
                              ("green", "u1"), ("x", ">f8")])
    body["x"], body["y"], body["z"] = xyz.T
    body["red"], body["green"], body["blue"] = rgb.T
    body["nx"] = 1
    head = ("ply\nformat binary_big_endian 1.0\ncomment made by hand\nelement vertex 7\nproperty uchar blue\n"
            "property float nx\nproperty double z\nproperty uchar red\nproperty double y\nproperty uchar green\n"
            "property double x\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n").encode()
    faces = np.array([(3, 0, 1, 2), (3, 2, 3, 4)], dtype=[("n", "u1"), ("a", ">i4"), ("b", ">i4"), ("c", ">i4")])
    (tmp_path / "b.ply").write_bytes(head + body.tobytes() + faces.tobytes())
    pc = P.read_ply_points(tmp_path / "b.ply")
    np.testing.assert_allclose(pc.xyz, xyz)
    np.testing.assert_array_equal(pc.rgb, rgb)
    _, els = P.read_ply(tmp_path / "b.ply")
    np.testing.assert_array_equal(els["face"]["vertex_indices"], [[0, 1, 2], [2, 3, 4]])


def test_float_colours_and_no_colours(tmp_path):
    xyz, rgb = _cloud(5)
    cols = [("x", xyz[:, 0]), ("y", xyz[:, 1]), ("z", xyz[:, 2]), ("red", rgb[:, 0] / 255.0),
            ("green", rgb[:, 1] / 255.0), ("blue", rgb[:, 2] / 255.0)]
    P.write_ply_element(tmp_path / "f.ply", "vertex", [(k, np.asarray(v, np.float32)) for k, v in cols])
    np.testing.assert_array_equal(P.read_ply_points(tmp_path / "f.ply").rgb, rgb)
    P.write_ply_points(tmp_path / "n.ply", xyz)
    assert P.read_ply_points(tmp_path / "n.ply").rgb is None
    with pytest.raises(P.PointCloudFormatError, match="red/green/blue"):
        P.read_ply_points(tmp_path / "n.ply", require_color=True)


def test_truncated_binary_names_file_and_property(tmp_path):
    xyz, rgb = _cloud(10)
    P.write_ply_points(tmp_path / "t.ply", xyz, rgb)
    data = (tmp_path / "t.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-2])  # cut inside the last row's 'green'
    with pytest.raises(P.PointCloudFormatError, match=r"t\.ply.*'vertex'.*property 'green' at row 9"):
        P.read_ply_points(tmp_path / "t.ply")


def test_corrupt_ascii_names_property(tmp_path):
    xyz, rgb = _cloud(4)
    P.write_ply_points(tmp_path / "a.ply", xyz, rgb, binary=False)
    lines = (tmp_path / "a.ply").read_text().splitlines()
    lines[-1] = " ".join(lines[-1].split()[:4])  # row 3 loses green, blue
    (tmp_path / "a.ply").write_text("\n".join(lines) + "\n")
    with pytest.raises(P.PointCloudFormatError, match=r"a\.ply.*'vertex', property 'green' at row 3.*end-of-line"):
        P.read_ply_points(tmp_path / "a.ply")
    (tmp_path / "a.ply").write_text("\n".join(lines[:-2]) + "\n")
    with pytest.raises(P.PointCloudFormatError, match=r"a\.ply.*'vertex' at row 2 \(header declares 4 rows\).*end-of-file"):
        P.read_ply_points(tmp_path / "a.ply")


def test_bad_headers(tmp_path):
    (tmp_path / "x.ply").write_bytes(b"not a ply\n")
    with pytest.raises(P.PointCloudFormatError, match="x.ply"):
        P.read_ply_points(tmp_path / "x.ply")
    (tmp_path / "y.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(P.PointCloudFormatError, match="no property 'y'"):
        P.read_ply_points(tmp_path / "y.ply")
    with pytest.raises(P.PointCloudFormatError, match="file not found"):
        P.read_ply_points(tmp_path / "missing.ply")


def test_kitti_reader(tmp_path, shared_data):
    pts = P.read_kitti_bin(shared_data / "lidar/kitti/000000.bin")
    assert pts.dtype == np.float32 and pts.shape[1] == 4 and 100_000 < len(pts) < 150_000
    # sensor ~1.73 m above the road: the densest height bin near the scanner is the road at z ~ -1.7
    near = pts[np.linalg.norm(pts[:, :2], axis=1) < 15]
    hist, edges = np.histogram(near[:, 2], bins=np.arange(-3, 1, 0.1))
    assert -2.0 < edges[hist.argmax()] < -1.5
    (tmp_path / "t.bin").write_bytes(pts[:3].tobytes()[:-4])
    with pytest.raises(P.PointCloudFormatError, match="intensity"):
        P.read_kitti_bin(tmp_path / "t.bin")
    pc = P.read_points_any(shared_data / "lidar/kitti/000001.bin")
    assert pc.xyz.shape[1] == 3 and "intensity" in pc.extra
