"""NavEnv's TorchRL contract and rules on the fake room (tests/envs/env_fakes.py), fast and exact."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from env_fakes import FakeNavMesh, FakeRenderer, FakeScene, make_env, make_episode, make_episodes
from PIL import Image
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from wanderland_nav import keys
from wanderland_nav.envs import ExpertPolicy, NavEnv, NavEnvConfig, RandomPolicy
from wanderland_nav.evaluation.metrics import aggregate_metrics
from wanderland_nav.envs.camera import group_size
from wanderland_nav.evaluation.loop import run_evaluation


def small_config(**kin):
    c = NavEnvConfig()
    c.camera.width = c.camera.height = 16
    c.camera.history = 3
    c.instruction_length = 32
    for k, v in kin.items():
        setattr(c.kinematics, k, v)
    return c


@pytest.mark.parametrize("mode", ["waypoints", "velocity"])
def test_check_env_specs(mode):
    c = small_config(action_mode=mode)
    c.camera.depth = True
    env = make_env(B=3, config=c)
    check_env_specs(env)
    td = env.reset()
    assert td[keys.RGB].shape == (3, 3, 16, 16, 3) and td[keys.RGB].dtype == torch.uint8
    assert td[keys.DEPTH].shape == (3, 3, 16, 16, 1)
    assert env.action_spec.shape == ((3, 5, 2) if mode == "waypoints" else (3, 2))


def test_reset_observations_are_in_the_body_frame():
    env = make_env(B=4, config=small_config(), episodes=make_episodes())
    env.config.episode_order = "iterate"
    env.set_seed(0)
    td = env.reset()
    assert td[keys.EPISODE_INDEX].flatten().tolist() == [0, 1, 2, 3]
    # episode 0: start (1, 1) facing +x, goal (4, 1) -> 3 m straight ahead (ramp adds nothing in 2D)
    assert torch.allclose(td[keys.GOAL_VECTOR][0], torch.tensor([3.0, 0.0]), atol=1e-5)
    # episode 2: start (8, 3) facing +x, goal (6, 3) -> 2 m behind
    assert torch.allclose(td[keys.GOAL_VECTOR][2], torch.tensor([-2.0, 0.0]), atol=1e-5)
    # episode 1: yaw 0.5, goal at (2, 3) relative -> rotate by -0.5
    c, s = math.cos(0.5), math.sin(0.5)
    assert torch.allclose(td[keys.GOAL_VECTOR][1], torch.tensor([c * 2 + s * 3, -s * 2 + c * 3]), atol=1e-5)
    assert torch.allclose(td[keys.AGENT_POSITION][0], torch.tensor([1.0, 1.0, 0.05]), atol=1e-5)  # on the ramp
    assert torch.allclose(td[keys.DISTANCE_TO_GOAL].flatten()[0], torch.tensor(math.sqrt(9 + 0.15**2)), atol=1e-4)
    assert torch.all(td[keys.PAST_POSITIONS] == 0)  # history filled with the start pose
    assert torch.equal(td[keys.RGB][:, 0], td[keys.RGB][:, -1])
    toks = td[keys.INSTRUCTION_TOKENS][2]
    assert bytes((toks[toks > 0] - 1).tolist()).decode() == "turn around"
    # goal pose: heading of the path's last segment relative to the agent (episode 2 walks -x while facing +x)
    assert torch.allclose(td[keys.GOAL_POSE][2, 2:], torch.tensor([-1.0, 0.0]), atol=1e-5)
    assert keys.HAS_GOAL_IMAGE not in td.keys() and keys.GOAL_IMAGE not in td.keys()  # no episode has a goal view


def test_step_moves_on_the_surface_and_updates_history():
    env = make_env(B=1, config=small_config(), episodes=[make_episode(0, (1, 1), (9, 1))])
    td = env.reset()
    td[keys.ACTION] = torch.tensor([[[1.0, 0.0]] * 5])
    out = env.step(td)["next"]
    assert torch.allclose(out[keys.AGENT_POSITION][0], torch.tensor([1.5, 1.0, 0.075]), atol=1e-5)
    assert torch.allclose(out[keys.PAST_POSITIONS][0], torch.tensor([[-0.5, 0.0], [-0.5, 0.0], [0.0, 0.0]]), atol=1e-5)
    assert not torch.equal(out[keys.RGB][0, -1], out[keys.RGB][0, 0])  # a new frame was pushed
    assert torch.equal(out[keys.RGB][0, 0], td[keys.RGB][0, 0])
    d0, d1 = float(td[keys.DISTANCE_TO_GOAL]), float(out[keys.DISTANCE_TO_GOAL])
    assert float(out[keys.REWARD]) == pytest.approx(-0.01 + (d0 - d1), abs=1e-5)
    assert out[keys.STEP_COUNT].item() == 1 and not out[keys.COLLISION].any()


def test_walls_block_and_stuck_agents_are_intervened():
    c = small_config()
    c.termination.stuck_steps = 3
    env = make_env(B=1, config=c, episodes=[make_episode(0, (9.8, 1), (1, 1))])  # facing the +x wall
    td = env.reset()
    rewards, flags = [], []
    for _ in range(4):
        td[keys.ACTION] = torch.tensor([[[1.0, 0.0]] * 5])
        td = env.step(td)
        nxt = td["next"]
        rewards.append(float(nxt[keys.REWARD]))
        flags.append((bool(nxt[keys.COLLISION]), bool(nxt[keys.INTERVENTION]), bool(nxt[keys.DONE])))
        if flags[-1][2]:
            break
        td = td["next"].clone()
    assert nxt[keys.AGENT_POSITION][0, 0] == pytest.approx(10.0)  # slid up to the wall, not through
    assert flags[-1] == (True, True, True) and len(flags) == 4  # first step moves 0.2 m, then 3 stuck steps
    assert rewards[-1] == -c.reward.failure_penalty and bool(nxt[keys.TERMINATED]) and not bool(nxt[keys.TRUNCATED])
    (m,) = env.pop_finished_metrics()
    # path length is horizontal (the ramp climb of 0.01 m is not counted), like the geodesic it is compared with
    assert m.intervention and not m.success and m.collisions == 4 and m.path_length == pytest.approx(0.2, abs=1e-5)
    assert m.intervention_cause == "stuck"


def test_timeout_is_truncation_not_intervention():
    c = small_config(action_mode="velocity")
    c.termination.max_steps = 5
    env = make_env(B=2, config=c)
    td = env.reset()
    td[keys.ACTION] = torch.tensor([[0.0, 1.0], [0.0, -1.0]])  # spin on the spot
    for _ in range(5):
        td = env.step(td)
        nxt = td["next"]
        td = nxt.clone().set(keys.ACTION, td[keys.ACTION])
    assert nxt[keys.TRUNCATED].all() and not nxt[keys.TERMINATED].any() and not nxt[keys.INTERVENTION].any()
    ms = env.pop_finished_metrics()
    assert len(ms) == 2 and all(m.timeout and not m.intervention and m.steps == 5 and m.spl == 0 for m in ms)
    assert [m.intervention_cause for m in ms] == ["", ""]  # a timeout has no intervention cause


def test_partial_reset_only_touches_masked_agents():
    env = make_env(B=3, config=small_config())
    td = env.reset()
    td[keys.ACTION] = torch.tensor([[[1.0, 0.0]] * 5]).expand(3, 5, 2).clone()
    td = env.step(td)["next"].clone()
    before = td.clone()
    td[keys.RESET] = torch.tensor([[False], [True], [False]])
    out = env.reset(td)
    assert torch.equal(out[keys.AGENT_POSITION][[0, 2]], before[keys.AGENT_POSITION][[0, 2]])
    assert torch.equal(out[keys.RGB][[0, 2]], before[keys.RGB][[0, 2]])
    assert out[keys.STEP_COUNT].flatten().tolist() == [1, 0, 1]
    ep1 = int(out[keys.EPISODE_INDEX][1])
    assert torch.allclose(out[keys.AGENT_POSITION][1], env.table.start_position[ep1])
    # the state behind agents 0 and 2 is untouched: the next step continues from there
    out[keys.ACTION] = torch.zeros(3, 5, 2)
    nxt = env.step(out)["next"]
    assert nxt[keys.STEP_COUNT].flatten().tolist() == [2, 1, 2]


def test_seeded_rollouts_are_reproducible_and_seeds_differ():
    def roll(seed):
        env = make_env(B=2, config=small_config(), seed=seed)
        env.set_seed(seed)
        pol = RandomPolicy(env.action_spec, seed=seed)
        r = env.rollout(30, pol, break_when_any_done=False)
        return r

    a, b, c = roll(3), roll(3), roll(4)
    assert torch.equal(a["next", keys.AGENT_POSITION], b["next", keys.AGENT_POSITION])
    assert torch.equal(a["next", keys.RGB], b["next", keys.RGB])
    assert torch.equal(a[keys.EPISODE_INDEX], b[keys.EPISODE_INDEX])
    assert not torch.equal(a["next", keys.AGENT_POSITION], c["next", keys.AGENT_POSITION])


def test_step_path_is_batched():
    """One navmesh motion call and ceil(B / render_chunk) render calls per step, whatever B is (the
    calls run on concurrent threads, so their order is not fixed); at least two groups when B >= 2."""
    c = small_config()
    c.camera.render_chunk = 4
    env = make_env(B=10, config=c)
    td = env.reset()
    env.navmesh.move_calls = 0
    env.camera.renderer.calls.clear()
    td[keys.ACTION] = torch.zeros(10, 5, 2)
    env.step(td)
    assert env.navmesh.move_calls == 1 and sorted(env.camera.renderer.calls) == [2, 4, 4]
    assert [group_size(B, 16) for B in (1, 2, 3, 8, 25, 64)] == [1, 1, 2, 4, 13, 16]


@pytest.mark.parametrize("mode", ["waypoints", "velocity"])
def test_expert_succeeds_and_random_does_not(mode):
    c = small_config(action_mode=mode)
    c.termination.max_steps = 60
    c.episode_order = "iterate"
    env = make_env(B=3, config=c, episodes=make_episodes(2))
    res = run_evaluation(env, ExpertPolicy(env), num_episodes=8)
    o = res.summary["overall"]
    assert o["episodes"] == 8 and o["SR"] == 1.0 and o["SPL"] >= 0.95 and o["IR"] == 0.0
    assert {"indoor", "outdoor"} <= set(res.summary)
    assert sorted(r["serial"] for r in res.records) == list(range(8))
    rnd = run_evaluation(env, RandomPolicy(env.action_spec, seed=0), num_episodes=8).summary["overall"]
    assert rnd["SR"] < 0.5 and rnd["SPL"] < o["SPL"]


def test_evaluation_does_not_depend_on_batch_size():
    c = small_config()
    c.episode_order = "iterate"
    recs, rendered = [], []
    for B in (1, 4):
        env = make_env(B=B, config=c, episodes=make_episodes(2))
        res = run_evaluation(env, ExpertPolicy(env), num_episodes=5)
        recs.append(sorted((r["serial"], r["steps"], round(r["path_length"], 4)) for r in res.records))
        rendered.append(sum(env.camera.renderer.calls))
        assert env.count_serials is None                      # restored after the evaluation
    assert recs[0] == recs[1]
    # B = 4 starts episodes past the fifth while the last ones finish; their agents are not rendered
    assert rendered[1] == rendered[0]


def test_goal_images_from_files_and_rendered(tmp_path):
    img = np.zeros((8, 12, 3), np.uint8)
    img[..., 0] = 200
    (tmp_path / "goal_images").mkdir()
    Image.fromarray(img).save(tmp_path / "goal_images" / "g0.png")
    from wanderland_nav.envs.episode_table import load_goal_images

    eps = make_episodes()
    eps[1].extras["goal_image"] = "goal_images/g0.png"
    with pytest.raises(ValueError, match="episodes name goal_image files; load them"):
        make_env(B=4, config=small_config(), episodes=eps)  # NavEnv itself reads no files
    env = make_env(B=4, config=small_config(), episodes=eps,
                   goal_images=load_goal_images(eps, [tmp_path], 16, 16, where="test"))
    env.config.episode_order = "iterate"
    env.set_seed(0)
    td = env.reset()
    assert td[keys.HAS_GOAL_IMAGE].flatten().tolist() == [False, True, False, False]
    assert td[keys.GOAL_IMAGE].shape == (4, 16, 16, 3) and td[keys.GOAL_IMAGE][1, ..., 0].float().mean() == 200
    eps[2].extras["goal_image"] = "goal_images/missing.png"
    with pytest.raises(FileNotFoundError, match=r"episodes\[2\].goal_image"):
        load_goal_images(eps, [tmp_path], 16, 16, where="test")
    c = small_config()
    c.goal_image = "render"
    env = make_env(B=2, config=c)
    assert env._has_goal_image.all() and env._goal_images.float().mean() > 0


def test_bad_inputs_are_named():
    far = make_episode(7, (1, 1), (4, 1))
    far.start_position = far.start_position + np.array([0.0, 5.0, 0.0])  # scene +y is down: 5 m below the floor
    with pytest.raises(ValueError, match=r"episodes\[0\] \(id 7\).start_position lies 5.00 m from the navmesh"):
        make_env(B=1, episodes=[far])
    with pytest.raises(ValueError, match="no episodes"):
        make_env(B=1, episodes=[])
    with pytest.raises(ValueError, match=r"batch_size must be \[B\]"):
        NavEnv(FakeScene(), make_episodes(), batch_size=[2, 2], navmesh=FakeNavMesh(), gaussians=object(),
               renderer=FakeRenderer())
    env = make_env(B=1)
    td = env.reset()
    td[keys.ACTION] = torch.zeros(1, 2)  # a velocity command sent to a waypoint env
    with pytest.raises(ValueError, match=r"waypoint action must be \[B, K, 2\]"):
        env.step(td)


def test_disabled_camera_never_renders_and_carries_no_images():
    """Camera off: no renderer call and no image keys in the spec or the tensordicts (blank frames were
    most of a blind B=256 step); goal views stay when episodes have real ones (loaded files)."""
    c = small_config()
    c.camera.enabled = False
    c.camera.depth = True
    renderer = FakeRenderer()
    env = NavEnv(FakeScene(), make_episodes(), batch_size=[2], config=c, navmesh=FakeNavMesh(), renderer=renderer)
    check_env_specs(env)
    td = env.rollout(5, ExpertPolicy(env), break_when_any_done=False)
    images = {keys.RGB, keys.DEPTH, keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE}
    assert renderer.calls == []
    assert not images & set(env.observation_spec.keys()) and not images & set(td["next"].keys())
    E = len(env.table)
    views = (torch.full((E, c.camera.height, c.camera.width, 3), 7, dtype=torch.uint8), torch.ones(E, dtype=torch.bool))
    env = NavEnv(FakeScene(), make_episodes(), batch_size=[2], config=c, navmesh=FakeNavMesh(), renderer=renderer,
                 goal_images=views)
    check_env_specs(env)
    td = env.reset()
    assert (td[keys.GOAL_IMAGE] == 7).all() and td[keys.HAS_GOAL_IMAGE].all() and keys.RGB not in td.keys()


def test_camera_without_gaussians_is_refused_by_name():
    """NavEnv reads no files: a camera needs its Gaussians handed in."""
    with pytest.raises(ValueError, match=r"NavEnv\(.*\): camera.enabled needs `gaussians`"):
        NavEnv(FakeScene(), make_episodes(), batch_size=[1], config=small_config(), navmesh=FakeNavMesh())


def test_env_ops_run_on_one_intra_op_thread_and_render_groups_on_the_cores(monkeypatch):
    """A camera-on step runs its own small ops on ONE intra-op thread (a pool only adds fork/join waits,
    milliseconds per op on a loaded machine) while the render groups use the CPU cores, whatever the
    caller's intra-op count (threads=1 keeps them); the caller's setting is restored afterwards, also
    when step_and_maybe_reset nests step and reset."""
    import wanderland_nav.envs.camera as camera_module

    seen = {"workers": [], "env_threads": []}
    real_map = camera_module.map_single_threaded

    def recording_map(fn, items, workers):
        seen["workers"].append(workers)
        return real_map(fn, items, workers)

    monkeypatch.setattr(camera_module, "map_single_threaded", recording_map)
    monkeypatch.setattr(camera_module, "available_cores", lambda: 3)
    env = make_env(B=4, config=small_config())
    real_observation = env._observation
    env._observation = lambda: (seen["env_threads"].append(torch.get_num_threads()), real_observation())[1]
    before = torch.get_num_threads()
    after = []
    try:
        for threads in (2, 1):
            torch.set_num_threads(threads)
            td = ExpertPolicy(env)(env.reset())
            env.step_and_maybe_reset(td)
            after.append(torch.get_num_threads())
    finally:
        torch.set_num_threads(before)
    assert after == [2, 1]
    assert seen["workers"] and set(seen["workers"]) == {3}  # render groups: the cores
    assert seen["env_threads"] and set(seen["env_threads"]) == {1}  # the env's own ops: one


def test_sampled_evaluation_actor_is_seeded_and_restarts_its_noise_at_reset():
    """eval.deterministic=false: the same evaluation twice gives the same samples (own generator, re-seeded)."""
    from tensordict import TensorDict

    from wanderland_nav.evaluation.loop import PolicyActor

    class Mean(torch.nn.Module):  # select_action as NavPolicy's: loc, or loc + scale * randn(generator)
        def __init__(self):
            super().__init__()
            self.loc = torch.nn.Parameter(torch.zeros(3, 5, 2))

        def select_action(self, td, deterministic=True, generator=None):
            noise = torch.randn(self.loc.shape, generator=generator)
            return td.set(keys.ACTION, self.loc.detach() + (0 if deterministic else 0.3 * noise))

        def reset(self):
            pass

    def draws(actor, n=3):
        actor.reset()
        return torch.stack([actor(TensorDict({}, [3]))[keys.ACTION] for _ in range(n)])

    a = PolicyActor(Mean(), deterministic=False, seed=4)
    first = draws(a)
    torch.manual_seed(123)  # the global stream does not matter
    assert torch.equal(draws(a), first) and first[0].abs().sum() > 0 and not torch.equal(first[0], first[1])
    assert not torch.equal(draws(PolicyActor(Mean(), deterministic=False, seed=5)), first)
    assert draws(PolicyActor(Mean(), deterministic=True)).abs().sum() == 0


def test_blank_camera_evaluation_skips_rendering_and_keeps_every_record():
    from policies import make_policy
    from wanderland_nav.evaluation.loop import PolicyActor
    from wanderland_nav.rl.blank_camera import BlankCamera, camera_paused

    torch.manual_seed(0)
    policy = make_policy("cnn", image_size=(16, 16), context=3, feature_dim=32)
    blind = PolicyActor(BlankCamera(policy))
    env = make_env(B=3, config=small_config(), episodes=make_episodes(2))
    rendered = run_evaluation(env, blind, num_episodes=6).records
    calls = len(env.camera.renderer.calls)
    assert calls > 0
    with camera_paused(env, blind.policy):
        assert not env.config.camera.enabled
        paused = run_evaluation(env, blind, num_episodes=6).records
    assert len(env.camera.renderer.calls) == calls   # nothing rendered while paused
    assert env.config.camera.enabled                 # and the camera is back
    assert paused == rendered
    with camera_paused(env, policy):                 # a seeing policy is never paused
        assert env.config.camera.enabled
