"""The PPO update encodes each distinct camera image once, and its loss and gradients are those of encoding every
context frame of every sample separately (the update before `policies.frame_memo`)."""

from __future__ import annotations

import types
from contextlib import nullcontext

import pytest
import torch
from fake_env import FakeNavEnv

from policies import make_policy
from policies.frame_memo import FrameMemo, content_keys, distinct
from wanderland_nav import keys as K
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer, make_collector

pytestmark = pytest.mark.usefixtures("one_thread")

B, T, C, S = 4, 8, 5, 16


class NullLogger:
    def log_scalars(self, scalars, step):
        pass

    def log_rollout(self, rollout, step, tag="eval"):
        pass

    def close(self):
        pass


def plain_frame_features(self, rgb, encoder):
    """Every context frame of every sample through the encoder: what the policies did before."""
    img = self.images(rgb)
    n, c = img.shape[:2]
    return encoder(img.flatten(0, 1)).view(n, c, -1)


def make_trainer(freeze: str, plain: bool) -> PPOTrainer:
    torch.manual_seed(0)
    policy = make_policy("citywalker", encoder="cnn", image_size=(S, S), context=C, dim=32, depth=1, heads=2,
                         freeze_encoder=freeze)
    if plain:
        policy.frame_features = types.MethodType(plain_frame_features, policy)
        policy.reuse_frame_features = lambda *rgb: nullcontext()
    cfg = PPOConfig(total_frames=B * T, frames_per_batch=B * T, minibatch_size=8, epochs=2, lr=1e-3,
                    target_kl=None, critic_epochs=2, critic_warmup_iters=0, overlap=False)
    return PPOTrainer(policy, lambda: FakeNavEnv((B,), context=C, size=S), cfg, logger=NullLogger(),
                      progress=False, kinematics=KinematicsConfig())


def sliding_batch() -> "TensorDict":  # noqa: F821
    """A `[B, T]` rollout of the fake env whose RGB histories are sliding windows over a stream of distinct
    frames (as NavEnv's are: consecutive steps share C-1 images), agent 0 resetting mid-batch (its first
    frame repeated C times)."""
    t = make_trainer("rl", plain=True)
    collector = make_collector(t.env_fn, t.actor, frames_per_batch=B * T, total_frames=B * T)
    batch = next(iter(collector))
    collector.shutdown()
    g = torch.Generator().manual_seed(1)
    stream = torch.randint(0, 256, (B, T + C, S, S, 3), generator=g, dtype=torch.uint8)
    win = torch.stack([stream[:, i:i + C] for i in range(T + 1)], dim=1)     # [B, T+1, C, S, S, 3]
    win[0, 4:] = stream[0, 4 + C - 1][None, None]                             # agent 0 restarts at step 4
    batch.set(K.RGB, win[:, :T].clone())
    batch.set(("next", K.RGB), win[:, 1:].clone())
    return batch


def count_encoded(policy) -> list[int]:
    rows = []
    policy.encoder.register_forward_hook(lambda m, inp, out: rows.append(inp[0].shape[0]))
    return rows


