"""`MultiSceneNavEnv`: one TorchRL batch of B agents drawing episodes from many scenes.

Why compose rather than extend `NavEnv`: a `NavEnv` is one scene's navmesh, distance field, episode
table and Gaussians, and its step is a fixed sequence of batched calls over that scene. Many scenes are
therefore many `NavEnv`s: the batch `[B]` is cut into `num_active` equal sub-batches (slots), each slot
bound to one scene's `NavEnv` with `batch_size=[B / num_active]`; a step steps every slot and
concatenates the TensorDicts along the batch (agents `s*b .. (s+1)*b-1` belong to slot `s`).

Rotation schedule (seeded, documented, deterministic): scenes are dealt from a queue that is refilled
with a fresh `randperm` of all scenes (generator seeded by `set_seed`) each time it runs dry, so every
scene is visited once per epoch of the set. A slot takes the next queued scene that no other slot holds
whenever *all* its agents reset at once: on a full `reset()` (every slot), and when a `_reset` mask
covers a slot's whole sub-batch. Agents that reset alone stay in their slot's scene, so an episode never
changes scene half-way. A collector created with `reset_at_each_iter=True` therefore rotates every
batch; otherwise every full reset does. Each newly bound env is seeded with `seed * 1_000_003 + draw`,
so the same seed gives the same scenes and the same episodes.

Per-scene assets are built lazily by `make_scene_env(scene_id, sub_batch, seed)` (a `NavEnv`: navmesh,
distance field, LOD Gaussians, episodes) and held in `SceneLRU`, whose budget counts the bytes of every
tensor and array reachable from the env (`measure_bytes`); the least recently bound scene not in use is
dropped first. Metrics come out per scene (`pop_finished_by_scene`) and are aggregated overall, per scene
and indoor/outdoor (`evaluation.metrics.aggregate_by_scene`); `samples_by_scene` counts the agent-steps taken in each scene.

`global_episodes=True` (behaviour cloning over a set): every scene is built once at construction to read
its episodes (`scene_episodes`, kept; the envs themselves stay under the LRU budget), and the
`episode_index` observation becomes global, `offset[scene] + local index` in `scene_ids` order, so one
table of expert paths (`rl.scene_sets.set_expert_paths`) labels agents of every scene.
"""

from __future__ import annotations

import logging
import types
from collections import OrderedDict
from typing import Callable, Sequence

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import EnvBase

from wanderland_nav import keys
from wanderland_nav.evaluation.metrics import EpisodeMetrics

log = logging.getLogger(__name__)

SCENE_INDEX = "scene_index"  # [B, 1] int64: index into MultiSceneNavEnv.scene_ids of each agent's scene


def measure_bytes(obj) -> int:
    """Bytes of the distinct tensor storages and numpy buffers reachable from `obj` (attributes, dicts,
    lists, tuples), each counted once. What an LRU budget must hold; Python object overhead is ignored."""
    seen_obj, seen_buf, total, stack = set(), set(), 0, [obj]
    while stack:
        o = stack.pop()
        if id(o) in seen_obj or o is None or isinstance(o, (str, bytes, int, float, bool, type)):
            continue
        seen_obj.add(id(o))
        if isinstance(o, torch.Tensor):
            st = o.untyped_storage()
            key = ("t", st.data_ptr(), o.device)
            if key not in seen_buf:
                seen_buf.add(key)
                total += st.nbytes()
        elif isinstance(o, np.ndarray):
            base = o if o.base is None or not isinstance(o.base, np.ndarray) else o.base
            if ("n", id(base)) not in seen_buf:
                seen_buf.add(("n", id(base)))
                total += base.nbytes
        elif isinstance(o, dict):
            stack.extend(o.values())
        elif isinstance(o, (list, tuple, set, frozenset)):
            stack.extend(o)
        elif isinstance(o, types.ModuleType) or (callable(o) and not isinstance(o, torch.nn.Module)):
            continue  # functions, classes, modules: code and globals, not scene data
        elif hasattr(o, "__dict__"):
            stack.extend(vars(o).values())
        elif hasattr(o, "__slots__"):
            stack.extend(getattr(o, s, None) for s in o.__slots__)
    return total


