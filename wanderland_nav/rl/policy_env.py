"""Glue between a policy and a `NavEnv`: env shaped to the policy, LOD Gaussians, policies from checkpoints.

Used by both entry points (`train`, `evaluate`), so a checkpoint is evaluated in exactly the env it was
trained in (camera size, frame history, waypoint count and Gaussian level of detail come from its config).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import torch

from policies import NavPolicy, make_policy
from wanderland_nav.rl.checkpoint import load_checkpoint

log = logging.getLogger(__name__)


def shaped_env_config(env: dict[str, Any] | None, policy: NavPolicy, image_size: tuple[int, int] | None = None):
    """NavEnvConfig from a plain `env` dict, shaped to the policy: camera size = `image_size` (default the
    policy's input size), at least `policy.context` frames of history, `policy.num_waypoints` waypoints."""
    import copy

    from wanderland_nav.envs import NavEnvConfig

    d = copy.deepcopy(dict(env or {}))
    d.setdefault("camera", {})
    d.setdefault("kinematics", {})
    need = policy.config.env_requirements()  # the one declared "what the camera must deliver"
    h, w = image_size if image_size is not None else need.image_size
    d["camera"]["height"], d["camera"]["width"] = int(h), int(w)
    d["camera"]["history"] = max(int(d["camera"].get("history", 1)), need.history)
    d["kinematics"]["num_waypoints"] = need.num_waypoints
    d["kinematics"]["action_mode"] = need.action_mode
    return NavEnvConfig.from_dict(d, source="env config (+ policy shape)")


def lod_gaussians(path: str | Path, max_gaussians: int | None):
    """The scene's Gaussians, or a level-of-detail subset: the `max_gaussians` with the largest
    opacity x footprint (sigmoid(opacity) * exp(sum of the two largest log-scales)).

    Why: the pure-torch rasteriser's cost grows with the Gaussians per tile; on a 2-core CPU the full tiny
    demo (54k) renders ~1 agent-frame/s, a 10k subset several times faster with the same layout and
    colours. Training and evaluation use the same subset, so the numbers are consistent; None keeps all.
    """
    from wanderland_nav.render import Gaussians

    g = Gaussians.load(path)
    if max_gaussians is None or len(g) <= int(max_gaussians):
        return g
    score = torch.sigmoid(g.opacity_logits.view(-1)) * torch.exp(g.log_scales.topk(2, dim=-1).values.sum(-1))
    keep = score.topk(int(max_gaussians)).indices.sort().values
    log.info("rendering %d of %d Gaussians (max_gaussians)", len(keep), len(g))
    return g[keep]


class PolicyActor(torch.nn.Module):
    """Evaluation wrapper: the policy's mean waypoints (or a Gaussian sample) written as `ACTION`."""

    def __init__(self, policy: NavPolicy, deterministic: bool = True):
        super().__init__()
        self.policy, self.deterministic = policy, deterministic

    def forward(self, td):
        return self.policy.select_action(td, deterministic=self.deterministic)

    def reset(self):
        self.policy.reset()


def policy_from_checkpoint(path: str | Path, device: str = "cpu") -> tuple[NavPolicy, dict]:
    """Rebuild the policy a training checkpoint was made with (its stored config) and load its weights."""
    ckpt = load_checkpoint(path)
    conf = ckpt.get("config") or {}
    pol = dict(conf.get("policy") or {})
    if "name" not in pol:
        raise ValueError(f"{path}: checkpoint config has no policy.name; cannot rebuild the policy")
    name = pol.pop("name")
    policy = make_policy(name, **pol)
    policy.load_state_dict(ckpt["policy"])
    policy.pretrained_from = str(path)
    return policy.to(device).eval(), ckpt
