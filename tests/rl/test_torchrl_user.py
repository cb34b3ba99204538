"""What a TorchRL user does with the env, written as they would write it, on the tiny demo with the camera on.

`make_env` + TorchRL transforms + `check_env_specs`; `to(device)`; the policy-facing key layout; episode
metrics at done; `pixels` into `VideoRecorder`; `Collector` into a `ReplayBuffer`; the tutorial PPO
(`GAE(value_network=...)` + `ClipPPOLoss`) on the library's CityWalker-style policy; `ParallelEnv` and
`MultiSyncCollector` (slow: each worker re-imports and reloads the scene). The README's quick start and
PPO snippet are the strings below, executed.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import Compose, InitTracker, RewardSum, StepCounter, ToTensorImage, TransformedEnv
from torchrl.envs.utils import check_env_specs

import wanderland_nav
from wanderland_nav import keys as K

pytestmark = pytest.mark.usefixtures("one_thread")

TINY_POLICY = dict(encoder="cnn", image_size=(32, 32), dim=16, depth=1, heads=2)

QUICK_START = '''
import wanderland_nav
env = wanderland_nav.make_env("demo", batch_size=4)  # the tiny demo: built, prepared, episodes made on first use
td = env.rollout(200, break_when_any_done=False)      # random waypoints, [4, 200]; a done agent starts its next episode
print(td["next", "reward"].shape, td["next", "episode", "spl"][td["next", "done"]])  # SPL of finished episodes
'''

PPO_SNIPPET = '''
import torch, wanderland_nav
from policies import make_policy
from torchrl.collectors import Collector
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE
from wanderland_nav.rl.torchrl_modules import policy_modules

policy = make_policy("citywalker", encoder="cnn", image_size=(32, 32), dim=16, depth=1, heads=2)
env = wanderland_nav.make_env("demo", batch_size=4, policy=policy)  # camera shaped to the policy
actor, value = policy_modules(policy, env)          # ProbabilisticActor + value operator, shared weights
collector = Collector(env, actor, frames_per_batch=32, total_frames=64)
advantage = GAE(gamma=0.99, lmbda=0.95, value_network=value)
loss = ClipPPOLoss(actor, value)
optim = torch.optim.Adam(loss.parameters(), lr=3e-4)
for batch in collector:                             # 2 iterations
    advantage(batch)
    for mb in batch.reshape(-1).split(16):
        out = loss(mb)
        (out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]).backward()
        optim.step(), optim.zero_grad()
'''


@pytest.fixture(scope="module")
def demo(demo_episodes):
    """make_env's keywords for the prepared tiny demo fixture (8 episodes, no goal views), at smoke sizes."""
    return dict(scene=str(demo_episodes.parent), debug="smoke", navigation={"prepare": False})


def _snippet(code: str, demo: dict):
    """`code` as the README has it, with make_env pointed at the test's tiny demo (same call otherwise)."""
    real = wanderland_nav.make_env
    scope = {}

    def make_env(scene, **kw):
        assert scene == "demo"
        return real(**{**demo, **kw})

    wanderland_nav.__dict__["make_env"] = make_env
    try:
        exec(textwrap.dedent(code), scope)
    finally:
        del wanderland_nav.__dict__["make_env"]
    assert wanderland_nav.make_env is real
    return scope


def test_readme_shows_these_snippets():
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert QUICK_START.lstrip("\n") in readme and PPO_SNIPPET.lstrip("\n") in readme


def test_readme_quick_start_runs(demo, capsys):
    scope = _snippet(QUICK_START, demo)
    td = scope["td"]
    out = capsys.readouterr().out
    assert td.batch_size == (4, 200) and "torch.Size([4, 200, 1])" in out
    assert K.PRIVILEGED not in td.keys() and K.PIXELS in td.keys()
    done = td["next", "done"].squeeze(-1)
    assert (done.sum(1) >= 2).all()  # every agent finished episodes and went on: auto-resets at done
    restarted = td["next", K.EPISODE, "steps"][:, 1:][done[:, :-1]]  # the step after a done: a fresh episode's first
    assert (restarted == 1).all()
    assert "tensor([])" not in out and td["next", K.EPISODE, "spl"][td["next", "done"]].numel() == int(done.sum())


