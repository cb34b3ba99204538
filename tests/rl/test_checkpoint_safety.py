"""Checkpoints cannot run code: every path that loads one refuses a hostile file (torch zip and legacy
pickle) by name, before anything in it runs; what we save is plain data and round-trips every RNG."""

from __future__ import annotations

import ast
import os
import random
from pathlib import Path

import numpy as np
import pytest
import torch

from policies import make_policy
from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.rl.checkpoint import (Checkpointer, load_checkpoint, load_policy_weights, rng_state,
                                          save_checkpoint, set_rng_state)

ROOT = Path(__file__).resolve().parents[2]


class _Hostile:
    """Unpickling this runs a shell command that creates `marker`."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch '{self.marker}'",)


def _hostile_files(tmp_path: Path) -> tuple[Path, list[Path]]:
    marker = tmp_path / "code_ran"
    payload = {"version": 1, "phase": "ppo", "policy": _Hostile(marker), "config": {"policy": {"name": "cnn"}}}
    zip_file, legacy = tmp_path / "zip" / "last.pt", tmp_path / "legacy" / "last.pt"
    for f in (zip_file, legacy):
        f.parent.mkdir()
    torch.save(payload, zip_file)
    torch.save(payload, legacy, _use_new_zipfile_serialization=False)
    return marker, [zip_file, legacy]


def test_the_hostile_files_do_run_code_when_unpickled(tmp_path):
    """The control: the same files loaded without weights_only execute their payload."""
    marker, files = _hostile_files(tmp_path)
    for f in files:
        torch.load(f, weights_only=False)
        assert marker.exists()
        marker.unlink()


def _loaders():
    from wanderland_nav.compose.checkpoints import policy_from_checkpoint
    from wanderland_nav.compose.training import checked_run_dir

    def resume(f):  # train's resume from <run_dir>/checkpoints/last.pt
        return Checkpointer(f.parent).resume()

    def run_dir_check(f):  # train's "is this run folder mine" look at last.pt
        run = f.parent / "run"
        (run / "checkpoints").mkdir(parents=True)
        (run / "checkpoints" / "last.pt").write_bytes(f.read_bytes())
        return checked_run_dir(run, {"hash": "0" * 64, "config": {}})

    return {"load_checkpoint": load_checkpoint,
            "init_checkpoint": lambda f: load_policy_weights(make_policy("cnn", image_size=(16, 16)), f),
            "evaluate checkpoints=": policy_from_checkpoint,
            "resume": resume,
            "run folder check": run_dir_check}


@pytest.mark.parametrize("loader", list(_loaders()))
def test_hostile_checkpoint_runs_nothing_on_any_load_path(tmp_path, loader):
    marker, files = _hostile_files(tmp_path)
    for f in files:
        with pytest.raises(WanderlandInputError, match=rf"{f.parent}/(run/checkpoints/)?last\.pt: checkpoint refused: it needs code to load "
                                                       r"\(global (posix|os|nt)\.system\)"):
            _loaders()[loader](f)
        assert not marker.exists(), f"{loader} ran the code in {f.parent.name}/last.pt"


def test_every_torch_load_in_the_package_is_weights_only():
    """A new `torch.load` that could unpickle code fails here (the library goes through errors.torch_load)."""
    offenders = []
    for folder in ("wanderland_nav", "policies", "planners", "experiments"):
        for py in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(py.read_text())):
                if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "load"
                        and isinstance(node.func.value, ast.Name) and node.func.value.id == "torch"):
                    kw = {k.arg: k.value for k in node.keywords}
                    if not (isinstance(kw.get("weights_only"), ast.Constant) and kw["weights_only"].value is True):
                        offenders.append(f"{py.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []


def test_rng_state_is_plain_data_and_round_trips(tmp_path):
    p = make_policy("cnn", image_size=(16, 16), feature_dim=16)
    opt = torch.optim.Adam(p.parameters())
    sum(x.sum() for x in p.parameters()).backward()
    opt.step()
    torch.manual_seed(3), np.random.seed(4), random.seed(5)
    path = save_checkpoint(tmp_path / "c.pt", policy=p, optimizer=opt, counters={"it": 2},
                           config={"a": [1, 2.5, None, "x"], "b": {"c": True}}, phase="ppo")
    expected = (torch.rand(3), np.random.rand(3), random.random())
    torch.manual_seed(0), np.random.seed(0), random.seed(0)
    ck = torch.load(path, weights_only=True)  # loads with no allowed globals at all
    set_rng_state(ck["rng"])
    assert torch.equal(torch.rand(3), expected[0]) and np.array_equal(np.random.rand(3), expected[1])
    assert random.random() == expected[2]
    assert ck["config"] == {"a": [1, 2.5, None, "x"], "b": {"c": True}}
    opt2 = torch.optim.Adam(p.parameters())
    opt2.load_state_dict(ck["optimizer"])


def test_checkpoint_with_numpy_legacy_rng_still_loads(tmp_path):
    """Checkpoints written while the numpy RNG state was a tuple holding an ndarray resume as before."""
    p = torch.nn.Linear(2, 2)
    np.random.seed(7)
    legacy = {**rng_state(), "numpy": np.random.get_state()}
    expected = np.random.rand(2)
    torch.save({"version": 1, "phase": "ppo", "policy": p.state_dict(), "optimizer": None, "counters": {},
                "config": None, "rng": legacy, "extra": {}}, tmp_path / "old.pt")
    ck = load_checkpoint(tmp_path / "old.pt")
    np.random.seed(0)
    set_rng_state(ck["rng"])
    assert np.array_equal(np.random.rand(2), expected)


def test_numpy_numbers_are_saved_as_python_numbers(tmp_path):
    path = save_checkpoint(tmp_path / "c.pt", policy=torch.nn.Linear(2, 2), optimizer=None, counters={"it": 1},
                           extra={"bc": {"loss": np.float64(0.5), "n": np.int64(3), "lr": np.float32(0.25)}})
    assert load_checkpoint(path)["extra"] == {"bc": {"loss": 0.5, "n": 3, "lr": 0.25}}


def test_saving_something_that_would_need_code_to_load_is_refused_naming_the_key(tmp_path):
    with pytest.raises(TypeError, match=r"checkpoint\.config\.out is a PosixPath: a checkpoint holds plain data"):
        save_checkpoint(tmp_path / "c.pt", policy=torch.nn.Linear(2, 2), optimizer=None, counters={},
                        config={"out": Path("x")})
    assert list(tmp_path.iterdir()) == []


def test_weights_that_do_not_fit_their_config_name_the_file_and_the_first_key(tmp_path):
    from wanderland_nav.compose.checkpoints import policy_from_checkpoint

    small = make_policy("cnn", image_size=(16, 16), feature_dim=32)
    config = {"policy": {"name": "cnn", "image_size": [16, 16], "feature_dim": 64}}  # edited after training
    path = save_checkpoint(tmp_path / "edited.pt", policy=small, optimizer=None, counters={}, config=config)
    with pytest.raises(WanderlandInputError, match=r"edited\.pt: .*checkpoint does not fit .*weight '[\w.]+' is "
                                                   r"\[\d+(, \d+)*\] in the file, \[\d+(, \d+)*\] in the policy") as e:
        policy_from_checkpoint(path)
    assert e.value.path == path and e.value.field.startswith("policy.")
    with pytest.raises(WanderlandInputError, match=r"edited\.pt: .*weight '[\w.]+'"):  # the warm-start path too
        load_policy_weights(make_policy("cnn", image_size=(16, 16), feature_dim=64), path)
