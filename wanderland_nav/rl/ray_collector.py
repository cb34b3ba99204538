"""`collector=ray`: TorchRL's `RayCollector`, N remote collectors (Ray actors) feeding one learner.

Why TorchRL's and not our own: it already ships the actor placement, the synchronous gather and the
weight broadcast (`update_policy_weights_`), and it runs unchanged on one machine or on a cluster
started with `ray start --head` (then `collector.address=auto`, or `host:6379` from another node).
Each remote collector builds its own env from `env_fn` (its own scenes for a multi-scene env) and
collects `frames_per_batch / num_workers` frames per batch; the batches are concatenated for the learner.
"""

from __future__ import annotations

from typing import Callable

from torchrl.envs import EnvBase


def make_ray_collector(env_fn: Callable[[], EnvBase], actor, *, frames_per_batch: int, total_frames: int,
                       num_workers: int = 2, seed: int = 0, address: str | None = None, cpus_per_worker: float = 1,
                       memory_per_worker_gb: float | None = None):
    """A synchronous `RayCollector` of `num_workers` single-process collectors; joins `address` or starts
    a local Ray instance with `num_workers * cpus_per_worker` CPUs."""
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
    remote = {"num_cpus": cpus_per_worker}
    if memory_per_worker_gb:
        remote["memory"] = int(memory_per_worker_gb * 1024**3)
    c = RayCollector([env_fn] * num_workers, actor, frames_per_batch=frames_per_batch, total_frames=total_frames,
                     sync=True, ray_init_config=init, remote_configs=remote, collector_class="single",
                     collector_kwargs={"split_trajs": False, "auto_register_policy_transforms": False})
    c.set_seed(seed)
    return c