def test_readme_python_section_is_these_snippets_and_true():
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("## Python", 1)[1].split("\n## ", 1)[0]
    assert section.count("```python") == 2
    assert "episode metrics sit in `(\"next\", \"episode\")`" in section  # the reward spec's step outputs
    assert "Observations hold the policy inputs" in section and "each worker process draws its own episodes" in section


def test_readme_ppo_snippet_trains_two_iterations(demo):
    torch.manual_seed(0)
    scope = _snippet(PPO_SNIPPET, demo)
    policy, batch = scope["policy"], scope["batch"]
    assert batch.numel() == 32 and batch[K.ACTION_LOG_PROB].shape == batch.shape  # one log-prob per sample
    assert torch.isfinite(batch["advantage"]).all() and not batch[K.ACTION_LOG_PROB].requires_grad
    fresh = make_policy_like(policy)
    moved = [not torch.equal(a, b) for a, b in zip(policy.parameters(), fresh.parameters())]
    assert any(moved)  # the optimiser changed the policy's own weights


def make_policy_like(policy):
    from policies import make_policy

    torch.manual_seed(0)
    return make_policy("citywalker", **TINY_POLICY)


def test_transforms_stack_passes_check_env_specs_with_the_camera_on(demo):
    env = TransformedEnv(wanderland_nav.make_env(batch_size=2, **demo),
                         Compose(StepCounter(), RewardSum(), InitTracker(),
                                 ToTensorImage(in_keys=[K.PIXELS], out_keys=["pixels_float"])))
    check_env_specs(env)
    td = env.rollout(3)
    assert td["next", "pixels_float"].shape == (2, 3, 3, 32, 32) and td["next", "pixels_float"].max() <= 1
    assert td["next", "step_count"][:, -1].flatten().tolist() == [3, 3]
    base = env.base_env
    assert set(base.observation_spec.keys()) == {K.PAST_POSITIONS, K.GOAL_VECTOR, K.GOAL_POSE, K.RGB, K.PIXELS,
                                                 K.INSTRUCTION_TOKENS}  # no metrics: they are reward-spec outputs
    assert set(base.full_reward_spec[K.EPISODE].keys()) == {k[-1] for k in K.EPISODE_KEYS}
    assert K.GOAL_IMAGE not in td.keys() and K.PRIVILEGED not in td["next"].keys()  # point-goal: no goal views


def test_episode_metrics_at_done_match_the_evaluators_records(demo):
    """The same episodes twice: metrics read at ("next", "done") == the env's own finished records."""
    kw = dict(batch_size=3, env={"expert_action": True, "termination": {"max_steps": 60}}, **demo)
    a = wanderland_nav.make_env(**kw)
    b = wanderland_nav.make_env(**{**kw, "env": {**kw["env"], "finished_records": True}})
    with pytest.raises(RuntimeError, match="finished_records=false"):
        a.pop_finished_metrics()
    follow = lambda td: td.set(K.ACTION, td[K.EXPERT_ACTION])  # noqa: E731
    ra, rb = a.rollout(50, follow, break_when_any_done=False), b.rollout(50, follow, break_when_any_done=False)
    done = ra["next", "done"].squeeze(-1)  # [B, T]
    got = ra["next", K.EPISODE][done]  # [n] finished episodes
    recs = b.pop_finished_metrics()
    assert len(recs) == int(done.sum()) >= 3
    for key, attr, tol in (("spl", "spl", 1e-5), ("navigation_error", "navigation_error", 1e-4),
                           ("path_length", "path_length", 1e-4), ("shortest_length", "shortest_length", 1e-5)):
        assert sorted(got[key].flatten().tolist()) == pytest.approx(sorted(getattr(m, attr) for m in recs), abs=tol)
    assert sorted(got["steps"].flatten().tolist()) == sorted(m.steps for m in recs)
    assert int(got["success"].sum()) == sum(m.success for m in recs) > 0  # the expert succeeds
    assert K.EPISODE not in ra.keys() and (ra["next", K.EPISODE, "steps"][:, 0] == 1).all()  # from zero after a reset


