"""The benchmark's three navigation tasks over one set of routes: point-goal, image-goal, instruction.

A task is what the policy is *told* about the goal; everything else is shared, so the tasks compare:

* the **episodes** are the same routes (one episodes file: starts, goals, reference paths) for all three;
* the **success rule** is the env's, for all three: the geodesic distance to the goal within the episode's
  goal radius (`envs.rewards.terminations`); SR / SPL / NE / IR mean the same in every task's rows;
* what the policy **observes** differs (`Task.observes`, a subset of the env's observation keys):

  | task | goal given as | keys |
  |---|---|---|
  | pointgoal | body-frame goal vector / pose (`goal_input=route`: the route point ahead, CityWalker's setting) | rgb, depth, past_positions, goal_vector, goal_pose |
  | imagegoal | the goal view, rendered by the agent's own camera at the goal pose, facing along the route's last segment | rgb, depth, past_positions, goal_image, has_goal_image |
  | instruction | the episode's instruction text as tokens (UTF-8 bytes + 1), no goal coordinates | rgb, depth, past_positions, instruction_tokens |

Why a key set rather than blanking values: a policy that reads a key its task hides is refused before it
runs (`check_reads`), so a table row can never come from a policy that peeked at the goal coordinates.
The point-goal env is the env as it is (`task_env_config` returns it unchanged).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Iterable

import torch

from wanderland_nav import keys
from wanderland_nav.envs.config import NavEnvConfig

TASK_NAMES = ("pointgoal", "imagegoal", "instruction")
_SEEN_BY_ALL = (keys.RGB, keys.DEPTH, keys.PAST_POSITIONS)
_GOAL_KEYS = {
    "pointgoal": (keys.GOAL_VECTOR, keys.GOAL_POSE),
    "imagegoal": (keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE),
    "instruction": (keys.INSTRUCTION_TOKENS,),
}
SUCCESS_RULE = "geodesic distance to the goal within the episode's goal radius (the env's rule, every task)"


@dataclass(frozen=True)
class Task:
    """One task: its name, the observation keys a policy may read, and (point-goal) the goal input."""

    name: str
    observes: tuple[str, ...]
    goal_input: str = "goal"  # pointgoal: "goal" (the final goal) | "route" (the route point ahead)

    @property
    def label(self) -> str:
        """The row label: `pointgoal`, `pointgoal(route)`, `imagegoal`, `instruction`."""
        return f"{self.name}(route)" if self.goal_input == "route" else self.name


def make_task(name: str, goal_input: str = "goal") -> Task:
    """The task `name` (one of `TASK_NAMES`); `goal_input` applies to pointgoal only."""
    if name not in TASK_NAMES:
        raise ValueError(f"task {name!r}: expected one of {TASK_NAMES}")
    if goal_input not in ("goal", "route"):
        raise ValueError(f"task {name}: goal_input={goal_input!r}, expected goal or route")
    return Task(name, _SEEN_BY_ALL + _GOAL_KEYS[name], goal_input if name == "pointgoal" else "goal")


def hidden_reads(task: Task, reads: Iterable[str]) -> list[str]:
    """The keys of `reads` that `task` does not show (sorted); empty when the policy fits the task."""
    return sorted(str(k) for k in set(reads) - set(task.observes))


def check_reads(task: Task, reads: Iterable[str], who: str) -> None:
    """Refuse a policy that reads keys its task hides, naming them."""
    bad = hidden_reads(task, reads)
    if bad:
        raise ValueError(f"{who} reads {bad}, which task {task.name} does not show (it shows {list(task.observes)})")


def task_env_config(task: Task, env: NavEnvConfig) -> NavEnvConfig:
    """The env config of `task`: pointgoal unchanged; imagegoal renders every episode's goal view with the agent's
    camera (`goal_image="render"`) and carries it; instruction carries the instruction tokens."""
    if task.name == "imagegoal":
        if not env.camera.enabled:
            raise ValueError("task imagegoal: the goal view is rendered by the agent's camera; camera.enabled is false")
        return dataclasses.replace(env, goal_image="render", observe_goal_image=True)
    if task.name == "instruction":
        return dataclasses.replace(env, observe_instruction=True)
    return env


def check_task_episodes(task: Task, env, where: str) -> None:
    """Refuse an env whose episodes cannot pose `task`: an image-goal episode without a goal view, an instruction
    episode without text. `env` is the `NavEnv` (or a transformed one with `.base_env`)."""
    base = getattr(env, "base_env", env)
    if task.name == "imagegoal":
        has = base.goal_view_mask
    elif task.name == "instruction":
        has = base.table.instruction_tokens.ne(0).any(-1)
    else:
        return
    missing = torch.nonzero(~has.cpu()).flatten()
    if missing.numel():
        i = int(missing[0])
        raise ValueError(f"{where}: task {task.name}: {missing.numel()} of {has.numel()} episodes have no "
                         f"{'goal view' if task.name == 'imagegoal' else 'instruction text'} (first: episodes[{i}], "
                         f"id {base.table.ids[i]})")
