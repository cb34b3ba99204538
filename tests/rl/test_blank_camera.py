"""The vision ablation's wrapper: the policy sees black frames, the env's observation is left as rendered."""

from __future__ import annotations

import torch
from fake_env import FakeNavEnv

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.rl.blank_camera import BlankCamera


def test_policy_sees_black_frames_and_the_observation_is_put_back():
    torch.manual_seed(0)
    policy = make_policy("cnn", image_size=(16, 16), context=2, feature_dim=32)
    with torch.no_grad():                        # a head that reads the image features, so the camera matters
        policy.head.weight.normal_(0, 0.5)
    td = FakeNavEnv((3,)).reset()
    rgb = td.get(K.RGB).clone()
    assert rgb.max() > 0
    blind = BlankCamera(policy).select_action(td.clone(), deterministic=True)
    black = td.clone()
    black.set(K.RGB, torch.zeros_like(rgb))
    expect = policy.select_action(black, deterministic=True)
    torch.testing.assert_close(blind.get(K.ACTION), expect.get(K.ACTION))
    assert torch.equal(blind.get(K.RGB), rgb)                       # recordings keep the rendered view
    seeing = policy.select_action(td.clone(), deterministic=True)
    assert not torch.allclose(seeing.get(K.ACTION), blind.get(K.ACTION))
    assert len(list(BlankCamera(policy).parameters())) == len(list(policy.parameters()))  # sampled eval's device
