"""conf/README.md documents every knob of the main job (`train +exp=citywalker_rl`), and only those."""

from __future__ import annotations

import re
from pathlib import Path

from omegaconf import OmegaConf

README = Path(__file__).resolve().parents[1] / "conf" / "README.md"


def test_every_knob_of_the_main_job_has_its_row_in_conf_readme():
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.identity import flatten_dotted

    knobs = set(flatten_dotted(OmegaConf.to_container(compose_config("train", ["+exp=citywalker_rl"]),
                                                      resolve=False)))
    text = README.read_text()
    section = text[text.index("## The main job's knobs"):]
    rows = dict(re.findall(r"^\| `([^`]+)` \| `[^|]*` \| (.*) \|$", section, flags=re.M))
    assert knobs - set(rows) == set(), f"knobs of the main job without a row in conf/README.md: {sorted(knobs - set(rows))}"
    assert set(rows) - knobs == set(), f"rows of conf/README.md the main job has no knob for: {sorted(set(rows) - knobs)}"
    assert not [k for k, what in rows.items() if not what.strip()], "a knob's row says nothing about it"
