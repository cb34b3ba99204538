"""Reward and termination rules of the paper's appendix, as pure batched tensor functions.

Kept apart from `NavEnv` so each rule is tested on hand-made tensors, and so a study can swap a
rule without touching the environment's plumbing. All inputs are `[B]` tensors.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from wanderland_nav.envs.config import RewardConfig, TerminationConfig


def navigation_reward(
    d_prev: torch.Tensor, d_now: torch.Tensor, success: torch.Tensor, intervention: torch.Tensor, cfg: RewardConfig
) -> torch.Tensor:
    """`+R_succ` on success, `-R_fail` on intervention, else `-alpha + beta * (d_{t-1} - d_t)`.

    d_prev, d_now `[B]`: geodesic distances to the goal (metres) before and after the step;
    success, intervention `[B]` bool (success wins if both). Returns float32 `[B]`.
    A non-finite distance (goal unreachable from a pose) gives no progress term rather than NaN.
    """
    progress = torch.nan_to_num(d_prev - d_now, nan=0.0, posinf=0.0, neginf=0.0)
    shaped = -cfg.time_penalty + cfg.progress_scale * progress
    r = torch.where(intervention, torch.full_like(shaped, -cfg.failure_penalty), shaped)
    r = torch.where(success, torch.full_like(shaped, cfg.success_reward), r)
    return r.to(torch.float32)


@dataclass
class ProgressState:
    """Per-agent counters behind the intervention rules, all `[B]`."""

    best_distance: torch.Tensor  # float: smallest geodesic distance reached so far in the episode
    steps_without_progress: torch.Tensor  # long
    stuck_steps: torch.Tensor  # long: consecutive blocked, motionless steps


def update_progress(
    state: ProgressState, d_now: torch.Tensor, collided: torch.Tensor, moved: torch.Tensor, cfg: TerminationConfig
) -> ProgressState:
    """Advance the counters after a step (out of place: the old tensors may live in rollouts).

    Progress means beating the best distance so far by `progress_epsilon`; a step is stuck when
    the navmesh blocked it and the body moved less than `stuck_distance` metres.
    """
    improved = d_now < state.best_distance - cfg.progress_epsilon
    best = torch.where(improved, d_now, state.best_distance)
    no_prog = torch.where(improved, torch.zeros_like(state.steps_without_progress), state.steps_without_progress + 1)
    stuck_now = collided & (moved < cfg.stuck_distance)
    stuck = torch.where(stuck_now, state.stuck_steps + 1, torch.zeros_like(state.stuck_steps))
    return ProgressState(best, no_prog, stuck)


def terminations(
    d_now: torch.Tensor,
    radius: torch.Tensor,
    state: ProgressState,
    navigable: torch.Tensor,
    step_count: torch.Tensor,
    cfg: TerminationConfig,
):
    """-> (success, intervention, truncated, cause): `[B]` bool each, mutually exclusive, and `[B]` long.

    success: within the goal radius (geodesic); intervention: stuck for `stuck_steps`, no
    progress for `no_progress_steps`, or off the navigable region; truncated: the step count
    reached `max_steps` without either (timeout is not an intervention). cause: `intervention_cause`'s
    code where `intervention`, else 0 (an episode record says which rule ended it: IR by cause).
    """
    success = d_now <= radius
    cause = torch.where(success, 0, intervention_cause(state, navigable, cfg))
    intervention = cause > 0
    truncated = (step_count >= cfg.max_steps) & ~success & ~intervention
    return success, intervention, truncated, cause




def intervention_cause(state: ProgressState, navigable: torch.Tensor, cfg: TerminationConfig) -> torch.Tensor:
    """`[B]` long: 1 + index into `evaluation.metrics.INTERVENTION_CAUSES` of the rule that fires, 0 where none does.

    The intervention rule of `terminations` (which also requires no success); kept apart so an episode
    record can say which rule ended it (IR by cause).
    """
    stuck = state.stuck_steps >= cfg.stuck_steps
    no_progress = state.steps_without_progress >= cfg.no_progress_steps
    cause = torch.where(no_progress, 3, 0)
    cause = torch.where(stuck, 2, cause)
    return torch.where(~navigable, 1, cause).long()
