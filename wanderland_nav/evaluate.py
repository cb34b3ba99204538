"""Evaluate: `python -m wanderland_nav.evaluate [reference=expert|random] [scene=<demo | folder>]`, or trained
policies side by side: `checkpoints=[a.pt,b.pt]` (each in the env it was trained in; the first is the baseline;
`env.pedestrians.*` of this command is the crowd they all meet).
`scene=demo_set` (a scene set) evaluates every scene of the set, with a row per scene
(`compose.scene_sets.scene_work`: a single scene is a set of one).

Prints the NE / SR / SPL / IR table (overall, indoor / outdoor) and writes `eval_<name>.{csv,json}` to `out`
(default: Hydra's run folder), each row tagged with the run identity. The scene is prepared and its episodes
made on first use; the reference policies never look, so the camera is off for them.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from wanderland_nav.compose import blind_env_config, run_identity, typed_config
from wanderland_nav.compose.cli import hydra_output_dir
from wanderland_nav.compose.comparison import compare_checkpoints, write_comparison
from wanderland_nav.compose.evaluating import reference
from wanderland_nav.compose.scene import refuse_set
from wanderland_nav.compose.scene_sets import scene_work
from wanderland_nav.compose.schema import EvaluateConfig
from wanderland_nav.envs.pedestrians.config import PedestrianConfig
from wanderland_nav.evaluation import Evaluator
from wanderland_nav.evaluation.loop import write_results


def run(cfg: DictConfig):
    """Everything `main` does, callable with a composed config (tests)."""
    c: EvaluateConfig = typed_config(cfg, EvaluateConfig)
    if c.save_rollouts:  # a recording is one scene's
        refuse_set(c.scene, f"save_rollouts={c.save_rollouts}: rollouts are recorded for one scene")
    work = scene_work(c.scene, c.navigation, num_episodes=c.demo_episodes, seed=c.seed,
                      goal_images=c.render_for_reference, episodes=c.episodes)
    identity = run_identity(OmegaConf.to_container(cfg, resolve=True), work.identity())
    out = Path(c.out) if c.out is not None else hydra_output_dir()
    split = c.split if c.split is not None else c.env.split
    if c.checkpoints:
        crowd = c.env.pedestrians or PedestrianConfig(count=0)  # this command's (none without env/pedestrians=crowd)
        rows, results, table = compare_checkpoints(c.checkpoints, work, split=split, num_episodes=c.num_episodes,
                                                   batch_size=c.batch_size, device=c.device, seed=c.seed,
                                                   progress=c.progress, pedestrians=crowd,
                                                   save_rollouts=c.save_rollouts, save_frames=c.save_frames)
        print(f"{work.label}: split {split}\n{table}", flush=True)
        if c.save_rollouts:
            print(f"wrote one rollout per checkpoint to {c.save_rollouts}")
        write_comparison(out, rows, table, results, identity["hash"])
        return rows
    env_cfg = c.env
    if env_cfg.camera.enabled and not c.render_for_reference:
        env_cfg = blind_env_config(env_cfg)
        print(f"reference {c.reference} does not read images: rendering is off (render_for_reference=true)")
    scenes = work.eval_scenes(env_cfg, split=split, batch_size=c.batch_size, seed=c.seed, device=c.device)
    res = Evaluator(scenes, per_scene=work.per_scene, num_episodes=c.num_episodes, seed=c.seed, progress=c.progress,
                    frames=c.save_frames).evaluate(reference(c), c.reference, rollout=c.save_rollouts)
    if c.save_rollouts:
        print(f"wrote rollouts to {c.save_rollouts}")
    print(f"{work.label}: {len(res.records)} episodes (split {split}), reference {c.reference}\n{res.table}",
          flush=True)
    write_results(out, c.reference, res, meta={**work.meta(), "split": split, "reference": c.reference,
                                               "env": OmegaConf.to_container(cfg.env), "seed": c.seed,
                                               "identity": identity})
    print(f"wrote {out / f'eval_{c.reference}.csv'} and .json")
    return res


main = entry_point("evaluate", run)


if __name__ == "__main__":
    main()
