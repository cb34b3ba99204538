"""Following `cfg` from `train.run`: how often a reader climbs back up the layers and re-enters a module.

    python -m experiments.architecture.follow_cfg [--steps 400] [--exp citywalker_rl]

Runs `wanderland_nav.train.run` on `+exp=<exp> debug=smoke` under `sys.setprofile` and records every call of a
first-party function (`wanderland_nav`, `policies`, `planners`) that is handed the configuration: the composed
`DictConfig`, or an instance of a config dataclass reachable from `TrainConfig` (`NavEnvConfig`, `CameraConfig`,
`BCConfig`, ... by their field types). A reader reads a function once, so only the first call of each function
counts (a loop over steps is read once); that call is a step into its module (a *room*), and consecutive steps
in the same room are one. Over the first `--steps` steps it counts

* rooms: distinct modules entered;
* climbs back up: steps into a module of a higher layer than the one before (layer of a part = 1 + the highest
  layer of the parts its row in ARCHITECTURE.md may import; the base parts are layer 0);
* revisits: steps into a module entered before (other than the one just left).

Prints the three counts and the room sequence. The figures depend on the code only (the smoke run is
deterministic), not on the machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import sys
import typing
from pathlib import Path

from omegaconf import DictConfig

REPO = Path(__file__).resolve().parents[2]
# the part table's reader (ARCHITECTURE.md -> parts) lives beside the test that enforces it
_spec = importlib.util.spec_from_file_location("layering", REPO / "tests" / "test_layering.py")
layering = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(layering)
PARTS, part_of = layering.PARTS, layering.part_of


def layers() -> dict[str, int]:
    """part -> layer: 0 for a part that may import nothing, else 1 + its highest allowed part's layer."""
    memo: dict[str, int] = {}

    def layer(p: str, seen=()) -> int:
        if p not in memo:
            allowed = [a for a in PARTS[p][1] if a != p and a not in seen]
            memo[p] = 0 if not allowed else 1 + max(layer(a, seen + (p,)) for a in allowed)
        return memo[p]

    return {p: layer(p) for p in PARTS}


def config_types(root) -> set[type]:
    """Every dataclass type reachable from `root`'s field annotations."""
    out, todo = set(), [root]
    while todo:
        t = todo.pop()
        if t in out or not dataclasses.is_dataclass(t):
            continue
        out.add(t)
        for hint in typing.get_type_hints(t).values():
            todo += [h for h in (hint, *typing.get_args(hint)) if isinstance(h, type)]
            for h in typing.get_args(hint):
                todo += [a for a in typing.get_args(h) if isinstance(a, type)]
    return out


def follow(exp: str, run_dir: Path) -> list[str]:
    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import TrainConfig
    from wanderland_nav.train import run

    kinds = tuple(config_types(TrainConfig))
    roots = (str(REPO / "wanderland_nav"), str(REPO / "policies"), str(REPO / "planners"))
    rooms: list[str] = []
    read: set = set()  # functions already read

    def hook(frame, event, arg):
        if event != "call":
            return
        code = frame.f_code
        if code in read or not code.co_filename.startswith(roots):
            return
        names = code.co_varnames[:code.co_argcount + code.co_kwonlyargcount]
        if any(isinstance(frame.f_locals.get(n), (DictConfig, *kinds)) for n in names):
            read.add(code)
            rel = Path(code.co_filename).resolve().relative_to(REPO).as_posix()
            if not rooms or rooms[-1] != rel:
                rooms.append(rel)

    cfg = compose_config("train", [f"+exp={exp}", "debug=smoke", f"run_dir={run_dir}", "logger=console"])
    sys.setprofile(hook)
    try:
        run(cfg)
    finally:
        sys.setprofile(None)
    return rooms


def counts(rooms: list[str], steps: int) -> dict[str, int]:
    rank = layers()
    seq = rooms[:steps]
    climbs = sum(rank[part_of(b)] > rank[part_of(a)] for a, b in zip(seq, seq[1:]))
    revisits = sum(b in seq[:i] for i, b in enumerate(seq) if i > 0)
    return {"steps": len(seq), "rooms": len(set(seq)), "climbs back up": climbs, "revisits": revisits}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--exp", default="citywalker_rl")
    ap.add_argument("--run-dir", type=Path, default=Path("outputs/follow_cfg"))
    a = ap.parse_args()
    rooms = follow(a.exp, a.run_dir)
    print(" -> ".join(r.removeprefix("wanderland_nav/").removesuffix(".py") for r in rooms[:a.steps]))
    for k, v in counts(rooms, a.steps).items():
        print(f"{k}: {v}")


if __name__ == "__main__":
    main()
