"""`make_env`: a TorchRL environment in one call, composed exactly as the entry points compose theirs.

Why through Hydra and `conf/make_env.yaml`: the scene, its navigation settings and the env's defaults
have one home each (`conf/scene`, `conf/navigation`, `conf/env`), so `make_env(scene="demo")` and
`python -m wanderland_nav.train scene=demo` prepare the same navmesh and step the same env. The
defaults fit together: the demo at its CPU-sized preset, episodes generated when the scene has none,
the camera's Gaussians loaded (`build.scene_gaussians`) when the camera is on, goal views loaded when
the episodes name them (`build.env_factory`), and a policy-facing env: no privileged ground truth,
episode metrics at done, `pixels` for video.

A scene set (`scene="demo_set"`, or `scene.set.*` overrides) gives one env over all its scenes, prepared
and given episodes in parallel and resumably as `train` does (`compose.scene_sets.scene_work`).

Keyword overrides are spelled as on the command line, one per config key: `batch_size=8`,
`debug="smoke"` (a group), `env={"camera": {"width": 64}}` (nested) or `**{"env.camera.width": 64}`.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing

from wanderland_nav.compose.build import env_factory, load_navmesh, scene_gaussians, shaped_env_config
from wanderland_nav.compose.cli import compose_config
from wanderland_nav.compose.scene_sets import scene_env_fn, scene_work
from wanderland_nav.compose.schema import MakeEnvConfig, typed_config
from wanderland_nav.rl.scene_sets import multi_scene_env_fn


def hydra_overrides(values: dict, prefix: str = "") -> list[str]:
    """`{"env": {"camera": {"width": 64}}, "debug": "smoke"}` -> `["env.camera.width=64", "debug=smoke"]`."""
    out = []
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out += hydra_overrides(value, f"{name}.")
        else:
            out.append(f"{name}={_hydra_value(value)}")
    return out


def _hydra_value(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_hydra_value(v) for v in value) + "]"
    text = str(value)
    plain = text and all(ch.isalnum() or ch in "_-./:+~" for ch in text)
    return text if plain else json.dumps(text)  # Hydra reads a double-quoted string as it is


def make_env_config(scene: str = "demo", **overrides) -> MakeEnvConfig:
    """The typed `conf/make_env.yaml` with `scene` and the overrides applied (a typo raises, key named)."""
    cfg = compose_config("make_env", [f"scene={scene}", *hydra_overrides(overrides)])
    return typed_config(cfg, MakeEnvConfig)


def make_env(scene: str = "demo", *, policy=None, **overrides):
    """A `NavEnv` (TorchRL `EnvBase`, `batch_size=[batch_size]`) on `scene` ("demo" or a scene folder), or
    for a scene set (`scene="demo_set"`, or any `scene.set` block) a `MultiSceneNavEnv` whose `batch_size`
    agents are spread over the set's scenes (`scene.set.num_active` at a time), as `train` steps a set.

    Args:
        scene: "demo" (the procedural block, built under `data/scenes/` on first use), "demo_set", or a scene
            folder.
        policy: a library policy (`policies.make_policy`); the camera size, history and waypoint action are
            shaped to it (`compose.shaped_env_config`), as `train` does. Without one the camera is the main
            job's: 32 x 32 px (its CityWalker-style policy's input) at the 2-px level of detail.
        overrides: keys of `conf/make_env.yaml`, spelled as on the command line (see the module docstring):

            - `batch_size` (1): agents stepped together.
            - `device` ("cpu"): where the state, observations and camera live (the navmesh stays on the CPU).
            - `seed` (None): the episode sampler's seed. None: 0 in the main process and a distinct seed in
              every worker process (`process_seed`), so `ParallelEnv` / `MultiSyncCollector` workers built from
              one `make_env` walk different episodes; an explicit seed is used as given in every process
              (then seed the workers apart with `env.set_seed` / `collector.set_seed`).
            - `episodes`: `path` (an episodes.json instead of the scene's own), `num` (60) / `seed` (0) /
              `goal_images` (False) for the episodes generated when the scene has none.
            - `render`: `lod_px` (2.0: the level of detail, pixels; None: every Gaussian), `image_size` (None:
              the policy's input size; with a policy only).
            - `env`: any `NavEnvConfig` field (`env={"camera": {"width": 64}}`, `env={"expert_action": True}`,
              `env={"privileged": True}`, `env={"termination": {"max_steps": 200}}`, `env={"camera": {"render_backend":
              "torch"}}`); the defaults make it
              policy-facing: no `privileged/`, `("next", "episode", ...)` metrics, `pixels` for video.
            - `scene`, `navigation`: the scene group's fields (`scene={"preset": "default"}`: the 500k-Gaussian
              demo instead of the tiny one) and the navmesh / collision settings
              (`navigation={"navmesh": {"agent_radius": 0.3}}`, `navigation={"prepare": False}`).
            - `debug` ("none" | "smoke"): the test sizes (`conf/debug_sizes/smoke_make_env.yaml`).
    """
    c = make_env_config(scene, **overrides)
    seed = c.seed if c.seed is not None else process_seed()
    env_cfg = shaped_env_config(c.env, policy, c.render.image_size) if policy is not None else c.env
    work = scene_work(c.scene, c.navigation, num_episodes=c.episodes.num, seed=c.episodes.seed,
                      goal_images=c.episodes.goal_images, episodes=c.episodes.path, episodes_key="episodes.path")
    if work.per_scene:  # one env over the set's scenes, as `train` steps a set
        scene_env = scene_env_fn(work.folders, env_cfg, split=None, device=c.device, lod_px=c.render.lod_px)
        return multi_scene_env_fn(list(work.folders), scene_env, batch_size=c.batch_size,
                                  num_active=work.settings.num_active, device=c.device,
                                  memory_budget_gb=work.settings.memory_budget_gb, seed=seed)()
    loaded = work.first()
    gaussians = scene_gaussians(loaded, c.render.lod_px, needed=env_cfg.camera.enabled)
    return env_factory(loaded, work.episodes[loaded.name], env_cfg, split=None, batch_size=c.batch_size, seed=seed,
                       device=c.device, navmesh=load_navmesh(loaded), gaussians=gaussians)()


def process_seed() -> int:
    """`make_env`'s seed when none is given: 0 in the main process; in a child process (a `ParallelEnv` or
    `MultiSyncCollector` worker, a Gymnasium `AsyncVectorEnv` worker) one derived from its place in the process
    tree (`multiprocessing`'s identity, `(k,)` for the parent's k-th child), so every worker differs and the
    same program gives the same seeds on every run."""
    identity = multiprocessing.current_process()._identity
    if not identity:
        return 0
    return int.from_bytes(hashlib.sha256(repr(tuple(identity)).encode()).digest()[:4], "little")
