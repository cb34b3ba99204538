"""`NavEnv`: B agents navigating one scene, moved on the navmesh, seeing through the splat renderer.

One TorchRL `EnvBase` with `batch_size=[B]`. The agent state (position at the feet, heading) lives
in the **nav frame** (z up); the navmesh and the renderer are called in the **scene frame** at the
boundary (`Scene.nav_from_scene`). A step is a fixed sequence of batched calls, never a loop over
agents:

    plan_motion (kinematics)  ->  NavMesh.move_along_surface  ->  distance field lookup
    -> rewards / terminations  ->  render the B cameras  ->  assemble observations

Geodesic distances: the exact `NavMesh.distance_field` over all (de-duplicated) episode goals gives
the start-goal lengths and rejects unreachable episodes at construction; per step, `d_t` comes
from its O(1) raster (`planners.GeodesicRaster`: exact almost everywhere, never below the exact
distance, at most 2 sqrt(2) cell sizes above it). A step whose distance is undefined (the agent on
another island than its goal) keeps the last defined distance, can never succeed, and is counted. Episode-level metrics are accumulated
per agent and handed out by `pop_finished_metrics()` for the trainer and the evaluator.

Keys exist only when they carry something (spec and tensordicts alike, fixed at construction): with the
camera off (blind or privileged agents) there are no image keys, so TorchRL's resets and copies never
touch blank frames; goal views and instruction tokens only when the task has them; the ground truth
(`privileged/`), the episode metrics (`episode/`), `pixels` and `expert_action` as `NavEnvConfig` asks.

`to(device)` (or the constructor's `device=`) moves every state tensor, the episode table, the goal
views, the camera and its Gaussians; the navmesh and its distance fields stay on the CPU (the
boundary copies there and back).

State tensors are replaced, never written in place: the tensors returned in a step's TensorDict
may be kept by a rollout, and must not change afterwards.
"""

from __future__ import annotations

import dataclasses
import logging
import time
import warnings
from collections import defaultdict
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import EnvBase

from wanderland_nav import keys
from wanderland_nav.envs.camera import AgentCamera, Renderer, one_intra_op_thread
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.envs.episode_table import build_episode_table
from wanderland_nav.envs.kinematics import finite_actions, plan_motion
from wanderland_nav.envs.rewards import ProgressState, navigation_reward, terminations, update_progress
from wanderland_nav.envs.experts import ExpertPolicy
from wanderland_nav.envs.pedestrians.component import make_pedestrians
from wanderland_nav.envs.specs import nav_env_specs
from wanderland_nav.evaluation.metrics import INTERVENTION_CAUSES, EpisodeMetrics, spl
from wanderland_nav.geometry import wrap_angle, world_to_body_2d
from wanderland_nav.render import render

log = logging.getLogger(__name__)


def _moved(value, device):
    """`value` with every tensor in it (dicts, lists, tuples, dataclasses such as `EpisodeTable`) on
    `device`; the same object when it holds no tensor."""
    if isinstance(value, torch.Tensor):
        return value.to(device)
    if isinstance(value, dict):
        new = {k: _moved(v, device) for k, v in value.items()}
        return new if any(new[k] is not value[k] for k in value) else value
    if isinstance(value, (list, tuple)) and not hasattr(value, "_fields"):
        new = [_moved(v, device) for v in value]
        return type(value)(new) if any(a is not b for a, b in zip(new, value)) else value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        new = {f.name: _moved(getattr(value, f.name), device) for f in dataclasses.fields(value)}
        changed = {k: v for k, v in new.items() if v is not getattr(value, k)}
        return dataclasses.replace(value, **changed) if changed else value
    return value