def test_to_device_leaves_nothing_behind(demo):
    """The meta device as a stand-in for a second one: every tensor reachable from the env's attributes (its
    camera, table, Gaussians, the in-env expert, finished records) moves, found by walking the objects themselves,
    not their `state_dict()` (TorchRL's specs cannot go to meta, so `to`'s state half is called; the gpu test
    runs `to("cuda")` whole). The navmesh and its distance fields stay on the CPU by design."""
    env = wanderland_nav.make_env(batch_size=2, env={"expert_action": True, "finished_records": True}, **demo)
    env.rollout(40, lambda td: td.set(K.ACTION, td[K.EXPERT_ACTION]))  # some finished records, expert progress
    assert env._finished and env.expert._progress is not None
    env.move_state(torch.device("meta"))
    found = dict(_tensors(env))
    left = [name for name, t in found.items() if t.device.type != "meta"]
    assert not left, f"still on the CPU after to('meta'): {left}"
    assert len(found) > 50 and "env.expert._progress" in found and any("gaussians" in n for n in found)


def _tensors(obj, name="env", seen=None):
    """(name, tensor) for every tensor reachable from `obj` through attributes (`vars`, slots), dicts, lists and
    tuples, into the project's, torch's and tensordict's objects; the specs and the CPU-side navmesh skipped."""
    seen = set() if seen is None else seen
    if id(obj) in seen or name.rsplit(".", 1)[-1] in ("_input_spec", "_output_spec", "navmesh", "field", "step_field"):
        return
    seen.add(id(obj))
    if isinstance(obj, torch.Tensor):
        yield name, obj
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _tensors(v, f"{name}.{k}" if k in ("_buffers", "_parameters", "_modules") else f"{name}[{k!r}]",
                                seen)
    elif isinstance(obj, (list, tuple, set)):
        for i, v in enumerate(obj):
            yield from _tensors(v, f"{name}[{i}]", seen)
    elif type(obj).__module__.split(".")[0] in ("wanderland_nav", "policies", "torch", "tensordict", "torchrl"):
        attrs = vars(obj) if hasattr(obj, "__dict__") else {}
        attrs = {**attrs, **{k: getattr(obj, k) for k in getattr(type(obj), "__slots__", ()) if hasattr(obj, k)}}
        for k, v in attrs.items():
            if k in ("_buffers", "_parameters", "_modules"):  # nn.Module: their entries as attributes
                for kk, vv in v.items():
                    yield from _tensors(vv, f"{name}.{kk}", seen)
            else:
                yield from _tensors(v, f"{name}.{k}", seen)


def test_the_expert_on_a_policy_facing_env_says_what_to_build(demo):
    from wanderland_nav.envs import ExpertPolicy

    env = wanderland_nav.make_env(batch_size=2, **demo)
    expert = ExpertPolicy(env)
    with pytest.raises(KeyError, match=r"privileged.*env=\{'privileged': True\}.*expert_action"):
        env.rollout(2, expert)
    env = wanderland_nav.make_env(batch_size=2, env={"privileged": True, "camera": {"enabled": False}}, **demo)
    td = env.rollout(60, ExpertPolicy(env), break_when_any_done=False)  # the privileged keys on request
    assert td["next", K.EPISODE, "success"][td["next", "done"]].any()


@pytest.mark.gpu
def test_cuda_env_steps_on_the_gpu(demo):
    env = wanderland_nav.make_env(batch_size=2, device="cuda", **demo)
    td = env.rollout(3)
    assert td.device.type == "cuda" and td["next", K.RGB].is_cuda and env._pos.is_cuda
    assert env.camera.gaussians.means.is_cuda and env.table.goal_position.is_cuda
    cpu = wanderland_nav.make_env(batch_size=2, env={"expert_action": True}, **demo)
    cpu.rollout(2, lambda td: td.set(K.ACTION, td[K.EXPERT_ACTION]))  # the expert's progress exists, on the CPU
    cpu = cpu.to("cuda")
    assert cpu._pos.is_cuda and cpu.camera.K.is_cuda and cpu.camera.gaussians.means.is_cuda
    assert cpu.expert._progress.is_cuda and cpu.expert.paths.is_cuda
    td = cpu.rollout(3, lambda td: td.set(K.ACTION, td[K.EXPERT_ACTION]))
    assert td["next", K.PIXELS].is_cuda and td["next", K.EPISODE, "spl"].is_cuda


