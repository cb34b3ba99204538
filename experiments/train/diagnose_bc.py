"""Why does behaviour cloning not fit the expert? Measures, on the tiny demo scene, each link of the chain.

    PYTHONPATH=$PWD python experiments/train/diagnose_bc.py --samples 2400 --updates 1500 --threads 1

1. the expert itself, executed through the env's kinematics (`ExpertActor`, no noise): its SR bounds BC;
2. a "goal-straight" policy (waypoints along the goal vector): what the observation's goal alone gives;
3. how often the expert's next waypoint is NOT toward the goal (the detour share): on those states the
   label depends on the route around buildings, which the observation must reveal (32 px images, 5 past
   positions) or nothing can predict it;
4. fits of the CityWalker-style policy on expert data (noisy-expert rollouts, train split), held-out by
   episode: with images, blind (images zeroed), and an overfit check on 64 samples (can it fit at all?);
   held-out L1 per waypoint horizon and split by detour / no detour;
5. test-split SR of the image fit;
6. the privileged-route oracle: the same model and data, but the goal input is the expert route's point
   `--lookahead` metres ahead (what CityWalker's GPS route waypoints give it) instead of the final goal:
   if this fits and succeeds where (4-5) do not, the expert's labels are not a function of the
   point-goal observation, and no amount of data or capacity fixes BC.

Prints one block of figures; every number is measured in this run.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import torch
import yaml
from tensordict import TensorDict

from policies import make_policy
from wanderland_nav import keys as K
from wanderland_nav.evaluation.loop import run_evaluation
from wanderland_nav.envs.factory import make_nav_env
from wanderland_nav.pipeline import ensure_demo_scene
from wanderland_nav.rl.bc import ExpertActor, ExpertPaths, collect
from wanderland_nav.rl.policy_env import PolicyActor, lod_gaussians, shaped_env_config
from wanderland_nav.rl.route_goal import RouteGoal

ROOT = Path(__file__).resolve().parents[2]
TERMINATION = {"max_steps": 100, "no_progress_steps": 30, "stuck_steps": 10}  # conf/train.yaml's demo env


class GoalStraight(torch.nn.Module):
    """Waypoints on the straight line to the goal, `spacing` apart (never past the goal)."""

    def __init__(self, k: int, spacing: float):
        super().__init__()
        self.k, self.spacing = k, spacing

    def forward(self, td):
        g = td.get(K.GOAL_VECTOR)                                             # [B, 2] body frame
        d = g.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        s = torch.arange(1, self.k + 1, dtype=g.dtype) * self.spacing        # [K]
        td.set(K.ACTION, (g / d)[:, None] * torch.minimum(s[None], d)[..., None])
        return td


class WithRouteGoal(torch.nn.Module):
    """The library's `RouteGoal` transform applied to the observation before `inner` acts (evaluation only)."""

    def __init__(self, paths: ExpertPaths, lookahead: float, inner):
        super().__init__()
        self.route, self.inner = RouteGoal(paths, lookahead), inner

    def forward(self, td):
        return self.inner(self.route._call(td))


def bearing_deg(xy: torch.Tensor) -> torch.Tensor:
    return torch.rad2deg(torch.atan2(xy[..., 1], xy[..., 0]))


def env_pair(policy, scene, episodes, threads_seed: int):
    cfg = shaped_env_config({"termination": TERMINATION}, policy)
    g = lod_gaussians(scene.gaussians_path, 10_000)
    kw = dict(config=cfg, episodes_path=episodes, seed=threads_seed, gaussians=g)
    return (make_nav_env(scene, batch_size=8, split="train", **kw),
            make_nav_env(scene, batch_size=10, split="test", **kw))


def fit(policy, data: TensorDict, labels: torch.Tensor, updates: int, seed: int, lr: float = 3e-4):
    """Minibatch AdamW on (data, labels); -> mean train L1 over the last 10 % of updates."""
    g = torch.Generator().manual_seed(seed)
    opt = torch.optim.AdamW(policy.trainable_parameters(), lr=lr, weight_decay=1e-4)
    policy.train()
    tail = []
    for u in range(updates):
        idx = torch.randint(0, data.shape[0], (min(64, data.shape[0]),), generator=g)
        loss, m = policy.bc_loss(data[idx], labels[idx])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.trainable_parameters(), 1.0)
        opt.step()
        if u >= 0.9 * updates:
            tail.append(m["waypoint_l1"])
    policy.eval()
    return sum(tail) / max(len(tail), 1)


