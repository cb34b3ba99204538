"""The typed shape of every entry point's config: Hydra's YAML merged onto these dataclasses.

Why: a typo or a wrong type in a YAML file or on the command line must fail before anything runs,
with the key named (`Key 'widht' not in 'CameraConfig' / full_key: env.camera.widht`), instead of
falling back to a default. The library dataclasses (`NavEnvConfig`, `CollisionSettings`,
`NavMeshSettings`, `BCConfig`, `PPOConfig`, `GeneratorSettings`, `FitConfig`) are used as they
are, so there is no second, hand-written copy of their fields.

One home per default: each schema is registered in Hydra's ConfigStore as `<app>_schema` (`store_schemas`) and
is the first item of `conf/<app>.yaml`'s defaults list, so Hydra composes every YAML file onto it: a field no
file sets keeps its dataclass default, and the YAML files hold only what differs from it (conf/README.md,
"Where a default lives"; `tests/test_config_defaults.py` fails on a file that restates a default). Hydra
checks keys and types while it composes; `typed_config` is the one conversion to the dataclasses,
`at_least` / `above` on this module's fields check ranges naming the full key (`train_env.batch_size=0:
must be >= 1`), and the library dataclasses' own `__post_init__` checks theirs (the error then names the
config key of the class that refused).

The `policy` node stays a plain mapping: each architecture has its own fields and
`policies.make_policy` rejects unknown ones with the field named.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import typing
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from planners import NavMeshSettings
from wanderland_nav.compose.study_config import StudyConfig
from wanderland_nav.envs.config import CameraConfig, NavEnvConfig
from wanderland_nav.episodes.generate import GeneratorSettings
from wanderland_nav.gsfit.trainer import FitConfig
from wanderland_nav.render.lod import DEFAULT_LOD_PX
from wanderland_nav.rl.bc import BCConfig
from wanderland_nav.rl.ppo import PPOConfig
from wanderland_nav.scene.collision import CollisionSettings
from wanderland_nav.scene.generated import GENERATORS


# ------------------------------------------------------------------------------ ranges


def at_least(low: float, default, *, strict: bool = False):
    """A field whose value (when not null) must be >= `low` (> `low` with `strict`); checked by `typed_config`."""
    return field(default=default, metadata={"min": low, "strict": strict})


def above(low: float, default):
    return at_least(low, default, strict=True)


# ------------------------------------------------------------------------------ shared groups
def _check_generator(where: str, generator: str, size: str) -> None:

    if generator not in GENERATORS:
        raise ValueError(f"{where}.generator={generator!r}: expected one of {list(GENERATORS)}")
    if size not in ("small", "paper"):
        raise ValueError(f"{where}.size={size!r}: expected small or paper")


@dataclass
class SceneSetSettings:
    """`scene.set` (`conf/scene/demo_set.yaml`): many scenes trained on together and evaluated per scene.
    Demo seeds (`seeds`) or a manifest (`wanderland_nav/scene/sets.py`: folder, .txt list, .csv)."""

    root: Optional[str] = None  # where the demo seeds are built and prepare_done.json lives (null: manifest's folder)
    seeds: Optional[List[int]] = None  # procedural demo seeds (then `manifest` is ignored)
    preset: str = "tiny"  # demo seeds only
    generator: str = "demo"  # the seeds' generator: demo | district (conf/scene/district_set.yaml)
    size: str = "small"  # district seeds only: small | paper
    seed_splits: Optional[Dict[str, List[int]]] = None  # {train|val|test: seeds}: each seed's split (null: train)
    manifest: Optional[str] = None
    data_root: Optional[str] = None  # list/CSV paths resolve against it (null: the manifest's folder)
    tiers: Optional[List[str]] = None  # CSV quality tiers kept (null: all)
    split: Optional[str] = None  # manifest split kept (null: all)
    num_active: Optional[int] = at_least(1, None)  # scenes stepped at once (null: most that split train_env.batch_size evenly)
    memory_budget_gb: Optional[float] = above(0, None)  # LRU budget for loaded scenes per env (null: keep all)
    prepare_workers: int = at_least(1, 2)  # scenes prepared in parallel
    backend: str = "process"  # process (local pool) | ray (Ray tasks; RAY_ADDRESS joins a cluster) | auto | serial

    def __post_init__(self):
        if self.backend not in ("process", "ray", "auto", "serial"):
            raise ValueError(f"scene.set.backend={self.backend!r}: expected process, ray, auto or serial")
        _check_generator("scene.set", self.generator, self.size)


@dataclass
class SceneGroup:
    """`conf/scene/*.yaml`: the procedural demo (`demo: true`) or a scene folder (`scene=<path>`)."""

    name: str = "demo"  # the scene's name in tables and run folders (a folder: its basename)
    path: str = "data/scenes/demo"  # the scene folder (the demo / a district: where it is built)
    demo: bool = True  # the procedural demo (`conf/scene/demo.yaml`); a folder sets false
    seed: int = 0  # demo / district only
    preset: str = "default"  # demo only: "tiny" | "default"
    generator: str = "demo"  # with `demo: true`, the procedural generator: demo (the block) | district
    size: str = "small"  # district only: "small" | "paper"
    up_axis: Optional[str] = None  # null: the scene's own (scene_meta.json, else its layout's convention)
    set: Optional[SceneSetSettings] = None  # a scene set (train/evaluate); single-scene entry points use `path`

    def __post_init__(self):
        _check_generator("scene", self.generator, self.size)


@dataclass
class NavigationGroup:
    """`conf/navigation/default.yaml`: how a scene becomes walkable. Composed by prepare, train,
    evaluate and make_episodes alike, so the agent radius has one home."""

    prepare: bool = True  # build/refresh collision mesh + navmesh with these settings before use
    collision: CollisionSettings = field(default_factory=CollisionSettings)
    navmesh: NavMeshSettings = field(default_factory=NavMeshSettings)  # up_axis: always the scene's


# ------------------------------------------------------------------------------ train
@dataclass
class BCStage(BCConfig):
    enabled: bool = True  # run the BC phase (skipped anyway with init_checkpoint)
@dataclass
class PPOStage(PPOConfig):
    enabled: bool = True  # run the PPO phase (false: `algo=bc`)
    def __post_init__(self):
        if not self.enabled:  # a disabled stage's sizes are never used (conf/algo/bc.yaml)
            return
        try:
            super().__post_init__()
        except ValueError as e:  # name the config keys: "algo.ppo.total_frames=..."
            raise ValueError(str(e).replace("PPO: ", "algo.ppo.", 1)) from None


@dataclass
class AlgoGroup:
    name: str = "rl"  # the recipe's name in `exp_name` (rl | bc | rl_long)
    ppo: PPOStage = field(default_factory=PPOStage)
    bc: BCStage = field(default_factory=BCStage)


@dataclass
class RerunOptions:
    """`logger.rerun` (`logger=rerun`): the rerun recording's throttles."""

    rollout_every: int = at_least(0, 5)  # log every n-th eval rollout's renders (0: never)
    max_agents: int = at_least(1, 2)  # agents of a rollout shown (their frames dominate the recording's size)
    spawn: bool = False  # open the rerun viewer as well as writing rerun.rrd