class NavEnv(EnvBase):
    """Batched point-goal / image-goal / instruction navigation in a prepared scene.

    Args:
        scene: a loaded `Scene` (its frame, name and root; nothing is read from its folder here).
        episodes: `Episode`s of that scene (scene frame), e.g. `load_episodes(path, split="val")`.
        batch_size: `[B]`, the number of agents stepped together.
        device: where observations, actions and the renderer live (the navmesh runs on CPU).
        config: `NavEnvConfig`.
        navmesh: the loaded `planners.NavMesh` (or a stand-in with the same methods).
        gaussians, renderer: the camera's splats and renderer (default `wanderland_nav.render.render`);
            `gaussians` is required while `config.camera.enabled`.
        seed: seeds the episode sampler (also `set_seed`).
        goal_images: `(images uint8 [E, H, W, 3], has bool [E])` for `goal_image="auto"`, loaded by the
            caller (`episode_table.load_goal_images`); required when an episode names a goal view.
    """

    batch_locked = True
    # TorchRL's entry points, its own bookkeeping included (tensordict copies, `where` on resets)
    step = one_intra_op_thread(EnvBase.step)
    reset = one_intra_op_thread(EnvBase.reset)
    step_and_maybe_reset = one_intra_op_thread(EnvBase.step_and_maybe_reset)

    def __init__(
        self,
        scene,
        episodes: Sequence,
        batch_size: Sequence[int] = (1,),
        device: str | torch.device = "cpu",
        config: NavEnvConfig | None = None,
        *,
        navmesh,
        gaussians=None,
        renderer: Renderer | None = None,
        seed: int = 0,
        goal_images: tuple[torch.Tensor, torch.Tensor] | None = None,
        episodes_source: str | None = None,
    ):
        batch_size = torch.Size(batch_size)
        if len(batch_size) != 1 or batch_size[0] < 1:
            raise ValueError(f"NavEnv: batch_size must be [B] with B >= 1, got {list(batch_size)}")
        super().__init__(device=device, batch_size=batch_size)
        self.config = config if config is not None else NavEnvConfig()
        self.config.validate()
        self.scene = scene
        self.episodes = list(episodes)
        # the file(s) the episodes came from (`episodes=`), else the scene's own: what errors name
        where = episodes_source or f"{getattr(scene, 'episodes_path', None) or getattr(scene, 'root', 'scene')}"
        self.episodes_source = where
        self.navmesh = navmesh
        if self.config.camera.enabled:
            if gaussians is None:
                raise ValueError(f"NavEnv({getattr(scene, 'name', 'scene')}): camera.enabled needs `gaussians` "
                                 "(load them with wanderland_nav.compose, or set camera.enabled=false)")
            renderer = render if renderer is None else renderer
        self._R_ns = torch.as_tensor(np.asarray(scene.nav_from_scene), dtype=torch.float32)  # nav_from_scene [3, 3]
        cfg = self.config
        self.table = build_episode_table(
            self.episodes, scene, self.navmesh, instruction_length=cfg.instruction_length, where=where
        ).to(self.device)
        self.field = self.navmesh.distance_field(self.table.field_goals_scene)  # exact: lengths and checks
        # O(1) per step, same goals; each goal's raster built on its first reset, cached beside the navmesh
        navmesh_path = getattr(scene, "navmesh_path", None)
        self.step_field = self.field.raster(cache_dir=Path(navmesh_path).parent if navmesh_path else None)
        self.camera = AgentCamera(cfg.camera, scene.nav_from_scene, renderer, gaussians, self.device)
        # pedestrians (envs/pedestrians/): a component with reset and step hooks, inert when count is 0
        self.pedestrians = make_pedestrians(cfg.pedestrians, navmesh, scene.nav_from_scene,
                                            self.nav_to_scene(self.table.start_position).cpu().numpy(), batch_size[0],
                                            cfg.kinematics.control_period, self.device)
        self.crowd = self.pedestrians.crowd  # the people themselves (None without): the expert yields to them
        self._init_goal_images(where, goal_images)
        # Image keys exist only when there are images: with the camera off, blank [B, T, H, W, 3] frames
        # were ~85 % of a B=256 step (TorchRL's reset `where` and copies over them); blank goal views and
        # 512 instruction tokens were ~53 KB of ~300 KB per agent-step of a point-goal run at 128 px.
        self.carries_frames = cfg.camera.enabled
        # episodes with a start serial >= this are not counted by anyone (an evaluation of its first n episodes
        # sets n): their agents step on, with black frames instead of renders. None: every agent renders.
        self.count_serials: int | None = None
        has_view, has_text = bool(self._has_goal_image.any()), bool(self.table.instruction_tokens.any())
        self.carries_goal_views = has_view if cfg.observe_goal_image is None else cfg.observe_goal_image
        self.carries_instruction = has_text if cfg.observe_instruction is None else cfg.observe_instruction
        for name, carried, has in (("observe_goal_image", self.carries_goal_views, has_view),
                                   ("observe_instruction", self.carries_instruction, has_text)):
            if has and not carried:  # the task would be unsolvable without them: say so, do not drop them
                raise ValueError(f"{where}: episodes carry {name[8:]}s but NavEnvConfig.{name}=false")
        if cfg.termination.success_radius is not None:
            self.table.goal_radius = torch.full_like(self.table.goal_radius, cfg.termination.success_radius)
        self.shortest_length = self._shortest_lengths(where)  # [E] exact geodesic start -> goal
        self.expert = None
        if cfg.expert_action:  # stateful (progress along each agent's path), driven by the env's own state
            self.expert = ExpertPolicy(self)
        self._make_specs()
        self._init_state()
        self.timings: dict[str, float] = defaultdict(float)
        self._finished: list[dict[str, torch.Tensor]] = []
        self.set_seed(seed)

    # ------------------------------------------------------------------ construction

    def _init_goal_images(self, where: str, loaded) -> None:
        c, mode = self.config.camera, self.config.goal_image
        E = len(self.table)
        if mode == "render":
            imgs, _ = self.camera.render(self.table.goal_position, self.table.goal_yaw)
            has = torch.full((E,), c.enabled, dtype=torch.bool, device=self.device)  # no camera, no goal view
        elif mode == "auto" and loaded is not None:
            imgs, has = loaded
            if tuple(imgs.shape) != (E, c.height, c.width, 3) or tuple(has.shape) != (E,):
                raise ValueError(f"{where}: goal_images {tuple(imgs.shape)} / has {tuple(has.shape)} do not match "
                                 f"{E} episodes at {c.height}x{c.width}")
        elif mode == "auto" and any(e.extras.get("goal_image") for e in self.episodes):
            raise ValueError(f"{where}: episodes name goal_image files; load them with "
                             "envs.episode_table.load_goal_images and pass goal_images= (NavEnv reads no files)")
        else:
            imgs = torch.zeros(E, c.height, c.width, 3, dtype=torch.uint8)
            has = torch.zeros(E, dtype=torch.bool)
        self._goal_images, self._has_goal_image = imgs.to(self.device), has.to(self.device)

    @property
    def goal_view_mask(self) -> torch.Tensor:
        """bool `[E]`: which episodes have a goal view (read by the image-goal task's checks)."""
        return self._has_goal_image

    def _make_specs(self) -> None:
        self.observation_spec, self.action_spec, self.reward_spec, self.done_spec = nav_env_specs(self)

    def _init_state(self) -> None:
        B, c, dev = self.batch_size[0], self.config.camera, self.device
        T, H, W = c.history, c.height, c.width
        z = lambda *s, dtype=torch.float32: torch.zeros(B, *s, dtype=dtype, device=dev)  # noqa: E731
        self._ep, self._serial, self._steps = z(dtype=torch.long), z(dtype=torch.long), z(dtype=torch.long)
        self._pos, self._yaw = z(3), z()
        self._rgb = z(T, H, W, 3, dtype=torch.uint8) if self.carries_frames else None
        self._depth = z(T, H, W, 1) if c.depth and self.carries_frames else None
        self._pos_hist = z(T, 3)
        self._dist = z()
        self._progress = ProgressState(z(), z(dtype=torch.long), z(dtype=torch.long))
        self._path_len, self._collisions, self._nonfinite = z(), z(dtype=torch.long), z(dtype=torch.long)
        self._nonfinite_warned = False
        self._undefined_steps = z(dtype=torch.long)  # steps whose geodesic distance was undefined
        self._warned_undefined = False
        self._flags = {k: z(dtype=torch.bool) for k in (keys.SUCCESS, keys.INTERVENTION, keys.COLLISION)}
        self._agent_goal_image = z(H, W, 3, dtype=torch.uint8) if self.carries_goal_views else None
        self._agent_has_goal_image = z(1, dtype=torch.bool)
        self._agent_tokens = z(self.config.instruction_length, dtype=torch.long) if self.carries_instruction else None
        self._outcome = {k: z(dtype=torch.bool) for k in (keys.EPISODE_SUCCESS, keys.EPISODE_INTERVENTION)}
        self._started = False

    # ------------------------------------------------------------------ TorchRL API

    def _set_seed(self, seed: int | None) -> None:
        """Seeds the episode sampler and restarts the episode cursor: same seed, same episodes."""
        self._rng = torch.Generator().manual_seed(0 if seed is None else int(seed))
        self._cursor = 0
        self.pedestrians.seed(0 if seed is None else int(seed))

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        B = self.batch_size[0]
        mask = None if tensordict is None else tensordict.get(keys.RESET, None)
        if mask is None or not self._started:
            idx = torch.arange(B, device=self.device)
        else:
            idx = mask.reshape(B).to(self.device).nonzero().flatten()
        self._started = True
        if idx.numel():
            self._start_episodes(idx)
        out = self._observation()
        false = torch.zeros(B, 1, dtype=torch.bool, device=self.device)
        out.update({keys.DONE: false, keys.TERMINATED: false.clone(), keys.TRUNCATED: false.clone()})
        return out

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        t0 = time.perf_counter()
        cfg = self.config
        action = tensordict.get(keys.ACTION).detach().to(self.device, torch.float32)  # a rollout outside no_grad
        plan_xy, plan_yaw = plan_motion(self._pos[:, :2], self._yaw, action, cfg.kinematics)
        nonfinite = ~finite_actions(action)  # [B]: these agents stand still this step (kinematics docs)
        self._count_nonfinite(nonfinite)
        target = torch.cat([plan_xy, self._pos[:, 2:]], -1)  # [B, 3] nav: the surface sets the height
        end, collided = self._move(self._pos, target)
        moved = (end - self._pos).norm(dim=-1)
        moved_xy = (end[:, :2] - self._pos[:, :2]).norm(dim=-1)  # path length is horizontal, as the geodesic (SPL)
        if cfg.termination.check_navigable:
            navigable = self._navigable(end)
        else:
            navigable = torch.ones_like(collided)
        t1 = time.perf_counter()
        d_now = self._step_distance(end)
        steps = self._steps + 1
        progress = update_progress(self._progress, d_now, collided, moved, cfg.termination)
        success, intervention, truncated, cause = terminations(
            d_now, self.table.goal_radius[self._ep], progress, navigable, steps, cfg.termination
        )
        intervention, truncated, cause, penalty = self.pedestrians.step(  # people move; a touch may end the episode
            end, self._pos, wrap_angle(plan_yaw - self._yaw), success, intervention, truncated, cause)
        reward = navigation_reward(self._dist, d_now, success, intervention, cfg.reward) - penalty
        self._pos, self._yaw, self._steps, self._dist, self._progress = end, plan_yaw, steps, d_now, progress
        self._path_len = self._path_len + moved_xy
        self._collisions = self._collisions + collided.long()
        self._flags = {keys.SUCCESS: success, keys.INTERVENTION: intervention, keys.COLLISION: collided}
        t2 = time.perf_counter()
        rgb, depth = (self.camera.render(end, plan_yaw, self._counted(self._serial), extra=self._people())
                      if cfg.camera.enabled and self.carries_frames else (None, None))
        t3 = time.perf_counter()
        self._push_frame(rgb, depth, end)
        terminated = success | intervention
        done = terminated | truncated
        self._outcome = {keys.EPISODE_SUCCESS: success, keys.EPISODE_INTERVENTION: intervention}
        if cfg.finished_records and bool(done.any()):
            self._record_finished(done.nonzero().flatten(), success, intervention, truncated, cause)
        out = self._observation()
        out.update(
            {
                keys.REWARD: reward.unsqueeze(-1),
                keys.DONE: done.unsqueeze(-1),
                keys.TERMINATED: terminated.unsqueeze(-1),
                keys.TRUNCATED: truncated.unsqueeze(-1),
                **(self._episode_metrics() if cfg.episode_metrics else {}),
            }
        )
        t4 = time.perf_counter()
        tm = self.timings
        tm["physics"] += t1 - t0
        tm["rules"] += t2 - t1
        tm["render"] += t3 - t2
        tm["observation"] += t4 - t3
        tm["step"] += t4 - t0
        tm["frames"] += self.batch_size[0]
        return out

    def _people(self, idx: torch.Tensor | None = None):
        """The pedestrians' Gaussians for the cameras of instances idx (all when None); None without people."""
        return self.pedestrians.gaussians(idx, self.device)

    def _count_nonfinite(self, nonfinite: torch.Tensor) -> None:
        """Count NaN/inf actions per agent (reported as `EpisodeMetrics.nonfinite_actions`); warn once."""
        self._nonfinite = self._nonfinite + nonfinite.long()
        if not self._nonfinite_warned and bool(nonfinite.any()):
            self._nonfinite_warned = True
            log.warning("NavEnv: %d of %d agents sent a NaN/inf action; they stand still for the step. Counted "
                        "per episode in the metric nonfinite_actions (a diverged policy?)",
                        int(nonfinite.sum()), nonfinite.numel())

    # ------------------------------------------------------------------ episodes

    def _draw_episodes(self, n: int) -> torch.Tensor:
        """n episode indices: seeded uniform draws, or the next n in order (evaluation)."""
        E = len(self.table)
        if self.config.episode_order == "iterate":
            ep = (self._cursor + torch.arange(n)) % E
        else:
            ep = torch.randint(E, (n,), generator=self._rng)
        return ep.to(self.device)

    def _start_episodes(self, idx: torch.Tensor) -> None:
        """(Re)start the agents `idx [n]` on freshly drawn episodes; out of place for every state tensor."""
        n, T = idx.numel(), self.config.camera.history
        ep = self._draw_episodes(n)
        serial = self._cursor + torch.arange(n, device=self.device)
        self._cursor += n
        pos, yaw = self.table.start_position[ep], self.table.start_yaw[ep]
        self.pedestrians.reset(idx, pos)  # new people for these instances, clear of the new starts
        render = self.carries_frames and self.config.camera.enabled  # switched off later: the history stays
        if render:
            t0 = time.perf_counter()
            rgb, depth = self.camera.render(pos, yaw, self._counted(serial), extra=self._people(idx))
            self.timings["reset_render"] += time.perf_counter() - t0
        d0 = self.shortest_length[ep]
        put = lambda state, new: state.index_copy(0, idx, new.to(state.dtype))  # noqa: E731
        zl = torch.zeros(n, dtype=torch.long, device=self.device)
        self._ep, self._serial, self._steps = put(self._ep, ep), put(self._serial, serial), put(self._steps, zl)
        self._pos, self._yaw, self._dist = put(self._pos, pos), put(self._yaw, yaw), put(self._dist, d0)
        if render:
            self._rgb = put(self._rgb, rgb.unsqueeze(1).expand(n, T, *rgb.shape[1:]))
            if self._depth is not None:
                self._depth = put(self._depth, depth.unsqueeze(1).expand(n, T, *depth.shape[1:]))
        self._pos_hist = put(self._pos_hist, pos.unsqueeze(1).expand(n, T, 3))
        p = self._progress
        self._progress = ProgressState(put(p.best_distance, d0), put(p.steps_without_progress, zl), put(p.stuck_steps, zl))
        self._path_len, self._collisions = put(self._path_len, zl.float()), put(self._collisions, zl)
        self._nonfinite = put(self._nonfinite, zl)
        self._undefined_steps = put(self._undefined_steps, zl)
        self._flags = {k: put(v, zl.bool()) for k, v in self._flags.items()}
        self._outcome = {k: put(v, zl.bool()) for k, v in self._outcome.items()}
        if self.carries_goal_views:
            self._agent_goal_image = put(self._agent_goal_image, self._goal_images[ep])
        self._agent_has_goal_image = put(self._agent_has_goal_image, self._has_goal_image[ep].unsqueeze(-1))
        if self.carries_instruction:
            self._agent_tokens = put(self._agent_tokens, self.table.instruction_tokens[ep])

    def _record_finished(self, idx, success, intervention, truncated, cause) -> None:
        """Stash the metrics of the agents `idx` whose episode just ended (tensors; converted lazily)."""
        ep = self._ep[idx]
        self._finished.append(
            {
                "episode_index": ep,
                "serial": self._serial[idx],
                "ne": (self.table.goal_position[ep] - self._pos[idx]).norm(dim=-1),  # Euclidean, as the paper
                "distance_to_goal": self._dist[idx],  # geodesic
                "nonfinite_actions": self._nonfinite[idx],
                "success": success[idx],
                "intervention": intervention[idx],
                "cause": cause[idx],  # 0 unless an intervention ended it
                "timeout": truncated[idx],
                "path_length": self._path_len[idx],
                "shortest": self.shortest_length[ep],
                "collisions": self._collisions[idx],
                "steps": self._steps[idx],
                "undefined_distance_steps": self._undefined_steps[idx],
                **self.pedestrians.finished_columns(idx),
            }
        )

    def pop_finished_metrics(self) -> list[EpisodeMetrics]:
        """Metrics of every episode that ended since the last call, in the order they ended (kept while
        `NavEnvConfig.finished_records`; a TorchRL user reads `("next", "episode", ...)` at done instead).

        `serial` on each record is the order in which the env *started* that episode since the
        last `set_seed`, which is what the evaluator uses to count each test episode once.
        """
        if not self.config.finished_records:
            raise RuntimeError("NavEnv.pop_finished_metrics: finished_records=false keeps no records; read the "
                               "episode metrics at done, td['next', 'episode', ...] (episode_metrics=true)")
        out = []
        for rec in self._finished:
            cols = {k: v.detach().cpu().tolist() for k, v in rec.items()}
            for j in range(len(cols["serial"])):  # per finished episode, off the step path
                e = cols["episode_index"][j]
                m = EpisodeMetrics(
                    episode_id=self.table.ids[e],
                    episode_index=e,
                    navigation_error=float(cols["ne"][j]),
                    success=bool(cols["success"][j]),
                    spl=spl(bool(cols["success"][j]), cols["shortest"][j], cols["path_length"][j]),
                    intervention=bool(cols["intervention"][j]),
                    intervention_cause=INTERVENTION_CAUSES[cols["cause"][j] - 1] if cols["cause"][j] else "",
                    timeout=bool(cols["timeout"][j]),
                    path_length=float(cols["path_length"][j]),
                    shortest_length=float(cols["shortest"][j]),
                    collisions=int(cols["collisions"][j]),
                    steps=int(cols["steps"][j]),
                    undefined_distance_steps=int(cols["undefined_distance_steps"][j]),
                    environment=self.table.environment[e],
                    serial=int(cols["serial"][j]),
                    distance_to_goal=float(cols["distance_to_goal"][j]),
                    nonfinite_actions=int(cols["nonfinite_actions"][j]),
                )
                self.pedestrians.fill_metrics(m, cols, j)
                out.append(m)
        self._finished = []
        return out

    # ------------------------------------------------------------------ observations

    def _counted(self, serial: torch.Tensor) -> torch.Tensor | None:
        """bool `[n]`: which of the episodes with start serials `serial [n]` are counted (`count_serials`);
        None: all of them."""
        return None if self.count_serials is None else serial < self.count_serials

    def _push_frame(self, rgb: torch.Tensor, depth: torch.Tensor | None, pos: torch.Tensor) -> None:
        if rgb is not None:  # camera off: no frames (or, switched off later, the history stays)
            self._rgb = torch.cat([self._rgb[:, 1:], rgb.unsqueeze(1)], 1)
            if self._depth is not None:
                self._depth = torch.cat([self._depth[:, 1:], depth.unsqueeze(1)], 1)
        self._pos_hist = torch.cat([self._pos_hist[:, 1:], pos.unsqueeze(1)], 1)

    def _observation(self) -> TensorDict:
        """Observation TensorDict `[B]` from the current state (all agents)."""
        B = self.batch_size[0]
        ep, xy, yaw = self._ep, self._pos[:, :2], self._yaw
        past = world_to_body_2d(self._pos_hist[..., :2], xy, yaw)  # [B, T, 2]
        goal = world_to_body_2d(self.table.goal_position[ep, None, :2], xy, yaw)[:, 0]  # [B, 2]
        dyaw = wrap_angle(self.table.goal_yaw[ep] - yaw)
        obs = {
            keys.PAST_POSITIONS: past,
            keys.GOAL_VECTOR: goal,
            keys.GOAL_POSE: torch.cat([goal, torch.cos(dyaw)[:, None], torch.sin(dyaw)[:, None]], -1),
        }
        if self.carries_instruction:
            obs[keys.INSTRUCTION_TOKENS] = self._agent_tokens
        if self._rgb is not None:
            obs[keys.RGB] = self._rgb
            if self.config.pixels:
                obs[keys.PIXELS] = self._rgb[:, -1]
        if self._depth is not None:
            obs[keys.DEPTH] = self._depth
        if self.carries_goal_views:  # per-agent copies, replaced at reset only
            obs.update({keys.GOAL_IMAGE: self._agent_goal_image, keys.HAS_GOAL_IMAGE: self._agent_has_goal_image})
        truth = self._privileged()
        if self.config.privileged:
            obs.update(truth)
        out = TensorDict(obs, batch_size=[B], device=self.device)
        if self.expert is not None:  # the label from the ground truth, which itself may stay out
            out.set(keys.EXPERT_ACTION, self.expert(TensorDict(truth, batch_size=[B])).get(keys.ACTION))
        return out

    def _privileged(self) -> dict:
        """`(PRIVILEGED, name)` -> `[B, ...]`: the simulator's ground truth for experts, labels and logs."""
        return {
            keys.EPISODE_INDEX: self._ep.unsqueeze(-1),
            keys.STEP_COUNT: self._steps.unsqueeze(-1),
            keys.AGENT_POSITION: self._pos,
            keys.AGENT_YAW: self._yaw.unsqueeze(-1),
            keys.DISTANCE_TO_GOAL: self._dist.unsqueeze(-1),
            **{k: v.unsqueeze(-1) for k, v in self._flags.items()},
        }

    def _episode_metrics(self) -> dict:
        """`(EPISODE, name)` -> `[B, 1]`: the running episode's metrics; at done, the finished episode's
        (the same definitions as `EpisodeMetrics`: NE Euclidean, SPL over the exact geodesic)."""
        ep, success = self._ep, self._outcome[keys.EPISODE_SUCCESS]
        shortest = self.shortest_length[ep]
        ne = (self.table.goal_position[ep] - self._pos).norm(dim=-1)
        spl = success.float() * shortest / torch.maximum(self._path_len, shortest).clamp_min(1e-9)
        col = lambda x: x.unsqueeze(-1)  # noqa: E731
        return {keys.EPISODE_SUCCESS: col(success), keys.EPISODE_SPL: col(spl), keys.EPISODE_NAVIGATION_ERROR: col(ne),
                keys.EPISODE_PATH_LENGTH: col(self._path_len), keys.EPISODE_SHORTEST_LENGTH: col(shortest),
                keys.EPISODE_STEPS: col(self._steps), keys.EPISODE_COLLISIONS: col(self._collisions),
                keys.EPISODE_INTERVENTION: col(self._outcome[keys.EPISODE_INTERVENTION]),
                **self.pedestrians.episode_metrics(self._path_len, shortest)}

    # ------------------------------------------------------------------ device and display

    def to(self, device) -> "NavEnv":
        """Specs (TorchRL) and every state tensor, the episode table, the goal views and the camera (its K and
        Gaussians) onto `device`; the navmesh and its distance fields stay on the CPU."""
        if torch.device(device) == self.device:
            return self
        super().to(device)
        return self.move_state(self.device)

    def move_state(self, device: torch.device) -> "NavEnv":
        """The state half of `to`, without TorchRL's specs (which cannot live on `meta`: tests use it here)."""
        for name, value in list(vars(self).items()):
            if name not in ("_input_spec", "_output_spec", "navmesh", "field", "step_field"):
                moved = _moved(value, device)
                if moved is not value:
                    self.__dict__[name] = moved
        self.camera.to(device)
        self.pedestrians.to(device)
        if self.expert is not None:
            self.expert.to(device)
        return self

    def render(self) -> torch.Tensor:
        """The newest camera frame of every agent, uint8 `[B, H, W, 3]` (what `keys.PIXELS` carries)."""
        if self._rgb is None:
            raise RuntimeError("NavEnv.render: the camera is off (camera.enabled=false): no frames")
        return self._rgb[:, -1]

    # ------------------------------------------------------------------ navmesh boundary (scene frame)

    def nav_to_scene(self, p_nav: torch.Tensor) -> torch.Tensor:
        """`[..., 3]` nav frame -> scene frame (row vectors: p_scene = p_nav @ R_ns)."""
        return p_nav.float() @ self._R_ns.to(p_nav.device)

    def scene_to_nav(self, p_scene) -> torch.Tensor:
        p = torch.as_tensor(p_scene, dtype=torch.float32)
        return p @ self._R_ns.T.to(p.device)

    def _move(self, start_nav: torch.Tensor, target_nav: torch.Tensor):
        """Batched navmesh motion: -> end `[B, 3]` nav frame, collided `[B]` bool."""
        end, collided = self.navmesh.move_along_surface(
            self.nav_to_scene(start_nav).cpu(), self.nav_to_scene(target_nav).cpu()
        )
        end_nav = self.scene_to_nav(end).to(self.device)
        return end_nav, torch.as_tensor(collided, dtype=torch.bool).reshape(-1).to(self.device)

    def _navigable(self, p_nav: torch.Tensor) -> torch.Tensor:
        ok = self.navmesh.is_navigable(self.nav_to_scene(p_nav).cpu())
        return torch.as_tensor(ok, dtype=torch.bool).reshape(-1).to(self.device)

    def _shortest_lengths(self, where: str) -> torch.Tensor:
        """Exact geodesic start -> goal `[E]`; an episode whose goal cannot be reached is refused."""
        table = self.table
        d = self.field.lookup(self.nav_to_scene(table.start_position).cpu(), table.goal_index.cpu())
        d = torch.as_tensor(d, dtype=torch.float32).to(self.device)
        bad = torch.nonzero(~torch.isfinite(d)).flatten()
        if bad.numel():
            i = int(bad[0])
            raise ValueError(
                f"{where}: episodes[{i}] (id {table.ids[i]}): goal unreachable from the start on the navmesh "
                f"(start and goal on different islands; {bad.numel()} of {len(table)} episodes are)"
            )
        return d

    def _step_distance(self, p_nav: torch.Tensor) -> torch.Tensor:
        """Geodesic distance `[B]` from the agents' nav-frame positions `[B, 3]` to their goals, per step.

        Where it is undefined (the agent on another island than its goal: a navmesh sliver, a
        motion bug), the rule is: keep the agent's last defined distance, raised to just above its
        goal radius, so the step earns no progress reward and cannot be a success (success needs
        a defined distance within the radius); the step is counted per episode
        (`EpisodeMetrics.undefined_distance_steps`) and warned about once per env.
        """
        d = torch.as_tensor(self.step_field.lookup(self.nav_to_scene(p_nav).cpu(), self.table.goal_index[self._ep].cpu()),
                            dtype=torch.float32).to(self.device)
        undefined = ~torch.isfinite(d)
        if not bool(undefined.any()):
            return d
        self._undefined_steps = self._undefined_steps + undefined.long()
        if not self._warned_undefined:
            self._warned_undefined = True
            i = int(undefined.nonzero()[0, 0])
            warnings.warn(
                f"NavEnv: geodesic distance undefined for {int(undefined.sum())} agent(s) (first: agent {i}, episode "
                f"id {self.table.ids[int(self._ep[i])]}, nav position {[round(v, 3) for v in p_nav[i].tolist()]}); kept "
                f"their last distance, no success possible there; counted in undefined_distance_steps",
                RuntimeWarning,
                stacklevel=3,
            )
        radius = self.table.goal_radius[self._ep]
        keep = torch.maximum(self._dist, torch.nextafter(radius, torch.full_like(radius, float("inf"))))
        return torch.where(undefined, keep, d)

