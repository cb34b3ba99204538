"""A tiny point-goal EnvBase speaking NavEnv's keys, so the PPO/BC loops are tested without a scene.

Agents live on an open plane (nav frame). Each episode puts the goal 2-4 m away at a bearing that the
image encodes: the RGB frame is dark with a bright vertical bar at the goal's bearing column, so an
image policy *can* learn; the goal vector is also given. Action: `[K, 2]` body-frame waypoints; the agent
turns to the first waypoint and moves up to `step` metres towards it. Reward as the paper: +1 on
success, -alpha per step, + beta * progress. Fully batched, partial resets via `_reset`.
"""

from __future__ import annotations

import math

import torch
from tensordict import TensorDict
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.data import Binary
from torchrl.envs import EnvBase

from wanderland_nav import keys as K


class FakeNavEnv(EnvBase):
    def __init__(self, batch_size=(4,), *, num_waypoints=5, context=2, size=16, max_steps=12, step=0.6,
                 goal_radius=0.6, num_episodes=8, seed=0):
        super().__init__(batch_size=torch.Size(batch_size), device="cpu")
        self.kw, self.ctx, self.size, self.max_steps = num_waypoints, context, size, max_steps
        self.step_len, self.goal_radius, self.num_episodes = step, goal_radius, num_episodes
        b = self.batch_size
        self.observation_spec = Composite(
            {
                K.RGB: Bounded(0, 255, (*b, context, size, size, 3), dtype=torch.uint8),
                K.PAST_POSITIONS: Unbounded((*b, context, 2)),
                K.GOAL_VECTOR: Unbounded((*b, 2)),
                K.GOAL_POSE: Unbounded((*b, 4)),
                K.GOAL_IMAGE: Bounded(0, 255, (*b, size, size, 3), dtype=torch.uint8),
                K.HAS_GOAL_IMAGE: Binary(1, (*b, 1), dtype=torch.bool),
                K.AGENT_POSITION: Unbounded((*b, 3)),
                K.AGENT_YAW: Unbounded((*b, 1)),
                K.DISTANCE_TO_GOAL: Unbounded((*b, 1)),
                K.EPISODE_INDEX: Unbounded((*b, 1), dtype=torch.int64),
                K.STEP_COUNT: Unbounded((*b, 1), dtype=torch.int64),
                K.SUCCESS: Binary(1, (*b, 1), dtype=torch.bool),
                K.INTERVENTION: Binary(1, (*b, 1), dtype=torch.bool),
            },
            shape=b,
        )
        self.action_spec = Bounded(-5.0, 5.0, (*b, num_waypoints, 2))
        self.reward_spec = Unbounded((*b, 1))
        self.done_spec = Composite({k: Binary(1, (*b, 1), dtype=torch.bool)
                                    for k in (K.DONE, K.TERMINATED, K.TRUNCATED)}, shape=b)
        g = torch.Generator().manual_seed(seed)
        ang = torch.rand(num_episodes, generator=g) * 2 * math.pi - math.pi
        dist = 2.0 + 2.0 * torch.rand(num_episodes, generator=g)
        self.goals = torch.stack([dist * ang.cos(), dist * ang.sin()], -1)  # [E, 2], start at origin, yaw 0
        self.pos = torch.zeros(*b, 2)
        self.yaw = torch.zeros(*b)
        self.ep = torch.zeros(*b, dtype=torch.long)
        self.steps = torch.zeros(*b, dtype=torch.long)
        self.next_ep = 0

    def _set_seed(self, seed):
        self.next_ep = int(seed or 0) % self.num_episodes

    def goal_paths(self) -> torch.Tensor:
        """Straight expert paths start -> goal, `[E, 9, 3]` nav frame (what gt_locations would give)."""
        t = torch.linspace(0, 1, 9)[None, :, None]
        xy = t * self.goals[:, None]
        return torch.cat([xy, torch.zeros_like(xy[..., :1])], -1)

    def _obs(self, success, intervention):
        gw = self.goals[self.ep]                                # [B, 2]
        d = gw - self.pos
        c, s = self.yaw.cos(), self.yaw.sin()
        gb = torch.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], -1)  # body frame
        bearing = torch.atan2(gb[:, 1], gb[:, 0])               # [B], left positive
        col = ((0.5 - bearing / math.pi) * (self.size - 1)).round().long().clamp(0, self.size - 1)
        img = torch.full((*self.batch_size, self.size, self.size, 3), 20, dtype=torch.uint8)
        cols = torch.arange(self.size)
        mask = (cols[None] == col[:, None])                      # [B, W]
        img[mask[:, None, :].expand(-1, self.size, -1)] = 230
        b = self.batch_size
        return {
            K.RGB: img[:, None].expand(-1, self.ctx, -1, -1, -1).clone(),
            K.PAST_POSITIONS: torch.zeros(*b, self.ctx, 2),
            K.GOAL_VECTOR: gb,
            K.GOAL_POSE: torch.cat([gb, torch.ones(*b, 1), torch.zeros(*b, 1)], -1),
            K.GOAL_IMAGE: torch.zeros(*b, self.size, self.size, 3, dtype=torch.uint8),
            K.HAS_GOAL_IMAGE: torch.zeros(*b, 1, dtype=torch.bool),
            K.AGENT_POSITION: torch.cat([self.pos, torch.zeros(*b, 1)], -1),
            K.AGENT_YAW: self.yaw[:, None].clone(),
            K.DISTANCE_TO_GOAL: d.norm(dim=-1, keepdim=True),
            K.EPISODE_INDEX: self.ep[:, None].clone(),
            K.STEP_COUNT: self.steps[:, None].clone(),
            K.SUCCESS: success[:, None], K.INTERVENTION: intervention[:, None],
        }

    def _reset(self, td):
        b = self.batch_size
        mask = torch.ones(*b, dtype=torch.bool) if td is None or K.RESET not in td.keys() else td.get(K.RESET).view(-1)
        n = int(mask.sum())
        eps = (self.next_ep + torch.arange(n)) % self.num_episodes
        self.next_ep = (self.next_ep + n) % self.num_episodes
        self.ep[mask] = eps
        self.pos[mask] = 0.0
        self.yaw[mask] = 0.0
        self.steps[mask] = 0
        z = torch.zeros(*b, dtype=torch.bool)
        obs = self._obs(z, z)
        obs[K.DONE] = torch.zeros(*b, 1, dtype=torch.bool)
        obs[K.TERMINATED] = torch.zeros(*b, 1, dtype=torch.bool)
        obs[K.TRUNCATED] = torch.zeros(*b, 1, dtype=torch.bool)
        return TensorDict(obs, b)

    def _step(self, td):
        wp = td.get(K.ACTION)[:, 0]                              # [B, 2] first waypoint, body frame
        d_prev = (self.goals[self.ep] - self.pos).norm(dim=-1)
        dist = wp.norm(dim=-1).clamp(max=self.step_len)
        head = self.yaw + torch.atan2(wp[:, 1], wp[:, 0])
        self.yaw = torch.atan2(head.sin(), head.cos())
        self.pos = self.pos + dist[:, None] * torch.stack([self.yaw.cos(), self.yaw.sin()], -1)
        self.steps += 1
        d = (self.goals[self.ep] - self.pos).norm(dim=-1)
        success = d < self.goal_radius
        intervention = (d > 8.0) & ~success
        truncated = (self.steps >= self.max_steps) & ~success & ~intervention
        reward = 1.0 * success.float() - 1.0 * intervention.float() - 0.01 + 0.5 * (d_prev - d)
        obs = self._obs(success, intervention)
        term = success | intervention
        obs.update({K.REWARD: reward[:, None], K.TERMINATED: term[:, None], K.TRUNCATED: truncated[:, None],
                    K.DONE: (term | truncated)[:, None]})
        return TensorDict(obs, self.batch_size)
