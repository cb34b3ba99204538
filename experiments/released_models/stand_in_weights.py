"""Write seeded stand-in weights for the released models, each in its release's own file format and name.

    python -m experiments.released_models.stand_in_weights <folder> [--models gnm,vint,nomad,mbra,citywalker] [--seed 46]

The fill is `policies.released.random_weights` (fan-in-scaled, the parity fixtures' rule); the files are what
`benchmark released_weights=<folder>` looks for (`compose.policy_sources.RELEASED_FILES`): a smoke run of the
paper's table through the real loaders where the real weights are absent. Real weights in the same folder
give the real table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from policies.released import random_weights as rw
from policies.released.citywalker import CityWalkerNet
from policies.released.visualnav import GNMNet, LogoNavNet, NoMaDNet, ViNTNet
from wanderland_nav.compose.policy_sources import RELEASED_FILES

NETS = {"gnm": GNMNet, "vint": ViNTNet, "nomad": NoMaDNet, "mbra": LogoNavNet, "citywalker": CityWalkerNet}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("folder")
    ap.add_argument("--models", default="gnm,vint,nomad,mbra,citywalker")
    ap.add_argument("--seed", type=int, default=46)
    a = ap.parse_args()
    root = Path(a.folder)
    root.mkdir(parents=True, exist_ok=True)
    for model in a.models.split(","):
        net = NETS[model]()
        net.load_state_dict(rw.seeded_state_dict(net, a.seed))
        path = root / RELEASED_FILES[model][0]
        if path.exists():
            raise FileExistsError(f"{path} exists; not overwritten (choose an empty folder)")
        rw.write_release_file("logonav" if model == "mbra" else model, net, path)
        print(f"{model}: {path} ({path.stat().st_size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
