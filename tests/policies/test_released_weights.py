"""The released-checkpoint reader: runs nothing a file names, reads the three release formats, and says what
does not fit."""

from __future__ import annotations

import os

import pytest
import torch
from torch import nn

from policies.released.weights import (Inert, ReleasedWeightsError, load_released, read_checkpoint,
                                       released_state_dict)


class _RunsCode:
    """Pickles as a call of `os.system` (what a hostile checkpoint does)."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


class _Exec:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').write('ran')",)


def _net():
    return nn.Sequential(nn.Linear(3, 4), nn.BatchNorm1d(4), nn.Linear(4, 2))


def test_nothing_in_the_file_runs(tmp_path):
    marker = tmp_path / "ran"
    path = tmp_path / "hostile.pth"
    torch.save({"weight": torch.ones(2), "payload": _RunsCode(marker), "more": [_Exec(marker)]}, path)
    obj = read_checkpoint(path)
    assert not marker.exists()
    assert isinstance(obj["payload"], Inert) and obj["payload"].qualname.endswith(".system")
    assert torch.equal(obj["weight"], torch.ones(2))
    with pytest.raises(ReleasedWeightsError, match=r"hostile\.pth.*\['payload', 'more'\] are not tensors"):
        released_state_dict(path)
    assert not marker.exists()


def test_raw_state_dict_loads_strictly(tmp_path):
    src = _net()
    path = tmp_path / "raw.pth"
    torch.save(src.state_dict(), path)
    dst = load_released(_net(), path)
    for k, v in src.state_dict().items():
        assert torch.equal(dst.state_dict()[k], v)


def test_lightning_checkpoint_drops_the_model_prefix(tmp_path):
    src = _net()
    path = tmp_path / "citywalker.ckpt"
    torch.save({"state_dict": {f"model.{k}": v for k, v in src.state_dict().items()}, "epoch": 3,
                "hyper_parameters": {"cfg": _RunsCode(tmp_path / "ran")}, "optimizer_states": [{}]}, path)
    sd = released_state_dict(path)
    assert list(sd) == list(src.state_dict())
    assert not (tmp_path / "ran").exists()


def test_pickled_module_gives_its_state_dict(tmp_path):
    src = _net()
    src[1].running_mean.fill_(0.5)
    path = tmp_path / "obj.pth"
    torch.save({"model": src, "optimizer": torch.optim.Adam(src.parameters())}, path)
    sd = released_state_dict(path)
    assert list(sd) == list(src.state_dict())
    assert torch.equal(sd["1.running_mean"], torch.full((4,), 0.5))
    assert sd["1.num_batches_tracked"].dtype == torch.int64


def test_non_persistent_buffers_are_left_out(tmp_path):
    src = _net()
    src.register_buffer("scratch", torch.zeros(3), persistent=False)
    path = tmp_path / "obj.pth"
    torch.save({"model": src}, path)
    assert "scratch" not in released_state_dict(path)


def test_faults_are_named(tmp_path):
    path = tmp_path / "bad.pth"
    sd = _net().state_dict()
    sd.pop("0.bias")
    sd["extra.weight"] = torch.zeros(1)
    sd["2.weight"] = torch.zeros(5, 4)
    torch.save(sd, path)
    with pytest.raises(ReleasedWeightsError) as e:
        load_released(_net(), path)
    msg = str(e.value)
    assert "bad.pth" in msg and "Sequential" in msg
    assert "missing key(s), e.g. ['0.bias']" in msg and "unexpected key(s), e.g. ['extra.weight']" in msg
    assert "2.weight: file (5, 4) vs model (2, 4)" in msg


def test_not_a_checkpoint(tmp_path):
    (tmp_path / "x.pth").write_bytes(b"not a zip")
    with pytest.raises(ReleasedWeightsError, match=r"x\.pth: not a torch zip checkpoint"):
        read_checkpoint(tmp_path / "x.pth")
    with pytest.raises(ReleasedWeightsError, match="no such checkpoint file"):
        read_checkpoint(tmp_path / "missing.pth")


def test_views_share_storage_correctly(tmp_path):
    """Tensors saved as views of one storage come back with their own offsets and strides."""
    base = torch.arange(24, dtype=torch.float32)
    path = tmp_path / "views.pth"
    torch.save({"a": base[4:10], "b": base.view(4, 6).t(), "c": torch.tensor(7.0), "h": base.half()}, path)
    out = read_checkpoint(path)
    assert torch.equal(out["a"], base[4:10]) and torch.equal(out["b"], base.view(4, 6).t())
    assert out["c"].shape == () and float(out["c"]) == 7.0 and out["h"].dtype == torch.float16


def test_tensor_with_attributes_is_a_plain_tensor(tmp_path):
    t = torch.arange(3.0)
    t.note = "kept by torch as Python state"
    torch.save({"w": t}, tmp_path / "attr.pth")
    out = read_checkpoint(tmp_path / "attr.pth")
    assert torch.equal(out["w"], torch.arange(3.0)) and not hasattr(out["w"], "note")