@torch.no_grad()
def held_out_error(policy, data: TensorDict, labels: torch.Tensor, detour: torch.Tensor) -> dict:
    """L1 (m) per horizon k and on detour / straight states."""
    pred = torch.cat([policy(data[i:i + 256].clone()).get(K.WAYPOINTS) for i in range(0, data.shape[0], 256)])
    err = (pred - labels).abs().mean(-1)                                  # [N, K]
    return {"per_k": [round(float(e), 3) for e in err.mean(0)], "all": float(err.mean()),
            "detour": float(err[detour].mean()) if detour.any() else float("nan"),
            "straight": float(err[~detour].mean()) if (~detour).any() else float("nan")}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=2400, help="expert-rollout samples (train split)")
    ap.add_argument("--updates", type=int, default=1500)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--detour-deg", type=float, default=30.0)
    ap.add_argument("--skip-baselines", action="store_true", help="skip (1-2), the two non-learned evaluations")
    ap.add_argument("--lookahead", type=float, default=3.0, help="metres ahead on the route for the oracle (6)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    t0 = time.perf_counter()
    scene = ensure_demo_scene(ROOT / "data/scenes/demo_tiny", preset="tiny")
    episodes = Path(scene.root) / "episodes.json"
    pcfg = yaml.safe_load((ROOT / "conf/policy/citywalker.yaml").read_text())
    name = pcfg.pop("name")
    policy = make_policy(name, **pcfg)
    train_env, test_env = env_pair(policy, scene, episodes, a.seed)
    k, sp = policy.num_waypoints, float(policy.waypoint_spacing)

    test_paths = ExpertPaths.from_episodes(test_env.episodes, scene.nav_from_scene)
    baselines = (("expert (no noise)", ExpertActor(test_paths, k, sp)), ("goal-straight", GoalStraight(k, sp)))
    for label, actor in baselines[:0] if a.skip_baselines else baselines:
        o = run_evaluation(test_env, actor, seed=a.seed, name=label).summary["overall"]
        print(f"[1-2] {label:18s} test SR {o['SR']:.2f} SPL {o['SPL']:.2f} NE {o['NE']:.2f} ({o['episodes']} episodes)")

    paths = ExpertPaths.from_episodes(train_env.episodes, scene.nav_from_scene)
    g = torch.Generator().manual_seed(a.seed)
    keys = sorted(set(policy.in_keys) | {K.AGENT_POSITION, K.AGENT_YAW, K.EPISODE_INDEX})
    train_env.set_seed(a.seed)
    data = collect(train_env, ExpertActor(paths, k, sp, 0.3, generator=g), math.ceil(a.samples / 8), keys)
    labels = ExpertActor(paths, k, sp).labels(data)
    goal_b = bearing_deg(data.get(K.GOAL_VECTOR))
    wp_b = bearing_deg(labels[:, min(1, k - 1)])
    off = ((wp_b - goal_b + 180) % 360 - 180).abs()
    detour = off > a.detour_deg
    far = data.get(K.GOAL_VECTOR).norm(dim=-1)
    print(f"[3] {data.shape[0]} samples: expert's 2nd waypoint > {a.detour_deg:.0f} deg off the goal bearing on "
          f"{float(detour.float().mean()):.0%} of states (median goal distance {float(far.median()):.1f} m); "
          f"label |wp1| mean {float(labels[:, 0].norm(dim=-1).mean()):.2f} m")

    held = data.get(K.EPISODE_INDEX).view(-1) % 5 == 0                    # 1 in 5 training episodes held out
    tr, te = data[~held], data[held]
    route = RouteGoal(paths, a.lookahead)._call
    variants = {"images": lambda td: td, "blind": lambda td: td.set(K.RGB, torch.zeros_like(td.get(K.RGB))),
                "route": route}
    fits = {}
    for vname, view in variants.items():
        torch.manual_seed(a.seed)
        p = make_policy(name, **pcfg)
        l1 = fit(p, view(tr.clone()), labels[~held], a.updates, a.seed)
        h = held_out_error(p, view(te.clone()), labels[held], detour[held])
        fits[vname] = p
        print(f"[4] fit {vname:7s} ({int((~held).sum())} train / {int(held.sum())} held-out samples, {a.updates} "
              f"updates): train L1 {l1:.3f} m | held-out L1 {h['all']:.3f} m, per k {h['per_k']}, "
              f"detour {h['detour']:.3f} vs straight {h['straight']:.3f}")
    torch.manual_seed(a.seed)
    p = make_policy(name, **pcfg)
    l1 = fit(p, tr[:64].clone(), labels[~held][:64], a.updates, a.seed)
    print(f"[4] overfit 64 samples, {a.updates} updates: train L1 {l1:.3f} m (near 0 = the model can fit)")
    o = run_evaluation(test_env, PolicyActor(fits["images"]), seed=a.seed, name="bc").summary["overall"]
    print(f"[5] image fit on the test split: SR {o['SR']:.2f} SPL {o['SPL']:.2f} NE {o['NE']:.2f} "
          f"({o['episodes']} episodes)")
    oracle = WithRouteGoal(test_paths, a.lookahead, PolicyActor(fits["route"]))
    o = run_evaluation(test_env, oracle, seed=a.seed, name="route").summary["overall"]
    print(f"[6] route-goal fit ({a.lookahead:g} m lookahead) on the test split: SR {o['SR']:.2f} SPL {o['SPL']:.2f} "
          f"NE {o['NE']:.2f} ({o['episodes']} episodes) | total {time.perf_counter() - t0:.0f}s")


if __name__ == "__main__":
    main()
