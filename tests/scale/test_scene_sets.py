"""Scene manifests: folder, Wanderland list files, the public CSV; tier/split filters; bad rows named."""

from __future__ import annotations

import pytest
from omegaconf import OmegaConf

from wanderland_nav.scene.sets import (
    ManifestError,
    demo_scene_set,
    load_scene_set,
    scene_set_from_config,
)


def test_folder_of_scenes_keeps_only_scene_folders(tmp_path):
    for name, marker in (("b_scene", "3dgs.ply"), ("a_scene", "sparse"), ("notes", None)):
        (tmp_path / name).mkdir()
        if marker == "sparse":
            (tmp_path / name / marker).mkdir()
        elif marker:
            (tmp_path / name / marker).write_bytes(b"")
    s = load_scene_set(tmp_path)
    assert s.ids == ["a_scene", "b_scene"]
    assert s.paths == [tmp_path / "a_scene", tmp_path / "b_scene"]


def test_list_file_resolves_against_data_root_and_reads_split(tmp_path):
    f = tmp_path / "train_scenes_v1.txt"
    f.write_text("# Wanderland train split\nscene_001\n\nscene_007  # a comment\n")
    s = load_scene_set(f, data_root="/data/wl")
    assert s.ids == ["scene_001", "scene_007"]
    assert [str(p) for p in s.paths] == ["/data/wl/scene_001", "/data/wl/scene_007"]
    assert {e.split for e in s} == {"train"}
    assert len(s.missing()) == 2
    assert load_scene_set(f, split="eval").ids == []


def test_list_file_repeated_id_names_both_lines(tmp_path):
    f = tmp_path / "eval_scenes_v1.txt"
    f.write_text("s1\ns2\ns1\n")
    with pytest.raises(ManifestError, match=r"eval_scenes_v1.txt:3: scene_id 's1' repeated \(first at .*:1\)"):
        load_scene_set(f)


CSV = """scene_id,quality_tier,manifest_version,data_path,split
s1,showcase,v1,scenes/s1,train
s2,training_ready,v1,,train
s3,evaluation_ready,v1,scenes/s3,eval
"""


def test_csv_manifest_filters_by_tier_and_split(tmp_path):
    f = tmp_path / "manifest.csv"
    f.write_text(CSV)
    s = load_scene_set(f)
    assert s.ids == ["s1", "s2", "s3"]
    assert s.entries[0].path == tmp_path / "scenes/s1" and s.entries[1].path == tmp_path / "s2"
    assert s.entries[0].manifest_version == "v1"
    assert load_scene_set(f, tiers=["showcase", "evaluation_ready"]).ids == ["s1", "s3"]
    assert load_scene_set(f, tiers="training_ready", split="train").ids == ["s2"]
    assert s.restrict(["s3", "s1"]).ids == ["s1", "s3"]
    with pytest.raises(ManifestError, match="not in the set"):
        s.restrict(["s9"])
    with pytest.raises(ManifestError, match="quality tier"):
        s.filter(tiers=["gold"])


@pytest.mark.parametrize(
    "body, match",
    [
        ("scene_id,tier\ns1,showcase\n", r"manifest.csv:1: column 'quality_tier' missing"),
        ("scene_id,quality_tier\ns1,showcase\ns2,gold\n", r"manifest.csv:3: quality_tier 'gold'"),
        ("scene_id,quality_tier\n../x,showcase\n", r"manifest.csv:2: scene_id '../x' is not a folder name"),
        ("scene_id,quality_tier\n", r"manifest.csv: no rows"),
    ],
)
def test_csv_bad_rows_name_file_and_line(tmp_path, body, match):
    f = tmp_path / "manifest.csv"
    f.write_text(body)
    with pytest.raises(ManifestError, match=match):
        load_scene_set(f)


def test_missing_manifest_is_named(tmp_path):
    with pytest.raises(ManifestError, match="nope.txt: scene manifest not found"):
        load_scene_set(tmp_path / "nope.txt")


def test_demo_set_config_names_three_seeds(tmp_path):
    cfg = OmegaConf.load("conf/scene/demo_set.yaml")
    s = scene_set_from_config(cfg)
    assert s.ids == ["demo_seed_0", "demo_seed_1", "demo_seed_2"] and s.demo == {"seeds": [0, 1, 2], "preset": "tiny", "generator": "demo"}
    assert cfg.path == str(s.paths[0])  # named in the refusal message of single-scene commands
    assert scene_set_from_config(OmegaConf.load("conf/scene/demo.yaml")) is None
    d = demo_scene_set(tmp_path, seeds=[4])
    assert d.paths == [tmp_path / "seed_4"]