class SceneLRU:
    """Loaded scenes keyed by id, least recently used first, within `budget_bytes` (None: unbounded).

    `get(key, pinned)` loads on a miss and then evicts unpinned scenes, oldest first, until the total
    fits. A scene that alone exceeds the budget is kept while pinned (it is needed) and counted in
    `over_budget` and logged, never dropped silently. `on_evict(key, value)` sees each dropped scene."""

    def __init__(self, load: Callable[[str], object], budget_bytes: int | None = None,
                 on_evict: Callable[[str, object], None] | None = None):
        self.load, self.budget, self.on_evict = load, budget_bytes, on_evict
        self.items: OrderedDict[str, object] = OrderedDict()
        self.sizes: dict[str, int] = {}
        self.stats = {"loads": 0, "hits": 0, "evictions": 0, "over_budget": 0}

    @property
    def total_bytes(self) -> int:
        return sum(self.sizes.values())

    def get(self, key: str, pinned: Sequence[str] = ()):
        if key in self.items:
            self.items.move_to_end(key)
            self.stats["hits"] += 1
            return self.items[key]
        value = self.load(key)
        self.items[key], self.sizes[key] = value, measure_bytes(value)
        self.stats["loads"] += 1
        self._evict(set(pinned) | {key})
        return value

    def _evict(self, keep: set[str]) -> None:
        if self.budget is None:
            return
        for k in [k for k in self.items if k not in keep]:  # oldest first
            if self.total_bytes <= self.budget:
                return
            value = self.items.pop(k)
            self.sizes.pop(k)
            self.stats["evictions"] += 1
            if self.on_evict is not None:
                self.on_evict(k, value)
        if self.total_bytes > self.budget:
            self.stats["over_budget"] += 1
            log.warning("scene cache holds %d bytes for the scenes in use, over its budget of %d bytes",
                        self.total_bytes, self.budget)


