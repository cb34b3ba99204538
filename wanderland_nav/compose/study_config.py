"""The typed shape of `python -m wanderland_nav.study +study=<name>` (`conf/study.yaml`, `conf/study/*.yaml`).

Why a schema of its own: the study is a grid of ordinary `train` runs and evaluations; its own keys are
the grid (which degraded environments, which seeds, which fixed policies) and the evaluation sizes,
while the recipe sizes stay `train` overrides (`study.train`), typed by `train`'s own schema when each
cell composes its config. A typo fails before any cell runs.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

#: the phases a training run leaves a checkpoint for (`rl/recipe.py`: `bc.pt`, `last.pt`), and the random init
POLICY_PHASES = ("untrained", "BC", "BC+RL")
#: also a phase: `BC-round<k>`, the BC policy after its k-th round (`checkpoints/bc_round<k>.pt`): a weaker fixed
#: policy, so a ranking test has more distinct skill levels than untrained / BC / BC+RL
BC_ROUND = re.compile(r"BC-round([1-9][0-9]*)")


def is_policy_phase(phase: str, *, trained: bool = False) -> bool:
    """A phase in POLICY_PHASES or `BC-round<k>`; `trained`: one a training run produces (not untrained)."""
    return (phase in POLICY_PHASES[trained:]) or BC_ROUND.fullmatch(phase) is not None
#: how a degraded environment is evaluated (Fig. 8): on its own test episodes, or on the grounded ones mapped into it
PROTOCOLS = ("own", "grounded_routes")


#: the parts a study config may run (`study.parts`): the grounding grid above (Table 3, Fig. 8 and the misranking
#: test), the main job over `seeds`, the pedestrian study over its policies, the task families (the benchmark)
PARTS = ("main_job", "pedestrians", "grounding", "task_families")


@dataclass
class MainJobPart:
    """`study.main_job`: the main job (`train` with these overrides), one cell per seed of `study.seeds`."""

    train: List[str] = field(default_factory=lambda: ["+exp=citywalker_rl"])


@dataclass
class PedestrianPart:
    """`study.pedestrians`: the main job's BC and BC+RL of every seed evaluated among `counts` people each."""

    counts: List[int] = field(default_factory=lambda: [0, 10, 30])
    evaluate: List[str] = field(default_factory=lambda: ["scene.preset=tiny", "split=test", "num_episodes=null",
                                                         "batch_size=25"])


@dataclass
class TaskFamilyPart:
    """`study.task_families`: per seed, one `train` run per experiment and one benchmark over their BC checkpoints
    (the tasks each fits). The point-goal row is the main job's BC, or with `pointgoal` set that experiment trained
    as one more of these runs (so all three policies share `train`: e.g. a district, conf/study/task_families/)."""

    exps: List[str] = field(default_factory=lambda: ["nomad_imagegoal_rl", "instruction_rl"])
    pointgoal: Optional[str] = None  # null: the main job's BC (its cells); an experiment: trained with `train`
    train: List[str] = field(default_factory=lambda: ["algo.ppo.enabled=false"])  # the table compares BC phases
    benchmark: List[str] = field(default_factory=lambda: ["scene.preset=tiny", "split=test", "num_episodes=null",
                                                          "pointgoal_input=route", "batch_size=25", "baseline=random"])


