"""The plyfile wrapper: memory-mapped reads, list properties, errors naming file/element/row/property."""

from __future__ import annotations

import numpy as np
import pytest
import torch

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


def test_chunked_write_is_the_whole_table_write_byte_for_byte(tmp_path):
    """`write_ply_chunks` (a splat saved a block at a time) writes the bytes `write_ply_table` writes, and
    refuses a row count that does not match what it announced."""
    from wanderland_nav.render import Gaussians
    from wanderland_nav.render.plyio import write_ply_chunks, write_ply_table

    rng = np.random.default_rng(0)
    table = np.zeros(1000, dtype=[("x", "<f4"), ("y", "<f4"), ("f_rest_0", "<f4")])
    for name in table.dtype.names:
        table[name] = rng.normal(size=1000)
    write_ply_table(tmp_path / "whole.ply", table)
    write_ply_chunks(tmp_path / "chunks.ply", table.dtype, 1000, (table[a:a + 77] for a in range(0, 1000, 77)))
    assert (tmp_path / "chunks.ply").read_bytes() == (tmp_path / "whole.ply").read_bytes()
    with pytest.raises(ValueError, match="999 rows written, 1000 announced"):
        write_ply_chunks(tmp_path / "short.ply", table.dtype, 1000, [table[:999]])
    assert not (tmp_path / "short.ply").exists()
    gen = torch.Generator().manual_seed(0)
    n = 500
    g = Gaussians(torch.randn(n, 3, generator=gen), torch.randn(n, 3, generator=gen), torch.randn(n, 4, generator=gen),
                  torch.randn(n, generator=gen), torch.randn(n, 3, generator=gen), torch.randn(n, 15, 3, generator=gen))
    g.save(tmp_path / "a.ply", chunk=64)
    g.save(tmp_path / "b.ply", chunk=n)
    assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()
    back = Gaussians.load(tmp_path / "a.ply")
    assert torch.equal(back.sh_rest, g.sh_rest) and torch.equal(back.means, g.means)