class MultiSceneNavEnv(EnvBase):
    """B agents over many scenes: `num_active` slots of `B / num_active` agents, one scene per slot.

    Args:
        scene_ids: the scenes to draw from (e.g. `SceneSet.ids`); at least `num_active` of them.
        make_scene_env: `(scene_id, sub_batch, seed) -> NavEnv`; every scene must give the same specs
            (same `NavEnvConfig`).
        batch_size: `[B]`, B divisible by `num_active`.
        num_active: scenes stepped at once.
        memory_budget_bytes: `SceneLRU` budget for the loaded scenes (None: keep all).
    """

    batch_locked = True

    def __init__(self, scene_ids: Sequence[str], make_scene_env: Callable[[str, int, int], EnvBase],
                 batch_size: Sequence[int] = (2,), num_active: int = 2, *, memory_budget_bytes: int | None = None,
                 seed: int = 0, device: str | torch.device = "cpu", global_episodes: bool = False):
        batch_size = torch.Size(batch_size)
        self.scene_ids = list(scene_ids)
        if len(set(self.scene_ids)) != len(self.scene_ids):
            raise ValueError("MultiSceneNavEnv: scene_ids repeat")
        if not 1 <= num_active <= len(self.scene_ids):
            raise ValueError(f"MultiSceneNavEnv: num_active={num_active} must be in [1, {len(self.scene_ids)}] "
                             f"(the number of scenes)")
        if len(batch_size) != 1 or batch_size[0] % num_active:
            raise ValueError(f"MultiSceneNavEnv: batch_size {list(batch_size)} must be [B] with B divisible by "
                             f"num_active={num_active}")
        super().__init__(device=device, batch_size=batch_size)
        self.num_active, self.sub_batch = int(num_active), int(batch_size[0]) // int(num_active)
        self._make_scene_env = make_scene_env
        self._finished: dict[str, list[EpisodeMetrics]] = {}
        self.cache = SceneLRU(self._load, memory_budget_bytes, on_evict=lambda k, env: self._stash_metrics(k, env))
        self.active: list[str | None] = [None] * self.num_active  # scene id bound to each slot
        self.history: list[tuple[int, str]] = []  # (slot, scene_id) per binding, in order
        self.samples_by_scene: dict[str, int] = dict.fromkeys(self.scene_ids, 0)  # agent-steps per scene
        self.scene_episodes: dict[str, tuple[list, np.ndarray]] = {}  # global_episodes: (episodes, nav_from_scene)
        self._offsets: dict[str, int] | None = None
        if global_episodes:
            self._offsets = {}
            for sid in self.scene_ids:  # in order: the offsets are the running episode counts
                env = self.cache.get(sid)
                self._offsets[sid] = sum(len(eps) for eps, _ in self.scene_episodes.values())
                self.scene_episodes[sid] = (list(env.episodes), np.asarray(env.scene.nav_from_scene))
        self.set_seed(seed)
        self._make_specs(self.cache.get(self.scene_ids[0]))

    # ------------------------------------------------------------------ scenes

    def _load(self, scene_id: str):
        return self._make_scene_env(scene_id, self.sub_batch, 0)

    def _next_scene(self, slot: int) -> str:
        """The next queued scene held by no other slot; the queue is a seeded permutation per epoch."""
        busy = {s for i, s in enumerate(self.active) if i != slot and s is not None}
        for _ in range(2):
            for j, sid in enumerate(self._queue):
                if sid not in busy:
                    return self._queue.pop(j)
            perm = torch.randperm(len(self.scene_ids), generator=self._rng).tolist()
            self._queue += [self.scene_ids[i] for i in perm]
        raise AssertionError("unreachable: num_active <= number of scenes")

    def _bind(self, slot: int) -> EnvBase:
        sid = self._next_scene(slot)
        self.active[slot] = sid
        env = self.cache.get(sid, pinned=[s for s in self.active if s is not None])
        env.set_seed(self._seed * 1_000_003 + self._draws)
        self._draws += 1
        self.history.append((slot, sid))
        return env

    def _env(self, slot: int) -> EnvBase:
        return self.cache.items[self.active[slot]]

    # ------------------------------------------------------------------ specs

    def _make_specs(self, env: EnvBase) -> None:
        B = self.batch_size[0]
        grow = lambda spec: spec[0].expand(B, *spec.shape[1:]).clone()  # noqa: E731  [b, ...] -> [B, ...]
        obs = grow(env.observation_spec)
        obs[SCENE_INDEX] = Unbounded(shape=(B, 1), dtype=torch.int64, device=self.device)
        self.observation_spec = obs
        self.action_spec = grow(env.action_spec)
        self.reward_spec = grow(env.reward_spec)
        self.done_spec = Composite({k: grow(env.done_spec[k]) for k in env.done_spec.keys()}, shape=self.batch_size,
                                   device=self.device)

    # ------------------------------------------------------------------ TorchRL API

    def _set_seed(self, seed: int | None) -> None:
        """Restart the schedule; scenes already bound stay bound (a collector seeds after its first reset)
        and are reseeded, and the next full reset deals from the restarted queue."""
        self._seed = 0 if seed is None else int(seed)
        self._rng = torch.Generator().manual_seed(self._seed)
        self._queue: list[str] = []
        self._draws = 0
        for sid in self.active:
            if sid is not None:
                self.cache.items[sid].set_seed(self._seed * 1_000_003 + self._draws)
                self._draws += 1

    def _slot_scene_index(self) -> torch.Tensor:
        idx = [self.scene_ids.index(s) for s in self.active]
        return torch.tensor(idx, device=self.device).repeat_interleave(self.sub_batch).unsqueeze(-1)

    def _stamp(self, out: TensorDictBase) -> TensorDictBase:
        """Add each agent's scene index (and, with `global_episodes`, make its episode index global)."""
        out.set(SCENE_INDEX, self._slot_scene_index())
        if self._offsets is not None:
            offsets = torch.tensor([self._offsets[s] for s in self.active], device=self.device)
            ep = out.get(keys.EPISODE_INDEX)
            out.set(keys.EPISODE_INDEX, ep + offsets.repeat_interleave(self.sub_batch).view(ep.shape).to(ep.dtype))
        return out

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        mask = None if tensordict is None else tensordict.get(keys.RESET, None)
        b, outs = self.sub_batch, []
        if mask is None:  # a full reset rebinds every slot from the queue
            self.active = [None] * self.num_active
        for slot in range(self.num_active):
            m = None if mask is None else mask.reshape(-1)[slot * b:(slot + 1) * b]
            if self.active[slot] is None or m is None or bool(m.all()):
                env = self._bind(slot)
                outs.append(env._reset(None))  # a fresh binding starts every agent of the slot
            else:
                env = self._env(slot)
                outs.append(env._reset(tensordict[slot * b:(slot + 1) * b]))
        return self._stamp(torch.cat(outs, 0))

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        b = self.sub_batch
        outs = [self._env(s)._step(tensordict[s * b:(s + 1) * b]) for s in range(self.num_active)]
        for sid in self.active:
            self.samples_by_scene[sid] += b
        return self._stamp(torch.cat(outs, 0))

    # ------------------------------------------------------------------ metrics

    def _stash_metrics(self, scene_id: str, env) -> None:
        got = env.pop_finished_metrics()
        if got:
            self._finished.setdefault(scene_id, []).extend(got)

    def pop_finished_by_scene(self) -> dict[str, list[EpisodeMetrics]]:
        """Finished episodes per scene id since the last call (scenes evicted meanwhile included)."""
        for sid, env in self.cache.items.items():
            self._stash_metrics(sid, env)
        out, self._finished = self._finished, {}
        return out

    def pop_finished_metrics(self) -> list[EpisodeMetrics]:
        """All finished episodes (NavEnv's interface, for trainers that aggregate overall)."""
        return [m for ms in self.pop_finished_by_scene().values() for m in ms]
