"""Training throughput on CPU: frames per second of the PPO learner and actor for each policy.

    python experiments/bench_train.py                       # CNN + CityWalker-style, demo sizes
    python experiments/bench_train.py --policies cnn citywalker nomad mbra --threads 2
    python experiments/bench_train.py --env                 # + end-to-end PPO on the tiny demo (real renderer)

Learner: ClipPPOLoss forward + backward + Adam step over minibatches of synthetic observations with the
demo's shapes (frames/s = transitions consumed per second of update time, per epoch). Actor: the
collector's stochastic forward (transitions/s, batch = the train env's B). `--env` runs `PPOTrainer` on
the real NavEnv (tiny demo, LOD Gaussians) and reports the collector's and the whole loop's frames/s.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch
from tensordict import TensorDict

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.rl.ppo import PPOConfig, PPOTrainer, make_actor

DEMO = {  # conf/policy/*.yaml demo sizes
    "cnn": dict(context=2, image_size=(64, 64), feature_dim=128),
    "citywalker": dict(encoder="cnn", image_size=(32, 32), dim=128, depth=2, heads=4),
    "nomad": dict(image_size=(64, 64), dim=128, depth=2, heads=4, unet_hidden=64, use_goal_vector=True),
    "mbra": dict(image_size=(64, 64), dim=128, depth=2, heads=4),
}


def synthetic(n: int, policy, k: int) -> TensorDict:
    h, w = policy.image_size
    t = policy.context
    g = torch.Generator().manual_seed(0)
    td = TensorDict({
        K.RGB: torch.randint(0, 256, (n, t, h, w, 3), generator=g, dtype=torch.uint8),
        K.PAST_POSITIONS: torch.randn(n, t, 2, generator=g),
        K.GOAL_VECTOR: torch.randn(n, 2, generator=g) * 5,
        K.GOAL_POSE: torch.randn(n, 4, generator=g),
        K.GOAL_IMAGE: torch.randint(0, 256, (n, h, w, 3), generator=g, dtype=torch.uint8),
        K.HAS_GOAL_IMAGE: torch.zeros(n, 1, dtype=torch.bool),
    }, [n])
    return td


def bench_policy(name: str, frames: int, minibatch: int, actor_batch: int) -> dict:
    torch.manual_seed(0)
    policy = make_policy(name, **DEMO[name])
    trainer = PPOTrainer.__new__(PPOTrainer)  # only the loss + optimiser, no env
    PPOTrainer.__init__(trainer, policy, lambda: None, PPOConfig(total_frames=frames, frames_per_batch=frames,
                        minibatch_size=minibatch, epochs=1, target_kl=None, action_dist="waypoints", lr=1e-4,
                        critic_warmup_iters=0, critic_epochs=10, overlap=False), logger=None, progress=False)
    actor = make_actor(policy)
    obs = synthetic(actor_batch, policy, policy.num_waypoints)
    with torch.no_grad():
        actor(obs.clone())
        t0 = time.perf_counter()
        reps = 5
        for _ in range(reps):
            actor(obs.clone())
        actor_fps = reps * actor_batch / (time.perf_counter() - t0)
    data = synthetic(frames, policy, policy.num_waypoints)
    with torch.no_grad():
        data = actor(data)
    data.set(K.STATE_VALUE, torch.zeros(frames, 1))
    data.set("advantage", torch.randn(frames, 1))
    data.set("value_target", torch.randn(frames, 1))
    t0 = time.perf_counter()
    for start in range(0, frames, minibatch):
        mb = data[start:start + minibatch]
        out = trainer.loss(mb)
        loss = out["loss_objective"] + out["loss_critic"]
        trainer.optim.zero_grad()
        loss.backward()
        trainer.optim.step()
    learner_fps = frames / (time.perf_counter() - t0)
    params = sum(p.numel() for p in policy.parameters())
    return {"policy": name, "params_M": params / 1e6, "actor_fps": actor_fps, "learner_fps": learner_fps}


def bench_env(name: str, iterations: int, batch: int, lod_px: float) -> dict:
    from wanderland_nav.compose import env_factory, load_navmesh, scene_gaussians
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.preparation.scene import ensure_demo_scene

    scene = ensure_demo_scene(Path("data/scenes/demo_tiny"), preset="tiny")
    episodes = Path(scene.root) / "episodes.json"
    if not episodes.is_file():
        raise SystemExit(f"{episodes} missing: run `python -m wanderland_nav.train +exp=citywalker_rl` once first")
    policy = make_policy(name, **DEMO[name])
    cfg = NavEnvConfig()
    cfg.camera.height, cfg.camera.width = policy.image_size
    cfg.camera.history = policy.context
    cfg.kinematics.num_waypoints = policy.num_waypoints
    cfg.termination.max_steps = 120
    g = scene_gaussians(scene, lod_px)
    fpb = batch * 25

    class Quiet:
        def __init__(self):
            self.rows = []

        def log_scalars(self, s, step):
            self.rows.append(s)

        def close(self):
            pass

    lg = Quiet()
    env_fn = env_factory(scene, episodes, cfg, split="train", batch_size=batch, seed=0, device="cpu",
                         navmesh=load_navmesh(scene), gaussians=g)
    tr = PPOTrainer(policy, env_fn,
                    PPOConfig(total_frames=fpb * iterations, frames_per_batch=fpb, minibatch_size=fpb // 4, lr=1e-4,
                              critic_warmup_iters=0, critic_epochs=10, overlap=False),
                    logger=lg, progress=False, kinematics=cfg.kinematics)
    tr.train()
    last = lg.rows[-1]
    return {"policy": name, "env_batch": batch, "collect_fps": last["time/collect_fps"], "loop_fps": last["time/fps"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policies", nargs="+", default=["cnn", "citywalker"])
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--minibatch", type=int, default=100)
    ap.add_argument("--actor-batch", type=int, default=8)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--lod-px", type=float, default=2.0,
                    help="the camera's level-of-detail cut in pixels (the main job's: 2)")
    ap.add_argument("--env", action="store_true")
    ap.add_argument("--env-iterations", type=int, default=2)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    print(f"torch {torch.__version__}, {a.threads} threads, frames {a.frames}, minibatch {a.minibatch}")
    print(f"{'policy':<11} {'params(M)':>9} {'actor f/s':>10} {'learner f/s':>12}")
    for name in a.policies:
        r = bench_policy(name, a.frames, a.minibatch, a.actor_batch)
        print(f"{r['policy']:<11} {r['params_M']:>9.2f} {r['actor_fps']:>10.1f} {r['learner_fps']:>12.1f}")
    if a.env:
        print(f"{'policy':<11} {'env B':>6} {'collect f/s':>12} {'loop f/s':>9}")
        for name in a.policies:
            r = bench_env(name, a.env_iterations, a.actor_batch, a.lod_px)
            print(f"{r['policy']:<11} {r['env_batch']:>6} {r['collect_fps']:>12.2f} {r['loop_fps']:>9.2f}")


if __name__ == "__main__":
    main()
