"""The docs' code blocks, for the tests that run them (`run_snippet` in conftest.py executes one)."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def python_blocks(page: str) -> list[str]:
    """The ```python blocks of a docs page (`page` relative to the repository), in order."""
    return re.findall(r"```python\n(.*?)```", (REPO / page).read_text(), re.S)


def merged(a: dict, b: dict) -> dict:
    """`a` updated with `b`, nested dicts merged key by key (`b` wins)."""
    out = dict(a)
    for k, v in b.items():
        out[k] = merged(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out
