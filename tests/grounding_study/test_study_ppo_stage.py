"""`study.ppo_stage`: the study's PPO again, with another budget, from each train cell's own BC (fast).

What matters: the BC cells and their evaluations keep their hashes (reused), every BC+RL evaluation gets a
new one (an old-budget policy is never reused for the new budget), the ppo cell runs exactly `train` with the
stage's overrides from the train cell's bc.pt, and the learning recipe's budget reaches it.
"""

from __future__ import annotations

import dataclasses

import pytest
import yaml
from omegaconf import OmegaConf

from wanderland_nav.compose.schema import study_config
from wanderland_nav.compose.study_config import StudyConfig, StudyGroup
from wanderland_nav.degrade.crosseval import table3
from wanderland_nav.grounding_study.cells import StudyCells
from wanderland_nav.cache import Ledger
from wanderland_nav.grounding_study.plan import GROUNDED, cell_digests, plan_cells
from wanderland_nav.grounding_study.report import cell_status_lines

STAGE = ["algo.ppo.total_frames=1600", "algo.ppo.frames_per_batch=400", "algo.ppo.critic_warmup_iters=1"]


def _config(tmp_path, **study) -> StudyConfig:
    group = {"presets": ["scale_1.2"], "seeds": [0, 1], "train": ["+exp=citywalker_rl", "debug=smoke"], **study}
    return StudyConfig(study=StudyGroup(**group), out=str(tmp_path))


def test_ppo_cells_produce_bc_rl_and_only_bc_rl_evaluations_change_hash(tmp_path):
    old = _config(tmp_path)
    new = dataclasses.replace(old, study=dataclasses.replace(old.study, ppo_stage=STAGE))
    cells = plan_cells(new.study)
    keys = [c.key for c in cells]
    assert keys.index("ppo/scale_1.2/seed1") == keys.index("train/scale_1.2/seed1") + 1
    by_key = {c.key: c for c in cells}
    assert by_key["ppo/grounded/seed0"].needs == ("train/grounded/seed0",)
    evals = [c for c in cells if c.kind == "eval"]
    assert {c.needs[0].split("/")[0] for c in evals if c.policy[1] == "BC+RL"} == {"ppo"}
    assert {c.needs[0].split("/")[0] for c in evals if c.policy[1] == "BC"} == {"train"}
    before, after = cell_digests(old, plan_cells(old.study)), cell_digests(new, cells)
    common = set(before) & set(after)
    changed = {k for k in common if before[k] != after[k]}
    assert changed == {c.key for c in evals if c.policy[1] == "BC+RL"} and len(changed) == 2 * 5
    # per seed: grounded's and scale_1.2's BC+RL in grounded, grounded's in scale_1.2 (own episodes and routes),
    # scale_1.2's on the routes in scale_1.2
    assert set(after) - set(before) == {f"ppo/{e}/seed{s}" for e in (GROUNDED, "scale_1.2") for s in (0, 1)}
    longer = dataclasses.replace(new, study=dataclasses.replace(new.study, ppo_stage=STAGE + ["algo.ppo.epochs=4"]))
    moved = cell_digests(longer, plan_cells(longer.study))
    assert {k for k in after if moved[k] != after[k]} == {"ppo/grounded/seed0", "ppo/grounded/seed1",
                                                         "ppo/scale_1.2/seed0", "ppo/scale_1.2/seed1"} | changed


def test_grounding_recipe_pins_the_learning_ppo_on_the_grounding_bc():
    from wanderland_nav.compose.cli import compose_config
    from wanderland_nav.compose.schema import TrainConfig, typed_config

    recipe = study_config(compose_config("study", ["+study=grounding_recipe"]))
    grounding = study_config(compose_config("study", ["+study=grounding"]))
    assert recipe.study.train == grounding.study.train and grounding.study.ppo_stage == []
    assert recipe.study.presets == ["video3dgs", "scale_0.8", "drift"] and recipe.study.seeds == [0, 1, 2, 3, 4]
    assert recipe.study.protocols == ["grounded_routes"]
    cells = plan_cells(recipe.study)
    ex = StudyCells(recipe, recipe.out, None, cells)
    ppo = ex.cells["ppo/video3dgs/seed1"]
    cfg = OmegaConf.to_container(ex.cell_train_config(ppo, ex.cell_dir(ppo.key)), resolve=True)
    assert cfg["init_checkpoint"] == str(ex.cell_dir("train/video3dgs/seed1") / "checkpoints" / "bc.pt")
    p = typed_config(cfg, TrainConfig).algo.ppo
    assert (p.total_frames, p.frames_per_batch, p.num_iterations - p.critic_warmup_iters) == (44800, 800, 54)
    assert (p.epochs, p.minibatch_size, p.lr, p.action_dist) == (4, 200, 5e-5, "tracked")
    train = OmegaConf.to_container(ex.cell_train_config(ex.cells["train/video3dgs/seed1"], ex.cell_dir(ppo.key)),
                                   resolve=True)
    assert train["algo"]["bc"] == cfg["algo"]["bc"] and train["algo"]["ppo"]["total_frames"] == 4800
    assert train["init_checkpoint"] is None and train["episodes"] == cfg["episodes"]