@dataclass
class LoggerGroup:
    kind: str = "console"  # console | rerun
    print_every: int = at_least(1, 1)  # console
    rerun: Optional[RerunOptions] = None  # the rerun recording's options (null unless logger=rerun)


@dataclass
class CollectorGroup:
    """`conf/collector/*.yaml`: local collectors (one process, or `num_workers` processes) or
    `kind: ray`, `num_workers` TorchRL Ray collectors (`rl/ray_collector.py`), one machine or a cluster."""

    kind: str = "local"  # local | ray
    num_workers: int = at_least(1, 1)  # collector processes (local) or Ray actors, each with its own env
    address: Optional[str] = None  # ray: null starts a local instance; `auto` joins a running cluster
    cpus_per_worker: float = above(0, 1.0)  # ray
    memory_per_worker_gb: Optional[float] = above(0, None)  # ray
    sync_timeout_s: float = above(0, 600.0)  # ray: how long the weight sync waits for a worker to join (TorchRL: 60 s)
    worker_niceness: Optional[int] = 0  # ray: collector processes' niceness (null: Ray's own, 15)

    def __post_init__(self):
        if self.kind not in ("local", "ray"):
            raise ValueError(f"collector.kind={self.kind!r}: expected local or ray")


@dataclass
class EpisodeSource:
    path: Optional[str] = None  # an episodes.json instead of <scene>/episodes.json
    num: Optional[int] = at_least(1, 400)  # null: the scene's own file as it is; else a sibling file with this many (compose/episode_file.py)
    splits: Tuple[float, float, float] = (0.6, 0.15, 0.25)  # train / val / test fractions
    seed: int = 0  # the generated episodes' sampler seed
    goal_images: bool = False  # render goal views into generated episodes (image-goal tasks)
    ppo_routes: int = at_least(0, 0)  # PPO also trains on this many more routes (a train-only file drawn with ppo_routes_seed)
    ppo_routes_seed: int = 1  # must differ from `seed`: the same seed would redraw the val/test routes


