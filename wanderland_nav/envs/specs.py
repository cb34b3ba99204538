"""The specs of a `NavEnv`: what its observations, actions, rewards and done flags are, from its config."""

from __future__ import annotations

import torch
from torchrl.data import Bounded, Categorical, Composite, Unbounded

from wanderland_nav import keys


def nav_env_specs(env) -> tuple[Composite, Bounded, Composite, Composite]:
    """-> (observation, action, reward, done) specs of `env` (a `NavEnv`: its batch size, device, config, which
    observations it carries, its expert and its crowd's episode keys)."""
    B, c, k = env.batch_size, env.config.camera, env.config.kinematics
    T, H, W, L = c.history, c.height, c.width, env.config.instruction_length
    dev = env.device
    f32 = lambda *s: Unbounded(shape=(*B, *s), dtype=torch.float32, device=dev)  # noqa: E731
    i64 = lambda *s: Unbounded(shape=(*B, *s), dtype=torch.int64, device=dev)  # noqa: E731
    flag = lambda: Categorical(2, shape=(*B, 1), dtype=torch.bool, device=dev)  # noqa: E731
    # uint8 images as Unbounded: a Bounded spec would hold full-size low/high tensors (B*T*H*W*3 each)
    img = lambda *s: Unbounded(shape=(*B, *s), dtype=torch.uint8, device=dev)  # noqa: E731
    obs = {keys.PAST_POSITIONS: f32(T, 2), keys.GOAL_VECTOR: f32(2), keys.GOAL_POSE: f32(4)}
    if env.carries_instruction:
        obs[keys.INSTRUCTION_TOKENS] = i64(L)
    if env.carries_frames:
        obs[keys.RGB] = img(T, H, W, 3)
        if c.depth:
            obs[keys.DEPTH] = f32(T, H, W, 1)
    if env.carries_goal_views:
        obs.update({keys.GOAL_IMAGE: img(H, W, 3), keys.HAS_GOAL_IMAGE: flag()})
    if env.config.pixels:
        obs[keys.PIXELS] = img(H, W, 3)
    if env.config.privileged:  # ground truth no policy may read: nested under keys.PRIVILEGED by the keys
        obs.update({keys.EPISODE_INDEX: i64(1), keys.STEP_COUNT: i64(1), keys.AGENT_POSITION: f32(3),
                    keys.AGENT_YAW: f32(1), keys.DISTANCE_TO_GOAL: f32(1), keys.SUCCESS: flag(),
                    keys.INTERVENTION: flag(), keys.COLLISION: flag()})
    observation = Composite(obs, shape=B, device=dev)
    if k.action_mode == "waypoints":
        r = k.waypoint_range
        action = Bounded(-r, r, shape=(*B, k.num_waypoints, 2), dtype=torch.float32, device=dev)
    else:
        low = torch.tensor([0.0, -k.max_angular_speed], device=dev).expand(*B, 2)
        high = torch.tensor([k.max_linear_speed, k.max_angular_speed], device=dev).expand(*B, 2)
        action = Bounded(low.clone(), high.clone(), shape=(*B, 2), dtype=torch.float32, device=dev)
    if env.expert is not None:
        observation[keys.EXPERT_ACTION] = Unbounded(shape=action.shape, dtype=torch.float32,
                                                              device=dev)
    # The episode metrics are step outputs beside the reward, no observation: in the reward spec they appear in
    # ("next", "episode") only, never at a reset, and the env's step_mdp leaves them behind as it leaves the reward
    # (in the done spec TorchRL would OR them into `done`; in the observation spec recipes feed them to policies)
    rewards = {keys.REWARD: Unbounded(shape=(*B, 1), dtype=torch.float32, device=dev)}
    if env.config.episode_metrics:
        rewards.update({key: (flag() if key in (keys.EPISODE_SUCCESS, keys.EPISODE_INTERVENTION) else
                              i64(1) if key in (keys.EPISODE_STEPS, keys.EPISODE_COLLISIONS) else f32(1))
                        for key in keys.EPISODE_KEYS})
        rewards.update({key: i64(1) if key == keys.EPISODE_PERSON_COLLISIONS else f32(1)
                        for key in env.pedestrians.episode_keys})
    reward = Composite(rewards, shape=B, device=dev)
    done = Composite(
        {keys.DONE: flag(), keys.TERMINATED: flag(), keys.TRUNCATED: flag()}, shape=B, device=dev
    )
    return observation, action, reward, done
