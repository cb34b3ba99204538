"""Shared fixtures: real data from ../shared/data and small generated scenes."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

# Idle OpenMP threads sleep instead of spinning: on a loaded machine spinning threads made CPU
# splat renders 40-150x slower (experiments/gsfit_depth_ablation). Must be set before torch loads.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
import torch  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
# pytest puts tests/ on sys.path, where tests/policies (and tests/planners) would shadow the editable-installed
# top-level packages as namespace packages; the checkout itself must come first.
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))
SHARED_DATA = Path(os.environ.get("WANDERLAND_SHARED_DATA", REPO.parent / "shared" / "data"))


def _damage_file(path: Path, how: str, bit_at: int = 200) -> bytes:
    """Damage a cache file as disks and killed copies do: "truncated" (half), "empty", or "bit_flipped" (one bit
    at byte `bit_at`, inside an `.npz`'s first member). -> its good bytes."""
    good = path.read_bytes()
    if how == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif how == "empty":
        path.write_bytes(b"")
    else:
        flipped = bytearray(good)
        flipped[bit_at] ^= 0x10
        path.write_bytes(bytes(flipped))
    return good


@pytest.fixture()
def damage_file():
    """`damage_file(path, how, bit_at=200)`: see `_damage_file`."""
    return _damage_file


@pytest.fixture(autouse=True)
def _deterministic_torch():
    torch.manual_seed(0)
    torch.set_num_threads(min(2, os.cpu_count() or 1))
    yield


def shared_data_missing() -> str:
    """Why the real-data tests cannot run here, or "" when the data is present."""
    if SHARED_DATA.is_dir():
        return ""
    return (f"real test data not found at {SHARED_DATA}: set WANDERLAND_SHARED_DATA to a folder holding "
            "meshes/, splats/, lidar/kitti/, trajectories/ and av2/ (the project's shared test data, "
            "described in its README), or place that folder at ../shared/data beside the checkout")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real test data beside the checkout. Missing data skips the test with the reason, except under CI
    (`CI` set), where it must be present and its absence is a failure: a CI run never passes by skipping."""
    why = shared_data_missing()
    if why and os.environ.get("CI"):
        pytest.fail(why)
    if why:
        pytest.skip(why)
    return SHARED_DATA


@pytest.fixture(scope="session")
def tiny_demo_scene(tmp_path_factory) -> Path:
    """The procedural demo block, preset "tiny" (seed 0): v1 layout, -Y up, built once per session (~1-2 s)."""
    from wanderland_nav.scene.demo import make_demo_scene

    return make_demo_scene(tmp_path_factory.mktemp("demo") / "demo_tiny", seed=0, preset="tiny")


@pytest.fixture(scope="session")
def prepared_demo_scene(tiny_demo_scene, tmp_path_factory) -> Path:
    """(SCENE) A copy of the tiny demo with `collision_mesh.ply` + `navmesh.npz` from `prepare_scene`.

    Copied so the demo fixture's own folder stays as `make_demo_scene` wrote it. Collision voxels
    of 0.25 m (test size); navmesh with the agent every entry point composes by default
    (`conf/navigation/default.yaml`, up axis from the scene), so a command composed over this scene with the
    default settings finds it up to date instead of rebaking it under the other tests.
    """
    import shutil

    from wanderland_nav.compose import compose_config
    from wanderland_nav.compose.schema import PrepareConfig, typed_config
    from wanderland_nav.preparation.scene import prepare_scene
    from wanderland_nav.scene.collision import CollisionSettings

    dst = tmp_path_factory.mktemp("prepared") / Path(tiny_demo_scene).name
    shutil.copytree(tiny_demo_scene, dst)
    navmesh = typed_config(compose_config("prepare", []), PrepareConfig).navigation.navmesh
    prepare_scene(dst, collision=CollisionSettings(voxel_size=0.25), navmesh=navmesh)
    return dst


@pytest.fixture(scope="session")
def demo_episodes(prepared_demo_scene) -> Path:
    """(EXPERT) `episodes.json` for the prepared tiny demo: 8 episodes, seed 0, no goal images
    (the CPU renderer costs seconds per view; tests/episodes renders its own few).

    Written into the scene folder, so `load_scene` sees it.
    """
    from planners import NavMesh
    from wanderland_nav.episodes.generate import GeneratorSettings, write_scene_episodes
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    out = Path(prepared_demo_scene) / "episodes.json"
    write_scene_episodes(scene, NavMesh.load(scene.navmesh_path), out, num_episodes=8, seed=0,
                         settings=GeneratorSettings(goal_images=False))
    return out


@pytest.fixture
def one_thread():
    """Tiny models: one intra-op thread is fastest, and on a shared 2-core box far more predictable."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def entry_point():
    """`entry_point(name, *overrides)` runs `python -m wanderland_nav.<name> <overrides>` in-process: the same
    Hydra composition and `scene=<folder>` shorthand as the command line, then the module's `run`."""
    import importlib

    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from wanderland_nav.compose.cli import scene_overrides

    def run(name: str, *overrides: str):
        with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
            cfg = compose(name, overrides=scene_overrides(list(overrides)))
        module = importlib.import_module(f"wanderland_nav.{name}")
        if name == "fit":
            return module.run_fit(cfg)
        return module.run(OmegaConf.to_container(cfg, resolve=True) if name == "recon_eval" else cfg)

    return run


@pytest.fixture
def run_snippet(monkeypatch):
    """`run_snippet(code, **scene_kwargs)` executes a snippet as the docs write it, with every
    `make_env("demo", ...)` it reaches (`wanderland_nav.make_env`, the Gymnasium env's, a worker's through a
    pickled `partial`) given `scene_kwargs` first (the test's tiny scene; the snippet's own keywords win, nested
    dicts merged). Returns the snippet's namespace."""
    import textwrap

    import wanderland_nav
    import wanderland_nav.compose.make_env as module
    from doc_snippets import merged

    real = module.make_env

    def run(code: str, **scene_kwargs):
        def make_env(scene="demo", **kw):
            assert scene == "demo", scene
            return real(**merged(scene_kwargs, kw))

        monkeypatch.setitem(wanderland_nav.__dict__, "make_env", make_env)
        monkeypatch.setattr(module, "make_env", make_env)
        scope = {"__name__": "__snippet__"}
        exec(textwrap.dedent(code), scope)
        return scope

    return run
