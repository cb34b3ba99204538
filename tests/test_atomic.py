import json
import os
import stat

import pytest

from wanderland_nav.atomic import atomic_path, atomic_write_json


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "sub" / "out.json"
    atomic_write_json(target, {"a": 1})
    assert json.loads(target.read_text()) == {"a": 1}
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half written")
            raise RuntimeError("crash mid-write")
    assert json.loads(target.read_text()) == {"a": 1}, "a failed write must leave the old file intact"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.json"], "no temporary left behind"


def test_atomic_files_get_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_json(tmp_path / "x.json", [1])
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "x.json").stat().st_mode) == 0o644


def test_atomic_json_refuses_nan(tmp_path):
    with pytest.raises(ValueError):
        atomic_write_json(tmp_path / "x.json", {"a": float("nan")})
    assert not (tmp_path / "x.json").exists()


def test_disk_full_mid_write_leaves_the_old_file(tmp_path, monkeypatch):
    """A writer that fails part-way (ENOSPC) must not touch the old file nor leave a temporary behind."""
    import errno

    target = tmp_path / "episodes.json"
    atomic_write_json(target, {"episodes": [1, 2, 3]})
    real_write = os.write

    def full_disk_write(fd, data):
        real_write(fd, data[: len(data) // 2])  # half the bytes land, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "write", full_disk_write)
    with pytest.raises(OSError, match="No space left on device"):
        with atomic_path(target) as tmp:
            fd = os.open(tmp, os.O_WRONLY)
            try:
                os.write(fd, b'{"episodes": []}' * 100)
            finally:
                os.close(fd)
    monkeypatch.undo()
    assert json.loads(target.read_text()) == {"episodes": [1, 2, 3]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episodes.json"]


def test_file_and_folder_are_fsynced_around_the_rename(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}"))),
                                                 real_fsync(fd)))
    monkeypatch.setattr(os, "replace", lambda a, b: (events.append(("replace", str(b))), real_replace(a, b)))
    atomic_write_json(tmp_path / "x.json", {"a": 1})
    kinds = [e[0] for e in events]
    assert kinds == ["fsync", "replace", "fsync"], events
    assert events[0][1].startswith(str(tmp_path / ".x.")) and events[0][1].endswith(".tmp.json")  # the data
    assert events[2][1] == str(tmp_path)  # the folder holding the new name


def test_a_full_disk_names_the_file_even_when_the_writer_does_not(tmp_path, monkeypatch):
    """torch.save on a full disk says only "unexpected pos"; the error must say ENOSPC and which file."""
    import errno
    import shutil
    from collections import namedtuple

    import torch

    from wanderland_nav.rl.checkpoint import save_checkpoint

    target = save_checkpoint(tmp_path / "last.pt", policy=torch.nn.Linear(2, 2), optimizer=None, counters={"it": 1})
    before = target.read_bytes()

    def torch_full(obj, f):
        open(f, "wb").write(b"PK\x03\x04")
        raise RuntimeError("[enforce fail at inline_container.cc:626] . unexpected pos 4 vs 0")

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(torch, "save", torch_full)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 << 30, 10 << 30, 0))
    with pytest.raises(OSError, match=rf"No space left on device while writing {target} \(0 bytes free.*"
                                      r"unexpected pos") as e:
        save_checkpoint(target, policy=torch.nn.Linear(2, 2), optimizer=None, counters={"it": 2})
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(target)
    monkeypatch.undo()
    assert target.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["last.pt"]


def test_temporaries_of_killed_writers_are_removed_by_the_next_write(tmp_path):
    import socket
    import subprocess
    import sys

    from wanderland_nav.atomic import atomic_dir

    host = socket.gethostname().replace(".", "_").replace("-", "_")
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    killed = tmp_path / f".last.{host}-{dead}.k3j2.tmp.pt"  # what kill -9 mid-save leaves
    live = tmp_path / f".last.{host}-{os.getpid()}.a1b2.tmp.pt"  # a writer still running (this process)
    foreign_new = tmp_path / ".last.otherhost-7.zz.tmp.pt"  # another machine's writer, just started
    foreign_old = tmp_path / ".last.otherhost-8.yy.tmp.pt"
    for p in (killed, live, foreign_new, foreign_old):
        p.write_bytes(b"partial")
    os.utime(foreign_old, (1e9, 1e9))
    killed_set = tmp_path / f".views.{host}-{dead}.q9.tmpdir"
    (killed_set / "00000.png").parent.mkdir()
    (killed_set / "00000.png").write_bytes(b"png")
    atomic_write_json(tmp_path / "last.pt", {"x": 1})
    with atomic_dir(tmp_path / "views") as d:
        (d / "00000.png").write_bytes(b"png")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["last.pt", "views", live.name, foreign_new.name])
