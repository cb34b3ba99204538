"""Sampling and learning at once: a collector thread renders the next batch while the learner updates.

Why: on a 2-core machine the PPO loop alternates two phases that each keep about one core busy (rendering
plus the policy's actions; the update). Running them concurrently, each on ONE intra-op thread, keeps both
cores busy with no OpenMP pool competing for them (torch ops release the GIL; `render/shards.py` renders
the same way). A thread, not a process: the train env (its geodesic rasters, its Gaussians) is built once
and BC's env is reused.

The price is staleness, said and corrected: batch k+1 is collected while update k runs, so by the weights
before update k; the learner then updates from weights one iteration newer than the ones that acted. Every
batch carries the weights version that collected it (`BEHAVIOUR_VERSION`), and `PPOTrainer` uses the
decoupled PPO objective for a stale batch (Hilton et al. 2021, "Batch size-invariance for policy
optimization"): the clip acts on pi_theta / pi_prox with pi_prox the weights at the update's start, and each
sample is weighted by pi_prox / pi_behaviour, so the surrogate is still an importance-weighted estimate for
the data at hand. GAE's advantages stay those of the behaviour data (one iteration old).

The collector acts with its own copy of the actor, loaded from the learner's weights when a batch is
requested: an in-place optimiser step never changes the weights in the middle of a rollout. It samples its
actions itself (`BehaviourActor`) with its own generator: TorchRL's interaction mode and torch's global
generator are process-wide, and the learner's loss switches the mode to deterministic while it runs, which
would make the collector thread act with the mean (and record a log-prob it did not sample from). So a seed
gives the same batches whatever the threads' timing.
"""

from __future__ import annotations

import copy
import queue
import threading

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector

from wanderland_nav import keys as K

BEHAVIOUR_VERSION = "behaviour_version"
"""int64 `[B, T]` in a collected batch: the learner iteration whose weights collected it (`OverlappedCollector`)."""


class BehaviourActor(TensorDictModuleBase):
    """The actor's distribution, always sampled, with its own generator: writes what the `ProbabilisticActor`
    writes (the policy's outputs, `ACTION`, `ACTION_LOG_PROB`) whatever another thread sets as interaction mode.
    The distributions here are Independent Normals (`WaypointNormal`, `TrackedTargetNormal`, whose samples
    leave as K copies)."""

    def __init__(self, actor, seed: int):
        super().__init__()
        self.actor = actor
        self.in_keys, self.out_keys = list(actor.in_keys), list(actor.out_keys)
        self.generator = torch.Generator().manual_seed(seed)

    @torch.no_grad()
    def forward(self, td: TensorDictBase) -> TensorDictBase:
        dist = self.actor.get_dist(td)
        normal = dist.base_dist
        noise = torch.randn(normal.loc.shape, generator=self.generator, dtype=normal.loc.dtype)  # CPU stream, any device
        x = normal.loc + normal.scale * noise.to(normal.loc.device)
        action = dist._copies(x) if hasattr(dist, "_copies") else x
        td.set(K.ACTION, action)
        td.set(K.ACTION_LOG_PROB, dist.log_prob(action))
        return td


class OverlappedCollector:
    """Iterates `[B, T]` batches like a TorchRL collector; the next batch is collected in the background.

    `update_policy_weights_()` (called by the learner after each update) marks the learner's weights as the
    ones to use for the batch after the one being collected; `version` counts those calls.
    """

    def __init__(self, env, actor, *, frames_per_batch: int, total_frames: int, seed: int = 0):
        self.source = actor                              # the learner's actor (its weights are read, never written)
        self.actor = copy.deepcopy(actor)                # the behaviour policy: what acts in the env
        self.actor.requires_grad_(False)
        self.collector = Collector(env, BehaviourActor(self.actor, seed), frames_per_batch=frames_per_batch,
                                   total_frames=total_frames, split_trajs=False, auto_register_policy_transforms=False)
        self.collector.set_seed(seed)
        self.env = self.collector.env
        self.remaining = -(-total_frames // frames_per_batch)
        self.version = 0
        self._weights = self._snapshot()
        self._pending = 0
        self._finished: list = []
        self._requests: queue.Queue = queue.Queue()
        self._results: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._work, name="ppo-collector", daemon=True)
        self._thread.start()
        self._request()

    def _snapshot(self) -> tuple[int, dict]:
        return self.version, {k: v.detach().clone() for k, v in self.source.state_dict().items()}

    def _request(self) -> None:
        if self.remaining > 0:
            self.remaining -= 1
            self._pending += 1
            self._requests.put(self._weights)

    def _work(self) -> None:
        torch.set_num_threads(1)                         # one intra-op thread; the learner has the other core
        batches = iter(self.collector)
        while (job := self._requests.get()) is not None:
            version, weights = job
            try:
                self.actor.load_state_dict(weights)
                batch = next(batches)
                batch.set(BEHAVIOUR_VERSION, torch.full(batch.shape, version, dtype=torch.long))
                finished = self.env.pop_finished_metrics() if hasattr(self.env, "pop_finished_metrics") else []
                self._results.put((batch, finished))
            except BaseException as e:  # noqa: BLE001  handed to the learner, which raises it
                self._results.put(e)
                return

    def __iter__(self):
        while self._pending > 0:
            item = self._results.get()
            self._pending -= 1
            if isinstance(item, BaseException):
                raise RuntimeError("PPO collector thread failed") from item
            batch, self._finished = item
            self._request()                              # the next batch starts now, with the weights last set
            yield batch

    def pop_finished_metrics(self) -> list:
        """The env's records of the episodes that ended in the batch last yielded (popped by the collector
        thread, which owns the env)."""
        out, self._finished = self._finished, []
        return out

    def update_policy_weights_(self) -> None:
        self.version += 1
        self._weights = self._snapshot()

    def shutdown(self) -> None:
        self._requests.put(None)
        self._thread.join(timeout=600)
        self.collector.shutdown()
