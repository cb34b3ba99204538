"""PPO over `NavEnv` with TorchRL: a collector, GAE (gamma 0.99), `ClipPPOLoss`, minibatch epochs.

The loop (`PPOTrainer.train`) reads top to bottom like a CleanRL/TorchRL recipe:

    for batch in collector:                       # [B, T] transitions from the current policy
        GAE(batch)                                # advantage + value_target, no grad
        for epoch: for minibatch: ClipPPOLoss -> clip grads -> Adam step
        log train/ losses/ time/ ; checkpoint atomically ; update collector weights

The actor is the policy wrapped in a `ProbabilisticActor`. Its distribution (`action_dist`) is, by default,
a 2-D Normal over the ONE waypoint the env's controller tracks (`rl/tracked_target.py`: the other K-1
waypoints never move the agent, and as action dimensions they are pure noise to PPO); `waypoints` keeps the
older `WaypointNormal` over all `[K, 2]` coordinates (`policies.base`). The critic is its own network (`rl/critic.py`: the policy's
detached readout features + final-goal features + the episode clock, PopArt-normalised targets), fitted
for `critic_epochs` passes per batch on inputs computed once; the policy's `value_head` is not used here.
The actor's learning rate anneals linearly to 0 over `total_frames` (`anneal_lr`, as CleanRL's PPO).

No repeated encoder work: a frame of experience carries `context` camera images and the next frame shares all
but one, so one update encodes each distinct image once (`NavPolicy.reuse_frame_features`; a frozen encoder's
features serve every critic pass, epoch and minibatch, a trained one runs per minibatch on its distinct
images). `overlap=True` collects the next batch in a thread while the update runs (`rl/overlap.py`): one
iteration stale, which the decoupled objective corrects (`_decoupled`).
"""

from __future__ import annotations

import logging
import time
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Callable

import torch
from tensordict import TensorDictBase
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE
from tqdm.auto import tqdm

from policies.base import NavPolicy, WaypointNormal
from wanderland_nav import keys as K
from wanderland_nav.envs.config import KinematicsConfig
from wanderland_nav.errors import NonFiniteLossError
from wanderland_nav.evaluation.metrics import aggregate_metrics
from wanderland_nav.rl.checkpoint import Checkpointer, set_rng_state
from wanderland_nav.rl.critic import NavCritic, explained_variance, fit_critic
from wanderland_nav.rl.loggers import Logger
from wanderland_nav.rl.overlap import BEHAVIOUR_VERSION, OverlappedCollector
from wanderland_nav.rl.tracked_target import TARGET_LOC, TARGET_SCALE, TrackedTargetActor, TrackedTargetNormal

log = logging.getLogger(__name__)

IS_WEIGHT = "importance_weight"
"""float32 `[N, 1]` in a stale batch: pi_prox / pi_behaviour of each sample's action (`PPOTrainer._decoupled`)."""


