"""The plyfile wrapper: memory-mapped reads, list properties, errors naming file/element/row/property."""

from __future__ import annotations

import numpy as np
import pytest

from wanderland_nav.render.plyio import element_table, read_ply_data, write_ply_table


class Bad(ValueError):
    pass


def _table(n=5):
    t = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("red", "u1")])
    t["x"], t["y"], t["red"] = np.arange(n), -np.arange(n), 7
    return t


def test_write_bytes_match_the_ply_spec_and_read_back_memory_mapped(tmp_path):
    p = tmp_path / "t.ply"
    write_ply_table(p, _table(), comments=("made here",))
    head = (b"ply\nformat binary_little_endian 1.0\ncomment made here\nelement vertex 5\nproperty float x\n"
            b"property float y\nproperty uchar red\nend_header\n")
    assert p.read_bytes() == head + _table().tobytes()
    v = element_table(read_ply_data(p), p, "vertex")
    assert isinstance(v, np.memmap) and np.array_equal(np.asarray(v), _table())
    with pytest.raises(Bad, match=r"t\.ply: PLY has no element 'face'"):
        element_table(read_ply_data(p), p, "face", Bad)


def test_triangle_and_ragged_lists(tmp_path):
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
            "element face {n}\nproperty list uchar int vertex_indices\nend_header\n")
    tri = np.array([(3, 0, 1, 2), (3, 2, 1, 0)], dtype=[("n", "u1"), ("a", "<i4"), ("b", "<i4"), ("c", "<i4")])
    (tmp_path / "tri.ply").write_bytes(head.format(n=2).encode() + np.float32(1).tobytes() + tri.tobytes())
    f = element_table(read_ply_data(tmp_path / "tri.ply"), "tri.ply", "face")
    assert f["vertex_indices"].tolist() == [[0, 1, 2], [2, 1, 0]]
    quad = np.array([(4, 0, 1, 2, 3)], dtype=[("n", "u1")] + [(c, "<i4") for c in "abcd"])
    (tmp_path / "mix.ply").write_bytes(head.format(n=2).encode() + np.float32(1).tobytes() + tri[:1].tobytes()
                                       + quad.tobytes())
    f = element_table(read_ply_data(tmp_path / "mix.ply"), "mix.ply", "face")
    assert [list(r) for r in f["vertex_indices"]] == [[0, 1, 2], [0, 1, 2, 3]]


def test_errors_name_file_element_row_and_property(tmp_path):
    p = tmp_path / "cut.ply"
    write_ply_table(p, _table())
    p.write_bytes(p.read_bytes()[:-5])  # 9-byte rows: the last row keeps only its 'x'
    with pytest.raises(Bad, match=r"cut\.ply: truncated.*'vertex', property 'y' at row 4 \(header declares 5"):
        read_ply_data(p, Bad)
    write_ply_table(p, _table())
    p.write_bytes(p.read_bytes() + b"\x01\x02")
    with pytest.raises(Bad, match=r"cut\.ply: 2 unexpected bytes after the last element"):
        read_ply_data(p, Bad)
    p.write_bytes(b"PLY?\n")
    with pytest.raises(Bad, match=r"cut\.ply: malformed PLY header.*magic"):
        read_ply_data(p, Bad)
    with pytest.raises(Bad, match="missing.ply: file not found"):
        read_ply_data(tmp_path / "missing.ply", Bad)
    with pytest.raises(ValueError, match=r"x\.ply: .*structured"):
        write_ply_table(tmp_path / "x.ply", np.zeros(3))