def test_ppo_cell_runs_train_from_the_bc_checkpoint_and_its_recipe_is_checked(tmp_path, monkeypatch):
    c = _config(tmp_path, seeds=[0], ppo_stage=STAGE)
    cells = plan_cells(c.study)
    ex = StudyCells(c, tmp_path, lambda cfg: ran.append(cfg) or {"BC+RL": {"SR": 0.5, "IR": 0.1}}, cells)
    ran = []
    episodes = tmp_path / "episodes.json"
    monkeypatch.setattr(ex, "env_episodes", lambda env, seed: (None, episodes, ex_typed(env, seed)))
    monkeypatch.setattr("wanderland_nav.grounding_study.cells.split_counts",
                        lambda path: {"train": 9, "val": 2, "test": 5})

    def ex_typed(env, seed):
        from wanderland_nav.compose.schema import TrainConfig, typed_config
        return typed_config(ex.train_config(env, seed), TrainConfig)

    key = "ppo/grounded/seed0"
    folder = ex.cell_dir(key)
    info = ex(ex.cells[key], folder)
    assert ran[0].init_checkpoint == str(ex.cell_dir("train/grounded/seed0") / "checkpoints" / "bc.pt")
    assert ran[0].run_dir == str(folder)
    assert (info["ppo_frames"], info["ppo_policy_updates"], info["rows"]) == (1600, 3, {"BC+RL": {"SR": 0.5, "IR": 0.1}})
    m = Ledger(tmp_path / "done.json")
    m.record(key, {"hash": ex.digests[key], "status": "done", "dir": str(folder), "seconds": 12.0, "info": info})
    line = cell_status_lines(m, cells, ex.digests)[-1]
    assert line.startswith("  PPO stage from the train cell's BC in grounded (seed 0)") and "1600 PPO frames, 3 PPO" in line
    recorded = OmegaConf.to_container(ran[0], resolve=True)
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(yaml.safe_dump(recorded))
    ex.check_trained_recipes(m)
    recorded["algo"]["ppo"]["total_frames"] = 800  # e.g. a cell made before the stage's budget was raised
    (folder / "config.yaml").write_text(yaml.safe_dump(recorded))
    with pytest.raises(RuntimeError, match=r"ppo/grounded/seed0 was trained with another recipe[\s\S]*"
                                           r"algo.ppo.total_frames: 800 -> 1600"):
        ex.check_trained_recipes(m)


def test_training_line_says_the_sampler_file_instead_of_none_asked(tmp_path):
    c = _config(tmp_path, seeds=[0])
    cells = plan_cells(c.study)
    digests = cell_digests(c, cells)
    m = Ledger(tmp_path / "done.json")
    key = "train/scale_1.2/seed0"
    info = {"episodes": {"train": 96, "val": 24, "test": 40}, "asked": None, "ppo_policy_updates": 2}
    m.record(key, {"hash": digests[key], "status": "done", "dir": "x", "seconds": 60.0, "info": info})
    line = [ln for ln in cell_status_lines(m, cells, digests) if "scale_1.2" in ln][0]
    assert "None" not in line and "'test': 40} (study.episode_sampler's file), cell 60s" in line


def _recs(successes: list[int]) -> list[dict]:
    return [{"episode_id": f"ep{i}", "navigation_error": 1.0 - s, "distance_to_goal": 1.0 - s, "success": float(s),
             "spl": 0.8 * s, "intervention": 0.0} for i, s in enumerate(successes)]


