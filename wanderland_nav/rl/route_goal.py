"""Route-following goal input: the point `lookahead` metres ahead on the episode's planned route.

Why: `experiments/train/diagnose_bc.py` shows that on the demo block the expert's next waypoints are
not a function of the point-goal observation (final-goal vector, 5 past positions, 32 px frames): a
third of the expert's states head more than 30 degrees away from the goal to go round a building,
and without a map nothing in the observation says which way round. CityWalker itself is deployed
that way: it follows GPS waypoints of a route from a map planner, not a bare goal behind a block.
This transform gives the policy the same input: `GOAL_VECTOR` (and the position part of `GOAL_POSE`)
becomes the body-frame point `lookahead` metres along the episode's planned route (`gt_locations`)
from the agent's projection onto it; at the route's end that is the goal itself.

It is an explicit setting (`goal_input: route` in `conf/train.yaml`), written in every table header,
because it changes the task from point-goal navigation to route following.
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.envs import Transform, TransformedEnv

from wanderland_nav import keys as K
from wanderland_nav.rl.bc import ExpertPaths
from wanderland_nav.rl.critic import FINAL_GOAL_VECTOR

GOAL_INPUTS = ("goal", "route")


class RouteGoal(Transform):
    """Overwrites `GOAL_VECTOR` `[*B, 2]` and `GOAL_POSE[..., :2]` with the route point ahead (body frame, m);
    the final goal's vector stays readable as `FINAL_GOAL_VECTOR` (PPO's critic reads it, the policy does not)."""

    def __init__(self, paths: ExpertPaths, lookahead: float):
        super().__init__(in_keys=[K.AGENT_POSITION, K.AGENT_YAW, K.EPISODE_INDEX], out_keys=[K.GOAL_VECTOR])
        if lookahead <= 0:
            raise ValueError(f"RouteGoal: lookahead must be > 0 metres, got {lookahead}")
        self.paths, self.lookahead = paths, float(lookahead)

    def route_point(self, td: TensorDictBase) -> torch.Tensor:
        lead = td.batch_size
        n = lead.numel()
        p = self.paths.waypoints(td.get(K.AGENT_POSITION).reshape(n, 3).cpu(), td.get(K.AGENT_YAW).reshape(n).cpu(),
                                 td.get(K.EPISODE_INDEX).reshape(n).cpu(), 1, self.lookahead)[:, 0]
        return p.view(*lead, 2).to(td.get(K.GOAL_VECTOR).device)

    def _call(self, td: TensorDictBase) -> TensorDictBase:
        if K.AGENT_POSITION not in td.keys(True):  # privileged keys are nested
            return td
        sub = self.route_point(td)
        td.set(FINAL_GOAL_VECTOR, td.get(K.GOAL_VECTOR).clone())
        td.set(K.GOAL_VECTOR, sub)
        if K.GOAL_POSE in td.keys(True):
            pose = td.get(K.GOAL_POSE).clone()
            pose[..., :2] = sub
            td.set(K.GOAL_POSE, pose)
        return td

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec):
        observation_spec[FINAL_GOAL_VECTOR] = observation_spec[K.GOAL_VECTOR].clone()
        return observation_spec


def with_goal_input(env, goal_input: str = "goal", lookahead: float = 3.0):
    """`env` unchanged for `goal_input="goal"`; wrapped with `RouteGoal` over its own episodes for `"route"`."""
    if goal_input not in GOAL_INPUTS:
        raise ValueError(f"goal_input={goal_input!r}: expected one of {GOAL_INPUTS}")
    if goal_input == "goal":
        return env
    paths = ExpertPaths.from_episodes(env.episodes, env.scene.nav_from_scene)
    return TransformedEnv(env, RouteGoal(paths, lookahead))


class GoalInputEnvFn:
    """A picklable env factory (collector workers call it): `env_fn(*args, **kwargs)` with the goal input
    applied (a plain `() -> env` factory, or a per-scene `(scene_id, batch_size, seed) -> env` one)."""

    def __init__(self, env_fn, goal_input: str = "goal", lookahead: float = 3.0):
        if goal_input not in GOAL_INPUTS:
            raise ValueError(f"goal_input={goal_input!r}: expected one of {GOAL_INPUTS}")
        self.env_fn, self.goal_input, self.lookahead = env_fn, goal_input, float(lookahead)

    def __call__(self, *args, **kwargs):
        return with_goal_input(self.env_fn(*args, **kwargs), self.goal_input, self.lookahead)
