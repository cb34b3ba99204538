"""`collector=ray`: TorchRL's `RayCollector`, N remote collectors (Ray actors) feeding one learner.

Why TorchRL's and not our own: it already ships the actor placement, the synchronous gather and the
weight broadcast (`update_policy_weights_`), and it runs unchanged on one machine or on a cluster
started with `ray start --head` (then `collector.address=auto`, or `host:6379` from another node).
Each remote collector builds its own env from `env_fn` (its own scenes for a multi-scene env) and
collects `frames_per_batch / num_workers` frames per batch; the batches are concatenated for the learner.

Four things on top of TorchRL's and Ray's defaults:
  * The learner's weights reach every worker before each collection starts: TorchRL 0.14 connects the
    weight sync lazily, on the first `update_policy_weights_`, so without a push the first batch comes from
    the policy as it was pickled when the collector was built (a warm start loaded after that would be
    missed; TorchRL warns "iteration started before weight synchronization was initialized").
  * Worker niceness `worker_niceness` (default 0): Ray renices every worker process to 15 so that the
    driver keeps priority; here the driver (the learner) waits while the workers collect, and on a shared
    machine nice-15 collectors starve behind everyone else's nice-0 processes (seen: 2 collectors still
    building their envs after 18 minutes at load 25). Set through the job's runtime env
    (`RAY_worker_niceness`), so it also holds on a cluster joined with `address=auto`.
  * Weight sync waits `sync_timeout_s` (default 600 s) for the workers: TorchRL 0.14's Ray weight sync
    (Gloo over a TCPStore) hard-codes a 60 s rendezvous (`torchrl.weight_update._ray._DIST_TIMEOUT`), and
    on a loaded machine a worker that is still importing torch misses it (`DistStoreError: wait timeout
    after 60000ms`). `PatientRayWeightSync` sets that constant in every process that holds the scheme
    (the learner, and each worker when the scheme arrives there pickled).
  * Determinism: worker `i` seeds its torch RNG (the policy's action sampling) with `seed`, `i` before it
    builds its env, the envs are seeded by `RayCollector.set_seed` (worker by worker, each from the seed
    the previous one returned), and the synchronous gather concatenates in worker order, so the same seed
    gives the same batches. Not covered: a worker that Ray restarts after a crash, and nodes whose
    hardware computes floats differently.
"""

from __future__ import annotations

from datetime import timedelta
from typing import Callable

import torch
from torchrl.envs import EnvBase
from torchrl.weight_update import RayWeightSyncScheme
from torchrl.weight_update import _ray as torchrl_ray


class PatientRayWeightSync(RayWeightSyncScheme):
    """TorchRL's `RayWeightSyncScheme` with the rendezvous / Gloo timeout set to `timeout_s`."""

    def __init__(self, timeout_s: float):
        super().__init__()
        self.timeout_s = float(timeout_s)
        self._apply_timeout()

    def _apply_timeout(self) -> None:
        torchrl_ray._DIST_TIMEOUT = timedelta(seconds=self.timeout_s)  # read at call time by TorchRL

    def __setstate__(self, state):  # unpickled in a worker: the same timeout there
        super().__setstate__(state)
        self._apply_timeout()


class SeededEnvFn:
    """`env_fn` for one Ray worker: seeds that worker's torch RNG with (`seed`, `worker`) first."""

    def __init__(self, env_fn: Callable[[], EnvBase], seed: int, worker: int):
        self.env_fn, self.seed, self.worker = env_fn, int(seed), int(worker)

    def __call__(self) -> EnvBase:
        torch.manual_seed(self.seed * 1_000_003 + self.worker)
        return self.env_fn()


def _weights_first(collector_class):
    """`collector_class` (TorchRL's `RayCollector`) whose iteration pushes the learner's weights first."""

    class WeightsFirstRayCollector(collector_class):
        def iterator(self):
            self.update_policy_weights_()  # the tracked policy's current weights, to every worker; blocks
            yield from super().iterator()

    return WeightsFirstRayCollector


def make_ray_collector(env_fn: Callable[[], EnvBase], actor, *, frames_per_batch: int, total_frames: int,
                       num_workers: int = 2, seed: int = 0, address: str | None = None, cpus_per_worker: float = 1,
                       memory_per_worker_gb: float | None = None, sync_timeout_s: float = 600.0,
                       worker_niceness: int | None = 0):
    """A synchronous `RayCollector` of `num_workers` single-process collectors; joins `address` or starts
    a local Ray instance with `num_workers * cpus_per_worker` CPUs. Every iteration over it starts with the
    actor's current weights on every worker."""
    try:
        from torchrl.collectors.distributed import RayCollector
        import ray  # noqa: F401
    except ImportError as e:
        raise ImportError("collector=ray needs Ray: pip install -e '.[ray]'") from e
    if frames_per_batch % num_workers:
        raise ValueError(f"collector=ray: algo.ppo.frames_per_batch={frames_per_batch} must be divisible by "
                         f"collector.num_workers={num_workers}")
    init = {"address": address, "ignore_reinit_error": True, "include_dashboard": False, "log_to_driver": False}
    if address is None:
        init["num_cpus"] = max(1, int(num_workers * cpus_per_worker))
    if worker_niceness is not None:  # None: Ray's own (15)
        init["runtime_env"] = {"env_vars": {"RAY_worker_niceness": str(int(worker_niceness))}}
    remote = {"num_cpus": cpus_per_worker}
    if memory_per_worker_gb:
        remote["memory"] = int(memory_per_worker_gb * 1024**3)
    c = _weights_first(RayCollector)([SeededEnvFn(env_fn, seed, i) for i in range(num_workers)], actor,
                     frames_per_batch=frames_per_batch, total_frames=total_frames, sync=True, ray_init_config=init,
                     remote_configs=remote, collector_class="single",
                     collector_kwargs={"split_trajs": False, "auto_register_policy_transforms": False},
                     weight_sync_schemes={"policy": PatientRayWeightSync(sync_timeout_s)})
    c.set_seed(seed)
    return c
