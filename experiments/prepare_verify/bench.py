"""Cost of `prepare_scene` on an already prepared scene (the up-to-date path), median of 5 calls.

The up-to-date check verifies that each cached artefact is intact (sha256 of its bytes
against the sidecar). To compare two code versions, run both back to back:

    PYTHONPATH=/tmp/base-<you> python experiments/prepare_verify/bench.py /tmp/demo_tiny
    PYTHONPATH=$PWD            python experiments/prepare_verify/bench.py /tmp/demo_tiny

The scene folder is made once (and copied, so both runs start from the same bytes) with
`make_demo_scene(path, seed=0, preset="tiny")`.
"""

from __future__ import annotations

import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch

from wanderland_nav.preparation.scene import prepare_scene
from wanderland_nav.scene.collision import CollisionSettings


def main(src: Path, repeats: int = 5) -> None:
    torch.set_num_threads(1)
    scene = Path(tempfile.mkdtemp()) / "demo"
    shutil.copytree(src, scene)
    settings = CollisionSettings(voxel_size=0.25)
    prepare_scene(scene, collision=settings)  # builds or refreshes the sidecars
    seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = prepare_scene(scene, collision=settings)
        seconds.append(time.perf_counter() - t0)
        assert out.meta["prepare"]["navmesh"]["skipped"], "expected the up-to-date path"
    print(f"up-to-date prepare_scene: median {statistics.median(seconds) * 1e3:.0f} ms "
          f"(min {min(seconds) * 1e3:.0f} ms, {repeats} calls)")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
