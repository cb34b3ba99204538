"""Any path a shell passes works in `scene=` and other path keys: values Hydra's lexer refuses are quoted
for it; what cannot be read even so is refused with the quoted spelling to type."""

from __future__ import annotations

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser

from wanderland_nav.compose import compose_config
from wanderland_nav.compose.cli import hydra_quoted, quote_overrides

PATHS = ["/data/café/s1", "/data/Straße (2)/scan", "/data/it's here", r"C:\data\scènes", "C:\\data\\", "/d/a b/[x]"]


@pytest.mark.parametrize("path", PATHS)
def test_hydra_quoted_reads_back_exactly(path):
    assert OverridesParser.create().parse_overrides([f"k={hydra_quoted(path)}"])[0].value() == path


@pytest.mark.parametrize("path", PATHS)
def test_scene_takes_any_path(path):
    c = compose_config("prepare", [f"scene={path}"])
    assert c.scene.path == path


def test_other_path_keys_are_quoted_and_plain_values_left_alone():
    assert quote_overrides(["run_dir=/runs/é (1)", "seed=3", "scene.path='/a b'", "--multirun", "--cfg", "job"]) == [
        "run_dir='/runs/é (1)'", "seed=3", "scene.path='/a b'", "--multirun", "--cfg", "job"]


def test_a_list_hydra_cannot_read_is_refused_with_each_path_quoted():
    with pytest.raises(ValueError, match=r"checkpoints=\[/a \(1\)/x\.pt, /b/y\.pt\]: Hydra cannot read this override "
                                         r".*quote the path: checkpoints=\['/a \(1\)/x\.pt', '/b/y\.pt'\]"):
        quote_overrides(["checkpoints=[/a (1)/x.pt, /b/y.pt]"])