def test_table3_keeps_whole_seeds_and_pairs_each_worlds_rl_gain():
    envs = [GROUNDED, "drift"]
    rec = {}
    for seed in (0, 1, 2):
        rec[(GROUNDED, seed, GROUNDED, "untrained")] = _recs([0] * 8 + [1] * 2)
        for env in envs:
            rec[(GROUNDED, seed, env, "BC")] = _recs([0] * 4 + [1] * 6)
            rec[(GROUNDED, seed, env, "BC+RL")] = _recs([0] * 2 + [1] * 8)
    del rec[(GROUNDED, 2, "drift", "BC+RL")]  # seed 2's drift PPO not finished
    text = table3(rec, envs, [0, 1, 2])
    assert "seeds [0, 1] (every row done; seeds [2] are not)" in text
    assert "x 2 seeds" in text and "x 3 seeds" not in text
    gain = [ln for ln in text.splitlines() if ln.startswith("drift BC+RL - drift BC")]
    assert len(gain) == 1 and "+0.200" in gain[0]  # 8/10 - 6/10 on the same episodes
    crossed = {k: v for k, v in rec.items() if k[1] == 2 and k[2:] != (GROUNDED, "BC")}
    crossed[(GROUNDED, 1, GROUNDED, "BC")] = rec[(GROUNDED, 1, GROUNDED, "BC")]  # each seed lacks a row the other has
    assert "no seed of [1, 2] has every row" in table3(crossed, envs, [1, 2])
    assert "are not" not in table3(rec, envs, [0, 1])  # every seed whole: none named


def test_a_copied_study_compares_its_own_paths_by_what_they_name():
    """A study copied to another out= moves its sampler episodes files and the ppo cells' bc.pt: still the same
    recipe. Another episodes file name (other generator settings) is not."""
    from wanderland_nav.grounding_study.cells import _portable

    def cfg(out: str, name: str = "episodes_study_c7d8bd09.json") -> dict:
        return {"scene": {"path": f"{out}/scenes/drift_s0"}, "seed": 1, "init_checkpoint": f"{out}/cells/bc.pt",
                "episodes": {"path": f"{out}/scenes/drift_s0/{name}", "num": None}, "algo": {"ppo": {"lr": 5e-5}}}

    assert _portable(cfg("/tmp/a")) == _portable(cfg("/tmp/b/out"))
    assert _portable(cfg("/tmp/a")) != _portable(cfg("/tmp/a", "episodes_study_00000000.json"))
    assert _portable({**cfg("/tmp/a"), "episodes": {"path": None, "num": 400}})["episodes"]["path"] is None


def test_smoke_runs_a_staged_study_at_the_smoke_train_sizes():
    """`+study=grounding_recipe debug=smoke` must stay minutes: the stage's pinned 44,800 frames are dropped, its
    lr kept, and the ppo cells still exist; a user's own stage under smoke is left alone."""
    from wanderland_nav.compose.cli import compose_config
    from wanderland_nav.compose.schema import TrainConfig, typed_config

    smoke = study_config(compose_config("study", ["+study=grounding_recipe", "debug=smoke"]))
    assert smoke.study.ppo_stage == ["algo.ppo.lr=5.0e-5"] and smoke.study.presets == ["scale_1.2", "holes"]
    cells = plan_cells(smoke.study)
    ex = StudyCells(smoke, smoke.out, None, cells)
    ppo = ex.cells["ppo/holes/seed0"]
    p = typed_config(OmegaConf.to_container(ex.cell_train_config(ppo, ex.cell_dir(ppo.key)), resolve=True),
                     TrainConfig).algo.ppo
    assert (p.total_frames, p.frames_per_batch, p.lr) == (16, 8, 5e-5)
    only_sizes = study_config(compose_config("study", ["+study=grounding", "debug=smoke",
                                                       "study.ppo_stage=['algo.ppo.total_frames=800']"]))
    assert only_sizes.study.ppo_stage == ["algo.ppo.enabled=true"]  # still staged: its cells are exercised
    own = study_config(compose_config("study", ["+study=grounding", "debug=smoke", "study.ppo_stage=['algo.ppo.lr=1e-4']"]))
    assert own.study.ppo_stage == ["algo.ppo.lr=1e-4"]