@dataclass
class RenderSettings:
    # Level of detail (render/lod.py): each view renders the coarsest hierarchy nodes whose bounding sphere
    # projects to at most this many pixels (radius); null: every Gaussian (the slow reference).
    lod_px: Optional[float] = DEFAULT_LOD_PX  # pixels: the cut's largest projected node radius; null: every Gaussian
    image_size: Optional[List[int]] = None  # camera [H, W]; null: the policy's input size


@dataclass
class TrainEnvSettings:
    batch_size: int = at_least(1, 8)  # agents stepped together by BC and PPO (B)
    split: Optional[str] = "train"  # episodes.json split the training envs draw from
@dataclass
class EvalSettings:
    split: Optional[str] = "test"  # headline split (tune with eval.split=val); null: every episode
    episodes: Optional[int] = at_least(1, None)  # null: every episode of the split, once
    batch_size: int = at_least(1, 25)  # agents rendered in one batched evaluation call
    deterministic: bool = True  # evaluate the policy's mean action (false: sampled)
    sampled_rows: bool = False  # also each trained row with sampled actions ("<row> sampled"; report.SAMPLED)
    blank_camera_rows: bool = True  # also each trained row with a black camera ("<row> blank camera"; rl/blank_camera.py)


@dataclass
class TrainConfig:
    """`conf/train.yaml`. The fields run from the composition's own groups down the layers (the recipe, the env,
    the navigation settings): the typed checks run in field order, so a reader following them never climbs back."""

    scene: SceneGroup = field(default_factory=SceneGroup)
    collector: CollectorGroup = field(default_factory=CollectorGroup)
    logger: LoggerGroup = field(default_factory=LoggerGroup)
    exp_name: str = "run"  # the run folder's experiment name (default: ${policy.name}_${algo.name})
    seed: int = 0  # policy init, episode order, PPO sampling
    device: str = "cpu"  # where the policy and the env's tensors live (cpu | cuda)
    threads: Optional[int] = at_least(1, None)  # torch intra-op threads (null: torch's default)
    progress: bool = True  # tqdm bars
    run_dir: Optional[str] = None  # null: outputs/<exp_name>/<identity hash>_seed<seed>
    init_checkpoint: Optional[str] = None  # warm-start weights (a *_bc run's checkpoints/last.pt); skips the BC phase
    goal_input: str = "route"  # route | goal (rl/route_goal.py)
    route_lookahead: float = above(0, 3.0)  # metres ahead on the planned route of the `goal_input: route` point
    save_rollouts: Optional[str] = None  # a folder: one rollout .npz per evaluation
    episodes: EpisodeSource = field(default_factory=EpisodeSource)
    render: RenderSettings = field(default_factory=RenderSettings)
    train_env: TrainEnvSettings = field(default_factory=TrainEnvSettings)
    eval: EvalSettings = field(default_factory=EvalSettings)
    policy: Dict[str, Any] = field(default_factory=dict)
    algo: AlgoGroup = field(default_factory=AlgoGroup)
    env: NavEnvConfig = field(default_factory=NavEnvConfig)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)


# ------------------------------------------------------------------------------ evaluate
@dataclass
class EvaluateConfig:
    scene: SceneGroup = field(default_factory=SceneGroup)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)
    env: NavEnvConfig = field(default_factory=NavEnvConfig)
    reference: Optional[str] = "expert"  # expert | random (ignored when checkpoints are given)
    expert_path_source: str = "reference"  # expert: episode's reference_path | navmesh (fresh find_path)
    render_for_reference: bool = False  # the references never look; true renders anyway
    episodes: Optional[str] = None
    demo_episodes: int = at_least(1, 60)
    split: Optional[str] = None
    num_episodes: Optional[int] = at_least(1, None)
    checkpoints: Optional[List[str]] = None
    batch_size: int = at_least(1, 8)
    device: str = "cpu"
    seed: int = 0
    out: Optional[str] = None
    progress: bool = True
    save_rollouts: Optional[str] = None
    save_frames: bool = False