@dataclass
class PPOConfig:
    """PPO sizes and rates; the defaults are the main job's (the home of each: `conf/algo/ppo.yaml` holds only what
    differs, checked by tests/test_config_defaults.py)."""

    total_frames: int = 44_800         # env steps summed over the batch (the main job's 56 iterations)
    frames_per_batch: int = 800        # per collector iteration (8 agents x 100 steps)
    epochs: int = 4  # passes over each batch
    minibatch_size: int = 200  # samples per gradient step
    lr: float = 5e-5                   # policy (actor) learning rate
    critic_lr: float = 1e-3            # value head: a fresh critic must catch up with a pretrained actor
    gamma: float = 0.99                # the paper's
    lmbda: float = 0.95  # GAE lambda
    clip_epsilon: float = 0.2  # PPO's ratio clip
    entropy_coeff: float = 0.0  # entropy bonus weight
    max_grad_norm: float = 0.5  # gradient-norm clip
    normalize_advantage: bool = True  # advantages standardised per minibatch
    target_kl: float | None = 0.05     # stop the epochs of one batch early beyond this approx KL
    critic_warmup_iters: int = 2       # first iterations update only the critic (see PPOTrainer.update)
    critic_epochs: int = 8             # passes of the critic over each batch (cached inputs: cheap)
    critic_hidden: int = 256  # width of the critic's MLP
    critic_horizon: float = 100.0      # the critic's clock input is step_count / this (a scale, not a limit)
    anneal_lr: bool = True             # actor lr: linear to 0 over total_frames
    init_std: float | None = None      # exploration std (m) PPO starts from; None: the policy's own (BC keeps
                                       #   the policy config's init_std: BC does not train it)
    std_lr: float | None = None        # the exploration std's own Adam lr; None: the actor's `lr`
    action_dist: str = "tracked"       # "tracked": Normal over the executed (tracked) waypoint, 2 dims
                                       #   (rl/tracked_target.py); "waypoints": Normal over all K*2 coordinates
    overlap: bool = True               # collect the next batch while updating (rl/overlap.py): one iteration
                                       #   stale, corrected by the decoupled objective; one process, 2 threads

    @property
    def num_iterations(self) -> int:
        """Collector iterations that actually run: TorchRL rounds total_frames UP to a multiple of
        frames_per_batch. `num_iterations - critic_warmup_iters` of them update the policy."""
        return -(-self.total_frames // self.frames_per_batch)

    def __post_init__(self):
        if self.frames_per_batch <= 0 or self.total_frames < self.frames_per_batch:
            raise ValueError(f"PPO: need 0 < frames_per_batch ({self.frames_per_batch}) <= total_frames "
                             f"({self.total_frames})")
        if not 0 < self.minibatch_size <= self.frames_per_batch:
            raise ValueError(f"PPO: minibatch_size={self.minibatch_size} must be in (0, frames_per_batch]")
        if self.action_dist not in ("tracked", "waypoints"):
            raise ValueError(f"PPO: action_dist='{self.action_dist}' must be 'tracked' or 'waypoints'")
        iterations = self.num_iterations
        if iterations <= self.critic_warmup_iters:  # the "RL" row would silently be the initial policy
            raise ValueError(
                f"PPO: total_frames={self.total_frames} / frames_per_batch={self.frames_per_batch} rounded up = "
                f"{iterations} iteration(s) <= critic_warmup_iters={self.critic_warmup_iters}: every iteration only trains the "
                f"critic and the policy is never updated. Raise total_frames above frames_per_batch * "
                f"critic_warmup_iters = {self.frames_per_batch * self.critic_warmup_iters} or lower critic_warmup_iters")


def make_actor(policy: NavPolicy, kinematics: KinematicsConfig | None = None,
               init_std: float | None = None) -> ProbabilisticActor:
    """Policy -> stochastic actor writing `ACTION` and `ACTION_LOG_PROB` (used by the collector and loss).

    With `kinematics` (the env's): the tracked-target distribution (`rl/tracked_target.py`), its std from
    `init_std` (None: the policy's); without: `WaypointNormal` over all K waypoints (std: the policy's)."""
    if kinematics is not None:
        return ProbabilisticActor(
            module=TrackedTargetActor(policy, kinematics, init_std),
            in_keys={"loc": TARGET_LOC, "scale": TARGET_SCALE},
            out_keys=[K.ACTION],
            distribution_class=TrackedTargetNormal,
            distribution_kwargs={"num_waypoints": policy.num_waypoints},
            return_log_prob=True,
            log_prob_key=K.ACTION_LOG_PROB,
        )
    if init_std is not None:
        policy.set_std(init_std)
    return ProbabilisticActor(
        module=policy,
        in_keys={"loc": K.LOC, "scale": K.SCALE},
        out_keys=[K.ACTION],
        distribution_class=WaypointNormal,
        return_log_prob=True,
        log_prob_key=K.ACTION_LOG_PROB,
    )


def make_collector(env_fn: Callable[[], EnvBase], actor, *, frames_per_batch: int, total_frames: int,
                   num_workers: int = 1, seed: int = 0, ray: dict | None = None):
    """One process (`Collector`; `env_fn` may then be an env already built, e.g. BC's) or `num_workers`
    synchronous processes (`MultiSyncCollector`, `env_fn` a picklable factory); with `ray`
    (the `collector=ray` options) `num_workers` Ray actors (`wanderland_nav.rl.ray_collector`)."""
    if ray is not None:
        from wanderland_nav.rl.ray_collector import make_ray_collector

        return make_ray_collector(env_fn, actor, frames_per_batch=frames_per_batch, total_frames=total_frames,
                                  num_workers=num_workers, seed=seed, **ray)
    if num_workers <= 1:
        c = Collector(env_fn, actor, frames_per_batch=frames_per_batch, total_frames=total_frames,
                      split_trajs=False, auto_register_policy_transforms=False)  # stateless policy: no InitTracker
    else:
        c = MultiSyncCollector([env_fn] * num_workers, actor, frames_per_batch=frames_per_batch,
                               total_frames=total_frames, split_trajs=False)
    c.set_seed(seed)
    return c


def env_episode_metrics(collector) -> dict[str, float]:
    """NE / SR / SPL / IR of the episodes the collector's env finished (single-process collector and an env
    with `pop_finished_metrics`, i.e. NavEnv, or the overlapped collector, which pops them in its own thread).
    Popping also keeps the env's record list from growing."""
    env = collector if hasattr(collector, "pop_finished_metrics") else getattr(collector, "env", None)
    if env is None or not hasattr(env, "pop_finished_metrics"):
        return {}
    finished = env.pop_finished_metrics()
    if not finished:
        return {}
    o = aggregate_metrics(finished)["overall"]
    return {"train/episodes": o["episodes"],
            **{f"train/{k}": o[k] for k in ("NE", "distance_to_goal", "SR", "SPL", "IR", "nonfinite_actions")}}


def episode_stats(batch: TensorDictBase) -> dict[str, float]:
    """SR / IR / distance_to_goal / return over the episodes that ended inside a collected batch `[..., T]`."""
    nxt = batch.get("next")
    done = nxt.get(K.DONE).squeeze(-1)
    out = {"train/reward_mean": float(nxt.get(K.REWARD).mean())}
    n = int(done.sum())
    out["train/episodes"] = n
    if n:
        if K.SUCCESS in nxt.keys(True):
            out["train/SR"] = float(nxt.get(K.SUCCESS).squeeze(-1)[done].float().mean())
        if K.INTERVENTION in nxt.keys(True):
            out["train/IR"] = float(nxt.get(K.INTERVENTION).squeeze(-1)[done].float().mean())
        if K.DISTANCE_TO_GOAL in nxt.keys(True):  # the env's distance (geodesic in NavEnv): not the paper's NE
            out["train/distance_to_goal"] = float(nxt.get(K.DISTANCE_TO_GOAL).squeeze(-1)[done].mean())
    return out


class PPOTrainer:
    """Owns the actor, critic, loss, optimiser and the loop; resumes from `checkpointer.last`."""

    def __init__(self, policy: NavPolicy, env_fn: Callable[[], EnvBase] | EnvBase, cfg: PPOConfig, *,
                 logger: Logger, checkpointer: Checkpointer | None = None, num_workers: int = 1,
                 seed: int = 0, config_dict: dict | None = None, progress: bool = True, ray: dict | None = None,
                 kinematics: KinematicsConfig | None = None, card: dict | None = None):
        """`kinematics`: the env's (`env.kinematics`), required by `action_dist=tracked`: the tracked waypoint
        must be chosen by the env's own rule and thresholds."""
        if cfg.action_dist == "tracked" and kinematics is None:
            raise ValueError("PPO: algo.ppo.action_dist=tracked needs the env's kinematics config "
                             "(PPOTrainer(kinematics=env_cfg.kinematics)) or algo.ppo.action_dist=waypoints")
        self.policy, self.env_fn, self.cfg = policy, env_fn, cfg
        self.ray = ray  # collector=ray options (address, cpus_per_worker, ...); None: local collectors
        self.logger, self.checkpointer = logger, checkpointer
        self.num_workers, self.seed, self.config_dict, self.progress = num_workers, seed, config_dict, progress
        self.card = card  # the policy card saved beside the weights (compose.checkpoints)
        if policy.config.freeze_encoder != "never":  # "rl" (the paper: update only the policy) or "always"
            policy.freeze_encoders(True)
        self.actor = make_actor(policy, kinematics if cfg.action_dist == "tracked" else None, cfg.init_std)
        # the exploration std PPO trains: the tracked target's own [2], or the policy's [K, 2]
        self.std_owner = self.actor.module[0] if cfg.action_dist == "tracked" else policy
        self.critic = NavCritic(policy, hidden=cfg.critic_hidden, horizon=cfg.critic_horizon)
        self.loss = ClipPPOLoss(self.actor, None, clip_epsilon=cfg.clip_epsilon,  # actor only: see rl/critic.py
                                entropy_bonus=cfg.entropy_coeff > 0, entropy_coeff=cfg.entropy_coeff,
                                critic_coeff=None, normalize_advantage=cfg.normalize_advantage)
        # a stale batch (overlap): the same objective on standardised, importance-weighted advantages
        self.decoupled_loss = ClipPPOLoss(self.actor, None, clip_epsilon=cfg.clip_epsilon,
                                          entropy_bonus=cfg.entropy_coeff > 0, entropy_coeff=cfg.entropy_coeff,
                                          critic_coeff=None, normalize_advantage=False)
        for loss in (self.loss, self.decoupled_loss):
            loss.set_keys(action=K.ACTION, sample_log_prob=K.ACTION_LOG_PROB, value=K.STATE_VALUE,
                          reward=K.REWARD, done=K.DONE, terminated=K.TERMINATED)
        # the learner's own random stream (minibatch permutations): the global one is the collector's
        self.generator = torch.Generator().manual_seed(seed)
        self.gae = GAE(gamma=cfg.gamma, lmbda=cfg.lmbda, value_network=None, average_gae=False)  # values given
        self.gae.set_keys(value=K.STATE_VALUE, reward=K.REWARD, done=K.DONE, terminated=K.TERMINATED)
        # init_std was applied by make_actor; a resumed run's checkpoint (restore) overwrites it again
        skip = {id(p) for p in policy.value_head.parameters()} | {id(policy.std_param)}  # head: not PPO's critic
        groups = [{"params": [p for p in policy.trainable_parameters() if id(p) not in skip], "lr": cfg.lr},
                  {"params": [self.std_owner.std_param], "lr": cfg.lr if cfg.std_lr is None else cfg.std_lr}]
        self.optim = torch.optim.Adam(groups)
        self.base_lrs = [g["lr"] for g in groups]
        self.critic_optim = torch.optim.Adam(self.critic.parameters(), lr=cfg.critic_lr)
        self.iteration, self.frames = 0, 0

    # -------------------------------------------------------------- checkpoints
    def state_counters(self) -> dict[str, int]:
        return {"ppo_iteration": self.iteration, "ppo_frames": self.frames}

    def save(self, phase: str = "ppo") -> None:
        if self.checkpointer is not None:
            critic = {"critic": self.critic.state_dict(), "critic_optimizer": self.critic_optim.state_dict(),
                      "action_std_param": self.std_owner.std_param.detach().clone(),
                      "learner_rng": self.generator.get_state()}
            self.checkpointer.save(self.iteration, policy=self.policy, optimizer=self.optim,
                                   counters=self.state_counters(), config=self.config_dict, card=self.card,
                                   phase=phase, extra=critic)

    def restore(self, ckpt: dict) -> None:
        self.policy.load_state_dict(ckpt["policy"])
        if ckpt.get("optimizer") is not None and ckpt.get("phase") in ("ppo", "ppo_done"):
            self.optim.load_state_dict(ckpt["optimizer"])
            extra = ckpt.get("extra") or {}
            if "critic" in extra:
                self.critic.load_state_dict(extra["critic"])
                self.critic_optim.load_state_dict(extra["critic_optimizer"])
            if "learner_rng" in extra:
                self.generator.set_state(extra["learner_rng"])
            if "action_std_param" in extra:  # same identity -> same action_dist -> same shape
                with torch.no_grad():
                    self.std_owner.std_param.copy_(extra["action_std_param"])
        self.iteration = int(ckpt["counters"].get("ppo_iteration", 0))
        self.frames = int(ckpt["counters"].get("ppo_frames", 0))
        if ckpt.get("rng") is not None:
            set_rng_state(ckpt["rng"])

    # -------------------------------------------------------------- one update
    def update(self, batch: TensorDictBase, stale: bool = False) -> dict[str, float]:
        """Critic values -> GAE -> actor epochs (ClipPPOLoss, target-KL stop) -> critic epochs. During the first
        `critic_warmup_iters` iterations the actor is left alone: a fresh critic gives near-random advantages,
        and policy-gradient steps on them would move a behaviour-cloned policy away from its demonstrations.
        `stale`: the batch was collected by older weights than the actor's (`rl/overlap.py`): the decoupled
        objective (`_decoupled`) is used."""
        with self._shared_frame_features(batch):
            return self._update(batch, stale)

    def _shared_frame_features(self, batch: TensorDictBase):
        """The batch's camera images encoded once for the whole update (`NavPolicy.reuse_frame_features`): each
        frame of `[B, T]` carries `context` images and the next frame shares all but one of them, and a frozen
        encoder (`freeze_encoder=rl`) gives the same features in every critic pass, epoch and minibatch. A
        trained encoder still runs per minibatch (on its distinct images), so the gradients are unchanged."""
        if K.RGB not in self.policy.in_keys:
            return nullcontext()
        return self.policy.reuse_frame_features(batch.get(K.RGB), batch.get(("next", K.RGB)))

    def _update(self, batch: TensorDictBase, stale: bool) -> dict[str, float]:
        cfg = self.cfg
        warmup = self.iteration < cfg.critic_warmup_iters
        batch = batch.exclude(K.STATE_VALUE)  # the policy's own value head wrote one: PPO's critic replaces it
        x, x_next = self.critic.inputs(batch), self.critic.inputs(batch.get("next"))  # [B, T, F], trunk once
        with torch.no_grad():
            batch.set(K.STATE_VALUE, self.critic(x))
            batch.get("next").set(K.STATE_VALUE, self.critic(x_next))
            self.gae(batch)
        flat = batch.reshape(-1)
        adv, target, value = flat.get("advantage"), flat.get("value_target"), flat.get(K.STATE_VALUE)
        self._check_finite({"advantage": adv, "value_target": target}, ("advantage", "value_target"), 0, 0)
        res = {"losses/explained_variance": explained_variance(value, target),  # of the critic that made the GAE
               "losses/advantage_mean": float(adv.mean()), "losses/advantage_std": float(adv.std()),
               "losses/value_target_mean": float(target.mean()), "losses/critic_warmup": float(warmup)}
        if cfg.anneal_lr:
            for group, lr in zip(self.optim.param_groups, self.base_lrs):
                group["lr"] = lr * max(0.0, 1.0 - self.frames / cfg.total_frames)
        res["losses/lr"] = self.optim.param_groups[0]["lr"]
        if not warmup:
            if stale:
                res.update(self._decoupled(flat))
            res.update(self._actor_epochs(flat, stale))
        xf = x.reshape(-1, x.shape[-1])
        res["losses/critic"] = fit_critic(self.critic, self.critic_optim, xf, target, epochs=cfg.critic_epochs,
                                          minibatch_size=cfg.minibatch_size, max_grad_norm=cfg.max_grad_norm,
                                          generator=self.generator)
        with torch.no_grad():
            res["losses/explained_variance_after_fit"] = explained_variance(self.critic(xf), target)
        res["losses/std_mean"] = float(self.std_owner.scale().detach().mean())
        return res

    @torch.no_grad()
    def _decoupled(self, flat: TensorDictBase) -> dict[str, float]:
        """A stale batch -> decoupled PPO's inputs (Hilton et al. 2021): the proximal policy is the actor now
        (the update's start), whose log-prob replaces the behaviour's as the clip's reference, and each sample's
        importance weight pi_prox / pi_behaviour (`IS_WEIGHT`) multiplies its standardised advantage. With
        w > 0, w * min(r A, clip(r) A) is exactly the decoupled surrogate."""
        behaviour = flat.get(K.ACTION_LOG_PROB)
        prox = self.actor.get_dist(flat.select(*self.actor.in_keys).clone()).log_prob(flat.get(K.ACTION))
        weight = (prox - behaviour).exp()
        flat.set(K.ACTION_LOG_PROB, prox.reshape(behaviour.shape))
        flat.set(IS_WEIGHT, weight.reshape(-1, 1))
        return {"losses/is_weight_mean": float(weight.mean()), "losses/is_weight_max": float(weight.max()),
                "losses/behaviour_kl": float((behaviour - prox).mean())}

    def _actor_epochs(self, flat: TensorDictBase, stale: bool = False) -> dict[str, float]:
        """Minibatch epochs of the clipped objective (+ entropy); stop the batch beyond `target_kl`. `stale`:
        `flat` holds `_decoupled`'s inputs, and the advantage is standardised per minibatch as the on-policy
        loss does, then weighted."""
        cfg = self.cfg
        n, sums, count, epoch = flat.shape[0], {}, 0, 0
        for epoch in range(cfg.epochs):
            perm = torch.randperm(n, generator=self.generator)
            for start in range(0, n - cfg.minibatch_size + 1, cfg.minibatch_size):
                mb = flat[perm[start:start + cfg.minibatch_size]]
                if stale:
                    adv = mb.get("advantage")
                    if cfg.normalize_advantage:
                        adv = (adv - adv.mean()) / adv.std().clamp_min(torch.finfo(adv.dtype).resolution)
                    mb.set("advantage", adv * mb.get(IS_WEIGHT))
                out = (self.decoupled_loss if stale else self.loss)(mb)
                terms = [t for t in ("loss_objective", "loss_entropy") if t in out.keys()]
                self._check_finite(out, terms, epoch, start // cfg.minibatch_size)
                self.optim.zero_grad(set_to_none=True)
                sum(out[t] for t in terms).backward()
                gn = torch.nn.utils.clip_grad_norm_(self.policy.trainable_parameters(), cfg.max_grad_norm)
                self._check_finite({"grad_norm": gn}, ("grad_norm",), epoch, start // cfg.minibatch_size)
                self.optim.step()
                stats = {"losses/objective": out["loss_objective"], "losses/approx_kl": out["kl_approx"],
                         "losses/clipfrac": out["clip_fraction"], "losses/grad_norm": gn}
                if "entropy" in out.keys():
                    stats["losses/entropy"] = out["entropy"]
                for k, v in stats.items():
                    sums[k] = sums.get(k, 0.0) + float(torch.as_tensor(v).detach().float().mean())
                count += 1
                if cfg.target_kl is not None and float(out["kl_approx"].detach().abs().mean()) > cfg.target_kl:
                    return {**{k: v / count for k, v in sums.items()}, "losses/epochs_done": epoch + 1}
        return {**{k: v / max(count, 1) for k, v in sums.items()}, "losses/epochs_done": epoch + 1}

    def _check_finite(self, values, names, epoch: int, minibatch: int) -> None:
        """Stop before a non-finite loss or gradient reaches the weights: the optimiser has not stepped,
        and `last.pt` still holds the previous iteration's (finite) state."""
        bad = {n: float(torch.as_tensor(values[n]).detach().float().mean()) for n in names
               if n in values.keys() and not bool(torch.isfinite(torch.as_tensor(values[n])).all())}
        if bad:
            last = self.checkpointer.last if self.checkpointer is not None else None
            kept = (f"the last good checkpoint {last} (iteration {self.iteration}) is intact"
                    if last is not None and last.is_file() else "no checkpoint was written yet")
            raise NonFiniteLossError(
                f"PPO diverged at iteration {self.iteration + 1} (epoch {epoch}, minibatch {minibatch}): "
                f"non-finite {', '.join(f'{n}={v}' for n, v in bad.items())}; {kept}. Lower algo.ppo.lr / "
                f"critic_lr or max_grad_norm, or look for NaN rewards or observations")

    # -------------------------------------------------------------- the loop
    def overlaps(self) -> bool:
        """Whether this run collects during the update (`overlap`): with one local collector. Worker processes
        or Ray actors (`collector=multi|ray`) already collect beside the learner's process and keep their
        synchronous batches; that is said in the log."""
        if not self.cfg.overlap:
            return False
        if self.num_workers > 1 or self.ray is not None:
            log.warning("PPO: algo.ppo.overlap=true applies to collector=single; with %s the batches are collected "
                        "synchronously (on-policy) by the worker processes", "Ray" if self.ray else
                        f"{self.num_workers} collector workers")
            return False
        return True

    def train(self) -> dict[str, float]:
        cfg = self.cfg
        remaining = cfg.total_frames - self.frames
        if remaining < cfg.frames_per_batch:
            log.info("PPO already complete (%d/%d frames)", self.frames, cfg.total_frames)
            return {}
        seed = self.seed + 1000 * self.iteration
        if self.overlaps():
            collector = OverlappedCollector(self.env_fn, self.actor, frames_per_batch=cfg.frames_per_batch,
                                            total_frames=remaining, seed=seed)
            threads = torch.get_num_threads()
            torch.set_num_threads(1)  # the learner's one intra-op thread; the collector thread has the other core
        else:
            collector = make_collector(self.env_fn, self.actor, frames_per_batch=cfg.frames_per_batch,
                                       total_frames=remaining, num_workers=self.num_workers, seed=seed, ray=self.ray)
        pbar = tqdm(total=cfg.total_frames, initial=self.frames, desc="PPO", unit="f", disable=not self.progress,
                    dynamic_ncols=True)
        last: dict[str, float] = {}
        t_collect = time.perf_counter()
        try:
            for batch in collector:
                dt_collect = time.perf_counter() - t_collect
                t0 = time.perf_counter()
                self.policy.train()
                stats = episode_stats(batch)
                stats.update(env_episode_metrics(collector))   # adds SPL where the env can say
                stale = BEHAVIOUR_VERSION in batch.keys() and int(batch.get(BEHAVIOUR_VERSION).min()) < collector.version
                stats.update(self.update(batch.exclude(BEHAVIOUR_VERSION), stale=stale))
                dt_update = time.perf_counter() - t0
                self.frames += batch.numel()
                self.iteration += 1
                collector.update_policy_weights_()
                stats.update({"time/collect_s": dt_collect, "time/update_s": dt_update,
                              "time/fps": batch.numel() / max(dt_collect + dt_update, 1e-9),
                              "time/collect_fps": batch.numel() / max(dt_collect, 1e-9),
                              "train/frames": self.frames, "train/iteration": self.iteration})
                self.logger.log_scalars(stats, self.frames)
                self.logger.log_rollout(batch, self.frames, tag="train")   # [B, T] transitions
                self.save("ppo" if self.frames + cfg.frames_per_batch <= cfg.total_frames else "ppo_done")
                pbar.update(batch.numel())
                pbar.set_postfix({k.split("/")[1]: f"{stats[k]:.3g}" for k in
                                  ("train/SR", "train/reward_mean", "losses/approx_kl", "time/fps") if k in stats})
                last = stats
                t_collect = time.perf_counter()
        finally:
            pbar.close()
            collector.shutdown()
            if isinstance(collector, OverlappedCollector):
                torch.set_num_threads(threads)
        return last
