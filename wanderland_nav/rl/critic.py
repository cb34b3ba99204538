"""PPO's critic: its own network, fitted to PopArt-normalised returns on features computed once per batch.

Why (diagnosed on the demo, `experiments/train/README.md`): the previous critic, the policy's
`value_head` on the frozen readout token, explained ~0 % of the return variance. Three reasons:
1. the return is dominated by the remaining geodesic distance (progress reward, 1 per metre) and the
   terminal +-10, but with `goal_input=route` the policy's goal token is a point 3 m ahead on the route,
   which says nothing about how far the final goal is; the critic also gets the final goal's body-frame
   vector (`FINAL_GOAL_VECTOR`, the point-goal observation, written by `RouteGoal`) and the episode clock
   (steps / `horizon`: episodes time out, so the value depends on the time left);
2. returns of +-10..30 fitted with a smooth-L1 loss in 8 minibatch steps per iteration: here the targets
   are normalised (PopArt, van Hasselt et al. 2016: running mean / std, with the output layer rescaled so
   that predictions are preserved when the statistics move), and the network is fitted for `epochs`
   passes on features computed once per batch (a small MLP: cheap next to rendering);
3. the readout features are detached: the critic never moves the actor's trunk.
Nothing privileged about the world is read: the final goal vector is what a point-goal agent sees,
and the clock is the agent's own step counter (stored under `privileged/` with the env's state).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torch import nn

from policies.base import NavPolicy
from wanderland_nav import keys as K

FINAL_GOAL_VECTOR = "final_goal_vector"
"""float32 `[2]`: the final goal in the body frame (x forward, y left), metres; `GOAL_VECTOR` when the
goal input is the goal itself, kept by `RouteGoal` when it overwrites `GOAL_VECTOR` with a route point."""


def _goal_features(goal: torch.Tensor) -> torch.Tensor:
    """Body-frame goal `[N, 2]` (m) -> `[N, 4]`: distance / 10 m, log(1 + distance), cos and sin of the bearing."""
    d = goal.norm(dim=-1, keepdim=True)
    unit = goal / d.clamp_min(1e-6)
    return torch.cat([d / 10.0, torch.log1p(d), unit], dim=-1)


class NavCritic(nn.Module):
    """V(s) = mu + sigma * net([policy readout features, final-goal features, clock]) (denormalised, reward units)."""

    def __init__(self, policy: NavPolicy, hidden: int = 256, horizon: float = 100.0, stats_decay: float = 0.9):
        super().__init__()
        object.__setattr__(self, "policy", policy)  # read only, never trained here: not a submodule (state_dict)
        self.horizon, self.stats_decay = float(horizon), float(stats_decay)
        in_dim = policy.feature_dim + 4 + 1
        self.net = nn.Sequential(nn.LayerNorm(in_dim), nn.Linear(in_dim, hidden), nn.SiLU(),
                                 nn.Linear(hidden, hidden), nn.SiLU())
        self.out = nn.Linear(hidden, 1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        self.register_buffer("mu", torch.zeros(()))
        self.register_buffer("sigma", torch.ones(()))
        self.register_buffer("batches", torch.zeros((), dtype=torch.long))

    @torch.no_grad()
    def inputs(self, td: TensorDictBase) -> torch.Tensor:
        """TensorDict `[*B]` -> critic inputs `[*B, F]` (no gradients: the trunk is the actor's)."""
        lead = td.batch_size
        feats = self.policy.value_features(td)                                     # [N, D]
        keys = td.keys(True)
        goal = td.get(FINAL_GOAL_VECTOR) if FINAL_GOAL_VECTOR in keys else td.get(K.GOAL_VECTOR)
        n = feats.shape[0]
        clock = (td.get(K.STEP_COUNT).reshape(n, 1).float() / self.horizon if K.STEP_COUNT in keys
                 else feats.new_zeros(n, 1))
        x = torch.cat([feats, _goal_features(goal.reshape(n, 2).float()), clock], dim=-1)
        return x.view(*lead, -1)

    def normalized(self, x: torch.Tensor) -> torch.Tensor:
        """Inputs `[..., F]` -> normalised value `[..., 1]` (what the loss compares with normalised targets)."""
        return self.out(self.net(x))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Inputs `[..., F]` -> value `[..., 1]` in reward units."""
        return self.mu + self.sigma * self.normalized(x)

    def normalize(self, target: torch.Tensor) -> torch.Tensor:
        return (target - self.mu) / self.sigma

    @torch.no_grad()
    def update_stats(self, target: torch.Tensor) -> None:
        """PopArt: move (mu, sigma) towards the batch's value targets and rescale the output layer so that
        every prediction is unchanged. The first batch sets the statistics outright."""
        t = target.detach().double().flatten()
        decay = 0.0 if int(self.batches) == 0 else self.stats_decay
        mean = decay * float(self.mu) + (1 - decay) * float(t.mean())
        second = decay * (float(self.sigma) ** 2 + float(self.mu) ** 2) + (1 - decay) * float((t * t).mean())
        sigma = max((second - mean * mean), 1e-4) ** 0.5
        self.out.weight.mul_(float(self.sigma) / sigma)
        self.out.bias.mul_(float(self.sigma)).add_(float(self.mu) - mean).div_(sigma)
        self.mu.fill_(mean)
        self.sigma.fill_(sigma)
        self.batches += 1


def explained_variance(pred: torch.Tensor, target: torch.Tensor) -> float:
    """1 - Var(target - pred) / Var(target): 1 perfect, 0 no better than the mean, < 0 worse (NaN: constant target)."""
    var = float(target.var())
    return float("nan") if var == 0 else 1.0 - float((target - pred).var()) / var


def fit_critic(critic: NavCritic, optim: torch.optim.Optimizer, x: torch.Tensor, target: torch.Tensor, *,
               epochs: int, minibatch_size: int, max_grad_norm: float,
               generator: torch.Generator | None = None) -> float:
    """`epochs` passes of MSE on normalised targets over cached inputs `x` `[N, F]`, targets `[N, 1]`
    (statistics updated first). Returns the last epoch's mean loss (normalised units)."""
    critic.update_stats(target)
    goal = critic.normalize(target)
    n, loss_sum, steps = x.shape[0], 0.0, 0
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=generator)
        loss_sum, steps = 0.0, 0
        for start in range(0, n, minibatch_size):
            idx = perm[start:start + minibatch_size]
            loss = (critic.normalized(x[idx]) - goal[idx]).pow(2).mean()
            optim.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(critic.parameters(), max_grad_norm)
            optim.step()
            loss_sum, steps = loss_sum + float(loss.detach()), steps + 1
    return loss_sum / max(steps, 1)