# ------------------------------------------------------------------------------ prepare / make_episodes
@dataclass
class PrepareConfig:
    scene: SceneGroup = field(default_factory=SceneGroup)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)
    force: bool = False
    navmesh_enabled: bool = True
    workers: Optional[int] = at_least(1, None)  # a scene set: scenes prepared at once (null: scene.set.prepare_workers)


@dataclass
class MakeEpisodesConfig:
    scene: SceneGroup = field(default_factory=SceneGroup)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)
    scenes: Optional[List[str]] = None  # several scenes / a folder of scenes (scene=[a,b])
    num_episodes: int = at_least(1, 100)
    seed: int = 0
    out: Optional[str] = None
    force: bool = False
    workers: Optional[int] = at_least(1, None)
    scenes_root: str = "data/scenes"
    topdown: bool = True
    progress: bool = True
    generator: GeneratorSettings = field(default_factory=GeneratorSettings)


# ------------------------------------------------------------------------------ replay / fit
@dataclass
class ReplayConfig:
    rollout: Optional[str] = None
    episodes: Optional[str] = None
    scene_path: Optional[str] = None
    out: Optional[str] = None
    viewer: bool = False
    frames: str = "auto"  # auto | render | none
    lod_px: Optional[float] = DEFAULT_LOD_PX  # as train's render.lod_px (the same camera); null: every Gaussian
    agents: Optional[List[int]] = None
    max_episodes: int = at_least(1, 8)
    max_points: int = at_least(1, 50000)
    max_cameras: int = at_least(0, 32)
    frame_chunk: int = at_least(1, 64)
    device: str = "cpu"
    camera: CameraConfig = field(default_factory=CameraConfig)
    num_waypoints: int = at_least(1, 5)
    path_stride: int = at_least(1, 1)
    control_period: float = above(0, 0.5)


@dataclass
class LpipsPaths:
    backbone_path: Optional[str] = None
    lin_path: Optional[str] = None


@dataclass
class FitRunConfig:
    scene: SceneGroup = field(default_factory=SceneGroup)
    out_dir: Optional[str] = None  # null: outputs/fit/<scene>/<run identity hash>
    resume: bool = True
    evaluate: bool = True
    eval_max_views: Optional[int] = at_least(1, 24)
    export_to_scene: bool = False
    log_every: int = at_least(1, 50)
    rerun: bool = False
    progress: bool = True
    threads: Optional[int] = at_least(1, None)
    lpips: LpipsPaths = field(default_factory=LpipsPaths)
    fit: FitConfig = field(default_factory=FitConfig)


@dataclass
class ExportUsdConfig:
    scene: SceneGroup = field(default_factory=SceneGroup)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)
    out: Optional[str] = None
    gaussians: bool = True
    max_gaussians: Optional[int] = None
    cameras: bool = True
    episodes: bool = True


@dataclass
class ReconEvalConfig:
    pred: Optional[str] = None
    gt: Optional[str] = None
    name: Optional[str] = None
    max_time_diff: float = at_least(0, 0.01)
    time_offset: float = 0.0
    rpe_delta: int = at_least(1, 1)
    collinear_tol: float = at_least(0, 1e-9)
    chunk_pairs: int = at_least(1, 65536)
    device: str = "cpu"
    out: Optional[str] = None
    plot: bool = True
    rerun: bool = True
    nvs: Optional[str] = None
    nvs_split: str = "val"
    nvs_holdout_every: int = at_least(1, 8)
    nvs_downscale: float = above(0, 1.0)
    lpips: LpipsPaths = field(default_factory=LpipsPaths)


# ------------------------------------------------------------------------------ make_env (Python API)
@dataclass
class MakeEnvEpisodes:
    path: Optional[str] = None
    num: int = 60
    seed: int = 0
    goal_images: bool = False