@pytest.mark.parametrize("freeze", ["rl", "never"])
def test_update_equals_the_update_that_encodes_every_frame(freeze):
    batch = sliding_batch()
    results, params, counts = [], [], []
    for plain in (True, False):
        t = make_trainer(freeze, plain)
        counts.append(count_encoded(t.policy))
        # SGD for the comparison: Adam divides by the gradient's own magnitude, so it turns the float noise of
        # gradients that are zero in exact arithmetic (attention's key bias) into full lr-sized steps
        t.optim = torch.optim.SGD([{"params": g["params"], "lr": g["lr"]} for g in t.optim.param_groups])
        before = {n: p.detach().clone() for n, p in t.policy.named_parameters()}
        torch.manual_seed(7)  # the minibatch permutations
        results.append(t.update(batch.clone()))
        step = max(float((p.detach() - before[n]).abs().max()) for n, p in t.policy.named_parameters())
        assert step > 1e-4  # the comparison below (atol 1e-5) is not between two unmoved policies
        params.append({n: p.detach().clone() for n, p in t.policy.named_parameters()})
        params[-1].update({f"critic.{n}": p.detach().clone() for n, p in t.critic.named_parameters()})
    old, new = results
    assert old.keys() == new.keys()
    for k in old:
        assert new[k] == pytest.approx(old[k], rel=1e-4, abs=1e-5), k
    moved = 0
    for n, p in params[0].items():
        torch.testing.assert_close(params[1][n], p, rtol=1e-4, atol=1e-5, msg=n)
        moved += n.startswith("encoder.") and freeze == "never"
    distinct_images = (B - 1) * (T + C) + 4 + C  # agent 0: windows 0..3 (frames 0..C+2), then one frame
    plain_rows, new_rows = sum(counts[0]), sum(counts[1])
    assert plain_rows == (2 + 2) * B * T * C          # critic inputs (batch, next) + 2 epochs, C images a frame
    if freeze == "rl":   # every distinct image once for the whole update
        assert new_rows == distinct_images
    else:                # once per minibatch pass: at most the minibatch's distinct images
        assert new_rows < plain_rows / 2
        assert moved > 0


def test_minibatch_loss_and_gradients_match_with_the_memo():
    batch = sliding_batch()
    grads, losses = [], []
    for plain in (True, False):
        t = make_trainer("rl", plain)
        flat = batch.reshape(-1)
        flat.set("advantage", torch.linspace(-1, 1, B * T).view(B * T, 1))
        with t._shared_frame_features(batch):
            out = t.loss(flat[torch.arange(3, 3 + 12)])
        out["loss_objective"].backward()
        losses.append(out["loss_objective"].detach())
        grads.append({n: p.grad.clone() for n, p in t.policy.named_parameters() if p.grad is not None})
    torch.testing.assert_close(losses[1], losses[0], rtol=1e-5, atol=1e-6)
    assert grads[0].keys() == grads[1].keys() and len(grads[0]) > 5
    assert not any(n.startswith("encoder.") for n in grads[0])  # frozen: the encoder gets no gradient
    for n in grads[0]:
        torch.testing.assert_close(grads[1][n], grads[0][n], rtol=1e-4, atol=1e-6, msg=n)


def test_distinct_groups_equal_images_and_refuses_a_colliding_key(monkeypatch):
    g = torch.Generator().manual_seed(0)
    imgs = torch.randint(0, 256, (5, 12), generator=g, dtype=torch.uint8)
    flat = imgs[torch.tensor([0, 1, 0, 2, 1, 3, 4, 4])]
    rep, inverse = distinct(flat)
    assert len(rep) == 5 and torch.equal(flat[rep][inverse], flat)
    assert inverse[0] == inverse[2] and inverse[1] == inverse[4] and inverse[6] == inverse[7]
    assert len(set(content_keys(imgs).tolist())) == 5
    monkeypatch.setattr("policies.frame_memo.content_keys", lambda x: torch.zeros(x.shape[0], dtype=torch.long))
    rep, inverse = distinct(flat)                # every key collides: no grouping is trusted
    assert rep.tolist() == list(range(8)) and inverse.tolist() == list(range(8))


def test_memo_looks_up_held_images_and_encodes_the_others():
    g = torch.Generator().manual_seed(0)
    held = torch.randint(0, 256, (6, 2, 2, 3), generator=g, dtype=torch.uint8)
    other = torch.randint(0, 256, (2, 2, 2, 3), generator=g, dtype=torch.uint8)
    enc = torch.nn.Linear(12, 3)
    seen = []

    def encode(x):
        seen.append(x.shape[0])
        return enc(x.reshape(x.shape[0], -1).float())

    memo = FrameMemo(torch.cat([held, held[:2]]))
    assert len(memo) == 6
    query = torch.cat([held[[5, 0]], other[[1]], held[[3]], other[[1, 0]]])
    with torch.no_grad():
        got = memo.features(enc, query, encode)
        torch.testing.assert_close(got, encode(query))
    assert seen[:2] == [6, 2]                     # the table once, then the two distinct misses
