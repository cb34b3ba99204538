"""`python -m wanderland_nav.recon_eval` end to end: composed config -> table, CSV/JSON, PNG, rerun recording."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from wanderland_nav.recon_eval import run

CONF = Path(__file__).resolve().parents[2] / "conf"


def _cfg(**overrides) -> dict:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("recon_eval", overrides=[f"{k}={v}" for k, v in overrides.items()])
    return OmegaConf.to_container(cfg, resolve=True)


def test_single_trajectory_writes_every_output(shared_data, tmp_path, capsys):
    d = shared_data / "trajectories"
    res = run(_cfg(pred=d / "fr2_desk_ORB_kf_mono.txt", gt=d / "fr2_desk_groundtruth.txt", out=tmp_path, name="orb"))
    printed = capsys.readouterr().out
    assert "| fr2_desk_groundtruth.txt | 0.9390 | 0.0077 | 0.899 |" in printed and "orb: SR" in printed
    doc = json.loads((tmp_path / "recon_eval.json").read_text())
    m = doc["poses"]["scenes"]["fr2_desk_groundtruth.txt"]
    assert m["t_ate_sim3"] == pytest.approx(0.007729, abs=1e-6) and doc["poses"]["aggregate"]["sr"] == 1.0
    rows = list(csv.DictReader((tmp_path / "recon_eval.csv").open()))
    assert len(rows) == 1 and float(rows[0]["ape.sim3.trans_m.rmse"]) == pytest.approx(0.007729, abs=1e-6)
    png, rrd = tmp_path / "traj_fr2_desk_groundtruth.png", tmp_path / "recon_eval.rrd"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and rrd.stat().st_size > 1000
    assert set(res["written"]) == {tmp_path / "recon_eval.json", tmp_path / "recon_eval.csv", png, rrd}


def test_folder_of_scenes_gives_mean_median_and_sr(shared_data, tmp_path, capsys):
    d = shared_data / "trajectories"
    gt, pred = tmp_path / "gt", tmp_path / "pred"
    gt.mkdir(), pred.mkdir()
    (gt / "README.md").write_text("not a scene\n")  # ignored: only folders and .txt/.json/.tum files are scenes
    for scene, (est, ref) in {"a": ("freiburg1_xyz-rgbdslam.txt", "freiburg1_xyz-groundtruth.txt"),
                              "b": ("fr2_desk_ORB_kf_mono.txt", "fr2_desk_groundtruth.txt"),
                              "c": (None, "fr2_desk_groundtruth.txt")}.items():
        shutil.copy(d / ref, gt / f"{scene}.txt")
        if est:
            shutil.copy(d / est, pred / f"{scene}.txt")
    res = run(_cfg(pred=pred, gt=gt, out=tmp_path / "out", plot=False, rerun=False))
    agg = res["bench"].aggregate()
    assert agg["scenes"] == {"evaluated": 2, "failed": 1, "total": 3} and agg["sr"] == pytest.approx(2 / 3)
    assert agg["mean"]["t_ate_sim3"] == pytest.approx((0.013389 + 0.007729) / 2, abs=1e-6)
    out = capsys.readouterr().out
    assert "| c.txt | failed: no prediction" in out and "**median**" in out
    doc = json.loads((tmp_path / "out" / "recon_eval.json").read_text())
    assert doc["poses"]["failed"] == {"c.txt": f"no prediction in {pred}"}


def test_nvs_only_and_missing_arguments(tiny_demo_scene, tmp_path):
    renders = tmp_path / "renders"
    cam = (tiny_demo_scene / "nvs_split" / "val.txt").read_text().split()[0]  # e.g. left/00028.png
    (renders / cam).parent.mkdir(parents=True)
    shutil.copy(tiny_demo_scene / "images" / cam, renders / cam)
    res = run(_cfg(gt=tiny_demo_scene, nvs=renders, out=tmp_path))
    assert res["nvs"]["n"] == 1 and res["bench"] is None
    doc = json.loads((tmp_path / "recon_eval.json").read_text())
    assert doc["nvs"]["psnr"] is None and doc["nvs"]["ssim"] == pytest.approx(1.0)  # inf PSNR -> null in JSON
    with pytest.raises(ValueError, match="needs gt=<path> and pred=<path>"):
        run(_cfg(gt=tiny_demo_scene, out=tmp_path))