def test_pixels_give_video_recorder_one_frame_per_step(demo, tmp_path):
    from torchrl.record import VideoRecorder
    from torchrl.record.loggers import CSVLogger

    logger = CSVLogger("nav", log_dir=str(tmp_path), video_format="pt")
    env = TransformedEnv(wanderland_nav.make_env(batch_size=3, **demo), VideoRecorder(logger, "walk", skip=1))
    env.rollout(4)
    recorder = env.transform
    assert len(recorder.obs) == 5  # reset + 4 steps, the 3 agents tiled into one frame each
    assert recorder.obs[0].dim() == 3 and recorder.obs[0].shape[0] == 3  # one [3, h, w] image per step
    assert torch.equal(env.base_env.render(), env.base_env._rgb[:, -1])
    recorder.dump()
    assert list(tmp_path.rglob("*.pt"))


def test_collector_fills_a_replay_buffer(demo):
    from torchrl.collectors import Collector
    from torchrl.data import LazyTensorStorage, ReplayBuffer

    env = wanderland_nav.make_env(batch_size=2, **demo)
    rb = ReplayBuffer(storage=LazyTensorStorage(64))
    for batch in Collector(env, None, frames_per_batch=8, total_frames=16):
        rb.extend(batch.reshape(-1))
    assert len(rb) == 16 and K.PRIVILEGED not in rb.sample(4)["next"].keys()


def test_gae_through_vmap_equals_the_loop_and_the_raw_policy_fails(demo):
    """The value operator runs under GAE's vmap (GroupNorm in the encoder) with the loop's numbers; the bare
    policy, whose forward also writes state_value, is what TorchRL refuses or cannot vmap."""
    from torchrl.objectives.value import GAE

    from policies import make_policy
    from wanderland_nav.rl.torchrl_modules import policy_modules

    torch.manual_seed(0)
    policy = make_policy("citywalker", **TINY_POLICY)
    env = wanderland_nav.make_env(batch_size=2, policy=policy, **demo)
    actor, value = policy_modules(policy, env)
    with torch.no_grad():
        td = env.rollout(3, actor)
        vm = GAE(gamma=0.9, lmbda=0.9, value_network=value)(td.clone())
        loop = GAE(gamma=0.9, lmbda=0.9, value_network=value, deactivate_vmap=True)(td.clone())
    assert torch.allclose(vm["advantage"], loop["advantage"], atol=1e-5)
    assert vm["advantage"].abs().sum() > 0
    with pytest.raises(RuntimeError, match="vmap"):
        GAE(gamma=0.9, lmbda=0.9, value_network=_BareValue(policy))(td.clone())
    dist = actor.get_dist(td[:, 0])
    assert dist.log_prob(td[:, 0][K.ACTION]).shape == (2,)  # one log-prob per agent, not per waypoint


class _BareValue(torch.nn.Module):
    """The policy's own `value()` as a value network, without the adapter."""

    def __init__(self, policy):
        super().__init__()
        self.policy, self.in_keys, self.out_keys = policy, list(policy.in_keys), [K.STATE_VALUE]

    def forward(self, td: TensorDict) -> TensorDict:
        return self.policy.value(td)


@pytest.mark.slow
def test_parallel_env_and_multi_sync_collector(demo):
    """Workers rebuild the env from make_env's keywords (picklable); each re-imports and reloads the scene."""
    from functools import partial

    from torchrl.collectors import MultiSyncCollector
    from torchrl.data import LazyTensorStorage, ReplayBuffer
    from torchrl.envs import ParallelEnv

    make = partial(wanderland_nav.make_env, batch_size=2, **demo)
    penv = ParallelEnv(2, make)
    try:
        check_env_specs(penv)
        assert penv.rollout(3).batch_size == (2, 2, 3)
    finally:
        penv.close()
    rb = ReplayBuffer(storage=LazyTensorStorage(64))
    collector = MultiSyncCollector([make, make], None, frames_per_batch=16, total_frames=32)
    try:
        for batch in collector:
            rb.extend(batch.reshape(-1))
    finally:
        collector.shutdown()
    assert len(rb) == 32


@pytest.mark.slow
def test_readme_quick_start_verbatim(tmp_path, monkeypatch, capsys):
    """The quick start exactly as written, in a fresh folder (it builds the tiny demo there)."""
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(textwrap.dedent(QUICK_START), scope)
    td = scope["td"]
    assert td.batch_size == (4, 200) and (tmp_path / "data" / "scenes" / "demo_tiny").is_dir()
    assert td["next", "episode", "spl"][td["next", "done"]].numel() > 0  # the SPL print is not empty