@dataclass
class MakeEnvConfig:
    """`conf/make_env.yaml`: `wanderland_nav.make_env`, one TorchRL env from Python."""

    scene: SceneGroup = field(default_factory=SceneGroup)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)
    env: NavEnvConfig = field(default_factory=NavEnvConfig)
    batch_size: int = 1
    device: str = "cpu"
    seed: Optional[int] = None  # null: 0 in the main process, a distinct seed per worker process (make_env.process_seed)
    episodes: MakeEnvEpisodes = field(default_factory=MakeEnvEpisodes)
    render: RenderSettings = field(default_factory=RenderSettings)

# ------------------------------------------------------------------------------ benchmark / serve_policy
@dataclass
class BenchmarkConfig:
    scene: SceneGroup = field(default_factory=SceneGroup)
    navigation: NavigationGroup = field(default_factory=NavigationGroup)
    env: NavEnvConfig = field(default_factory=NavEnvConfig)
    tasks: List[str] = field(default_factory=lambda: ["pointgoal", "imagegoal", "instruction"])
    pointgoal_input: str = "goal"        # goal: the final goal's vector | route: the route point ahead (CityWalker)
    route_lookahead: float = 3.0
    policies: List[Any] = field(default_factory=lambda: [{"name": "expert", "reference": "expert"},
                                                          {"name": "random", "reference": "random"}])
    # [{name, reference|checkpoint|target|url|model|navdp_url, ...}]
    released_weights: Optional[str] = None  # a folder of released files: one `model` entry per file found
    baseline: Optional[str] = None       # the policy the paired differences are against (null: the first)
    episodes: Optional[str] = None
    demo_episodes: int = at_least(1, 60)
    split: Optional[str] = None
    num_episodes: Optional[int] = at_least(1, None)
    batch_size: int = at_least(1, 8)
    image_size: List[int] = field(default_factory=lambda: [64, 64])  # camera of a policy that names no size
    lod_px: Optional[float] = DEFAULT_LOD_PX  # one camera for every policy: the faithful cut, whatever cut a policy trained at
    timeout_s: float = 30.0
    max_consecutive_failures: int = at_least(1, 3)
    device: str = "cpu"
    seed: int = 0
    out: Optional[str] = None
    progress: bool = True


@dataclass
class ServePolicyConfig:
    target: Optional[str] = None         # pkg.module:Class (a protocol policy, wanderland_nav.external.protocol)
    kwargs: Dict[str, Any] = field(default_factory=dict)
    checkpoint: Optional[str] = None     # or a trained checkpoint of a package policy
    model: Optional[str] = None          # or a released model (gnm|vint|nomad|mbra|citywalker) ...
    weights: Optional[str] = None        # ... with its released file
    protocol: str = "wanderland"         # wanderland (/info, /act, .npz) | navdp (NavDP's contract)
    host: str = "127.0.0.1"
    port: int = at_least(0, 8765)        # 0: a free port (the printed url says which)
    device: str = "cpu"
    max_body_mb: int = at_least(1, 64)   # the largest request body read (its arrays bounded the same, uncompressed)
    allowed_hosts: List[str] = field(default_factory=list)  # Host names accepted besides IP addresses and localhost


SCHEMAS = {"train": TrainConfig, "evaluate": EvaluateConfig, "prepare": PrepareConfig, "make_episodes": MakeEpisodesConfig,
           "replay": ReplayConfig, "fit": FitRunConfig, "recon_eval": ReconEvalConfig,
           "export_usd": ExportUsdConfig, "study": StudyConfig, "make_env": MakeEnvConfig,
           "benchmark": BenchmarkConfig, "serve_policy": ServePolicyConfig}


def store_schemas() -> None:
    """Every entry point's schema in Hydra's ConfigStore as `<app>_schema`, the base its `conf/<app>.yaml` extends
    (first in its defaults list). Frozen library dataclasses are stored writable, so the YAML can be merged in."""

    store = ConfigStore.instance()
    for app, schema in SCHEMAS.items():
        store.store(name=f"{app}_schema", node=copy.deepcopy(schema_node(schema)), provider="wanderland_nav")


@functools.lru_cache(maxsize=None)
def schema_node(schema: type) -> DictConfig:
    """`schema` as an OmegaConf node with every default, built once per class (merging never changes it): the
    frozen library dataclasses' read-only flags cleared, so YAML can be merged in (`to_object` still builds them
    frozen)."""
    return _writable(OmegaConf.structured(schema))