@dataclass
class StudyGroup:
    """`conf/study/<name>.yaml`: the grid and its sizes."""

    name: str = "grounding"
    presets: List[str] = field(default_factory=lambda: ["scale_0.8", "scale_1.2", "drift", "splat_mesh", "video3dgs"])
    degrade_seed: int = 0  # the seed of the stochastic degradations (drift, holes): one degraded world per preset
    seeds: List[int] = field(default_factory=lambda: [0])  # training seeds (policy init, episodes order, PPO)
    train: List[str] = field(default_factory=lambda: ["+exp=citywalker_rl"])  # `train` overrides: the recipe sizes
    # the policy family of every train cell (`policy=<name>` appended to `train`); at every size, as a debug size's
    # `train` replaces the study's: null: the recipe's own policy
    policy: Optional[str] = None
    # `train` overrides of a separate PPO stage (e.g. the learning recipe's PPO sizes): when set, every train cell
    # gets a `ppo` cell = `train` with `train` + these + init_checkpoint=<the train cell's bc.pt>, and BC+RL is that
    # cell's policy. The train cells (BC, and their own PPO, then unused) keep their hash, so a study re-runs only
    # the PPO with a new budget and stays paired on the same BC policies; [] : BC+RL is the train cell's own PPO
    ppo_stage: List[str] = field(default_factory=list)
    fixed_policies: List[str] = field(default_factory=lambda: list(POLICY_PHASES))  # grounded-trained, Fig.-8 rows
    table3_phases: List[str] = field(default_factory=lambda: ["BC", "BC+RL"])  # degraded-trained rows of Table 3
    # Fig. 8 in a degraded env: "own" = its own test episodes; "grounded_routes" = the grounded test episodes
    # mapped into its frame (the paper's protocol, `grounding_study/routes.py`); the grounded env has one set
    protocols: List[str] = field(default_factory=lambda: list(PROTOCOLS))
    ranked_phases: List[str] = field(default_factory=lambda: ["BC+RL"])  # degraded-trained policies added to the
    # Fig.-8 ranking (evaluated on the grounded routes in every env), so Kendall tau has more than 3 policies
    trained_presets: Optional[List[str]] = None  # presets BC+PPO is trained in (Table 3); null: all. The others are
    # only evaluated in (Fig. 8), which costs a fraction of a training
    ranking_seeds: Optional[List[int]] = None  # seeds with the full Fig.-8 grid (own protocol + ranked_phases); null: all
    eval_split: str = "test"
    eval_episodes: Optional[int] = None  # null: every episode of the split
    eval_batch_size: int = 10
    rank_metric: str = "SR"  # the metric policies are ranked by in the Fig.-8 agreement
    bootstrap_resamples: int = 1000
    # dotted train-config keys (prefixes) whose change since a train cell ran is accepted on reuse, e.g.
    # env.camera.render_chunk; any other difference refuses the study (`StudyCells.check_trained_recipes`)
    accept_recipe_changes: List[str] = field(default_factory=list)
    retry_failed: bool = False  # a failed cell (e.g. a navmesh too broken for episodes) is re-run on restart
    # `episodes.sampler.SamplerSettings` overrides for every environment's episodes (e.g. camera_radius on a LiDAR
    # street whose capture path is a few metres long); {}: the recipe's own episodes file, as `train` makes it
    episode_sampler: Dict[str, Any] = field(default_factory=dict)
    parts: List[str] = field(default_factory=lambda: ["grounding"])  # which of `PARTS` run, in this order
    main_job: MainJobPart = field(default_factory=MainJobPart)
    pedestrians: PedestrianPart = field(default_factory=PedestrianPart)
    task_families: TaskFamilyPart = field(default_factory=TaskFamilyPart)
    # appended to every main-job, pedestrian and task-family cell's command (debug=smoke: `debug=smoke`, so each
    # runs at its entry point's smoke size)
    part_overrides: List[str] = field(default_factory=list)


@dataclass
class SourceScene:
    """The grounded scene every environment is built from: the demo block, a generated district or a scene folder."""

    path: str = "data/scenes/demo"
    demo: bool = True  # generated on first use (`generator`); false: `path` is a scene folder
    demo_seed: int = 0  # the generator's seed
    demo_preset: str = "tiny"  # the demo block's preset
    generator: str = "demo"  # demo (the block) | district (`conf/scene/district.yaml`)
    size: str = "small"  # a district's size: small | paper


@dataclass
class StudyConfig:
    study: StudyGroup = field(default_factory=StudyGroup)
    source: SourceScene = field(default_factory=SourceScene)
    out: str = "outputs/study/grounding"  # cells, done-manifest, table.txt, chart and recording
    threads: Optional[int] = None  # torch intra-op threads for every cell
    report_only: bool = False  # write table.txt / fig8.png / meshes.rrd from the cells done so far; run none
    device: str = "cpu"
    study_debug: Optional[Dict[str, Any]] = None  # debug=smoke sizes, merged over `study` (`study_config`)
    # a Ray cluster's address ("auto", "ray://host:10001", or "local": start one on this machine): cells whose needs
    # are done run as Ray tasks side by side, `ray_cpus_per_cell` CPUs each; null: one cell after another here
    ray: Optional[str] = None
    ray_cpus_per_cell: int = 1