def typed_config(cfg: DictConfig | dict, schema: type):
    """The composed config as `schema`'s dataclasses; an unknown key or a wrong type raises with its
    full key (`env.camera.widht`), a range error with the dataclass field (from `__post_init__`)."""
    node = schema_node(schema)
    if isinstance(cfg, DictConfig):  # as plain containers: a key Hydra added past the schema (`+key=`) is refused
        cfg = OmegaConf.to_container(cfg, resolve=False)
    merged = OmegaConf.merge(node, cfg)
    try:
        obj = OmegaConf.to_object(merged)
    except ValueError as e:  # a library dataclass's own range check names its class: add the config key
        where = _config_keys_of(schema).get(str(e).split(":")[0].split(".")[0].split(" ")[0])
        raise ValueError(f"{e} (config key: {where})" if where else str(e)) from None
    # One pass over the built dataclasses (here, not in helpers, so the checks are read in one place): the
    # `tuple[...]` fields get their tuples back (OmegaConf returns lists; tuples are hashable and equal the
    # defaults), every `at_least` / `above` field is in range with the full key in the error, and every number is
    # finite (a library class's `> 0` lets `inf` through, and NaN fails no `if x < low`).
    todo = [(obj, "")]
    while todo:
        node, prefix = todo.pop()
        for f in dataclasses.fields(node):
            value, key = getattr(node, f.name), f"{prefix}{f.name}"
            if dataclasses.is_dataclass(value):
                todo.append((value, key + "."))
                continue
            if isinstance(value, list) and str(f.type).startswith(("tuple", "Tuple")):
                value = tuple(value)
                object.__setattr__(node, f.name, value)  # frozen dataclasses too
            if "min" in f.metadata and value is not None:
                low, strict = f.metadata["min"], f.metadata["strict"]
                if isinstance(value, bool) or not math.isfinite(value) or (value <= low if strict else value < low):
                    raise ValueError(f"{key}={value}: must be {'>' if strict else '>='} {low:g}")
            elif any(isinstance(v, float) and not math.isfinite(v) for v in
                     (value if isinstance(value, (list, tuple)) else [value])):
                raise ValueError(f"{key}={value}: must be a finite number")
    return obj


def _override_key(override: str) -> str:
    """`+algo.ppo.lr=1` -> `algo.ppo.lr`: the key a Hydra override sets."""
    return override.split("=", 1)[0].lstrip("+~")


def study_config(cfg) -> StudyConfig:
    """The composed config typed, with the `debug=<x>` sizes (`study_debug`) merged over `study` and the study's
    `policy` family appended to its `train` recipe."""
    cfg = OmegaConf.create(OmegaConf.to_container(cfg, resolve=True))
    if cfg.get("study_debug"):
        debug = OmegaConf.to_container(cfg.study_debug)
        drop = set(debug.pop("ppo_stage_drop", []))
        study = OmegaConf.merge(cfg.get("study") or {}, debug)
        if drop and study.get("ppo_stage"):  # a staged study's PPO at the debug train's sizes: still minutes
            kept = [o for o in study.ppo_stage if _override_key(o) not in drop]
            study.ppo_stage = kept or ["algo.ppo.enabled=true"]  # still a stage, so its cells are exercised
        cfg.study = study
    if cfg.get("study") is not None and cfg.study.get("policy"):  # after the debug sizes: a smoke keeps the family
        own = [o for o in cfg.study.get("train", []) if _override_key(o) != "policy"]
        cfg.study.train = [*own, f"policy={cfg.study.policy}"]
    return typed_config(cfg, StudyConfig)


def _config_keys_of(schema: type, prefix: str = "") -> dict[str, str]:
    """{dataclass name (and its bases'): the config key where it sits} for every nested dataclass field."""
    out: dict[str, str] = {}
    hints = typing.get_type_hints(schema)
    for f in dataclasses.fields(schema):
        t = hints.get(f.name)
        if dataclasses.is_dataclass(t):
            for base in t.__mro__:
                out.setdefault(base.__name__, prefix + f.name)
            out.update({k: v for k, v in _config_keys_of(t, f"{prefix}{f.name}.").items() if k not in out})
    return out


def _writable(node: DictConfig) -> DictConfig:
    """Frozen library dataclasses become read-only nodes; clear the flag on each so the YAML can be
    merged in (`to_object` still builds the frozen objects)."""
    OmegaConf.set_readonly(node, False)
    for key in node:
        child = node._get_node(key)
        if isinstance(child, DictConfig):
            _writable(child)
    return node
