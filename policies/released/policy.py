"""A released model behind the project's policy contract: `make_policy("released", model=..., weights=...)`.

`ReleasedPolicy` wraps one of the released networks (`policies.released.visualnav`, `.citywalker`) with the
observation pipeline that release expects, so it runs in the env (benchmark, evaluate) and as the warm start
of PPO (`train policy=released`), weights read safely (`policies.released.weights`). What each reads:

| model | reads | frames | image | goal | waypoints | stop |
|---|---|---|---|---|---|---|
| gnm, vint | `RGB`, `GOAL_IMAGE` | 6 (context 5 + current) | 64 x 85 | goal view | 5, `x metres_per_unit` | temporal distance < `stop_distance` |
| nomad | `RGB`, `GOAL_IMAGE`, `HAS_GOAL_IMAGE` | 4 | 96 x 96 | goal view, masked when none | 8, `x metres_per_unit` | the same, with a goal view |
| logonav (mbra) | `RGB`, `GOAL_POSE` | 6 | 96 x 96 | `[x, y] / 0.25 m` (clipped to 30 m), cos, sin | 8, `x 0.1 m` | none |
| citywalker | `RGB`, `PAST_POSITIONS`, `GOAL_VECTOR` | 5 | 400 x 400 -> 392 | past positions + goal, `/ step` | 5, `x step` | arrival probability > 0.5 |

Images are ImageNet-normalised (CityWalker's network normalises itself), the frames oldest first and one
env step apart. `metres_per_unit` is the metric size of one normalised unit: the releases train on
waypoints divided by each dataset's spacing (RECON 0.25 m) and deploy with `max_v / frame_rate` of the
robot (visualnav-transformer's locobot: 0.05 m; NavDP's servers: 0.8 / 3 m; LogoNav: 0.3 / 3 m); the
default is the training normaliser, 0.25 m. CityWalker's unit is the mean step of its past positions
(`step`, floored at `min_step` metres) and its frame is the one its data code builds (x right, y forward).

PPO's mean (and the benchmark's deterministic action) for NoMaD is the release's DDPM chain with all its
noise set to zero (deterministic and differentiable); `sample_waypoints` draws the release's stochastic
samples. A stop is an all-zero trajectory (the agent stays), as NavDP's servers answer a stop.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from policies.base import NavPolicy
from policies.config import PolicyConfig
from policies.released.citywalker import CITYWALKER_RELEASE, CityWalkerNet
from policies.released.visualnav import (GNM_RELEASE, LOGONAV_RELEASE, NOMAD_RELEASE, VINT_RELEASE, GNMNet,
                                         LogoNavNet, NoMaDNet, ViNTNet, logonav_spec)
from policies.released.weights import load_released, released_state_dict
from wanderland_nav import keys as K

log = logging.getLogger(__name__)

RELEASED_MODELS = ("gnm", "vint", "nomad", "logonav", "citywalker")
ALIASES = {"mbra": "logonav"}
_SPECS = {"gnm": GNM_RELEASE, "vint": VINT_RELEASE, "nomad": NOMAD_RELEASE, "logonav": LOGONAV_RELEASE}
_READS = {"gnm": (K.RGB, K.GOAL_IMAGE), "vint": (K.RGB, K.GOAL_IMAGE),
          "nomad": (K.RGB, K.GOAL_IMAGE, K.HAS_GOAL_IMAGE), "logonav": (K.RGB, K.GOAL_POSE),
          "citywalker": (K.RGB, K.PAST_POSITIONS, K.GOAL_VECTOR)}
LOGONAV_GOAL_UNIT = 0.25      # metres per goal unit (LogoNav_ros.py / LogoNav_frodobot.py)
LOGONAV_GOAL_CLIP = 30.0      # metres: farther goals are pulled in to this distance (the deployment's thres_dist)
LOGONAV_WAYPOINT_UNIT = 0.1   # metres per waypoint unit: MAX_v / RATE = 0.3 / 3 in the deployment


def released_io(model: str) -> tuple[int, tuple[int, int], int]:
    """(frames read, (H, W) image, waypoints) of a released model."""
    if model == "citywalker":
        s = CITYWALKER_RELEASE
        return s.context, tuple(s.crop), s.len_traj_pred
    s = _SPECS[model]
    return s.context + 1, tuple(s.image_size), s.len_traj_pred


@dataclass
class ReleasedConfig(PolicyConfig):
    """`context`, `num_waypoints` and `image_size` are the release's (leave them unset)."""

    model: str = "nomad"
    weights: str | None = None           # the released file (.pth state dict, pickled model, Lightning .ckpt)
    metres_per_unit: float = 0.25        # gnm / vint / nomad: metres per normalised waypoint unit
    stop_distance: float = 3.0           # gnm / vint / nomad: stop when the predicted temporal distance is below
    min_step: float = 0.1                # citywalker: floor of the step unit (metres)
    arrival_threshold: float = 0.5       # citywalker: stop when sigmoid(arrival logit) exceeds it
    context: int = 0
    num_waypoints: int = 0
    image_size: tuple[int, int] = (0, 0)

    def __post_init__(self):
        self.model = ALIASES.get(str(self.model), str(self.model))
        if self.model not in RELEASED_MODELS:
            raise ValueError(f"ReleasedConfig.model={self.model!r}: expected one of {RELEASED_MODELS} (or 'mbra')")
        frames, size, k = released_io(self.model)
        for field_name, want in (("context", frames), ("num_waypoints", k), ("image_size", size)):
            got = getattr(self, field_name)
            unset = got in (0, None) or (field_name == "image_size" and tuple(got) == (0, 0))
            if not unset and (tuple(got) if field_name == "image_size" else int(got)) != want:
                raise ValueError(f"ReleasedConfig.{field_name}={got!r}: the released {self.model} takes {want}; "
                                 f"leave it unset")
            setattr(self, field_name, want)
        super().__post_init__()
        if not self.metres_per_unit > 0 or not self.min_step > 0:
            raise ValueError(f"ReleasedConfig: metres_per_unit={self.metres_per_unit} and min_step={self.min_step} "
                             f"must be > 0")

    @property
    def feature_dim(self) -> int:
        return NOMAD_RELEASE.encoding_size if self.model == "nomad" else 32


def _net(model: str, weights: str | None):
    if model == "citywalker":
        return CityWalkerNet()
    if model == "logonav" and weights:
        return LogoNavNet(logonav_spec(released_state_dict(weights)))
    return {"gnm": GNMNet, "vint": ViNTNet, "nomad": NoMaDNet, "logonav": LogoNavNet}[model]()


def to_citywalker_frame(xy: torch.Tensor) -> torch.Tensor:
    """Body frame (x forward, y left) -> CityWalker's (x right, y forward)."""
    return torch.stack([-xy[..., 1], xy[..., 0]], dim=-1)


def from_citywalker_frame(xy: torch.Tensor) -> torch.Tensor:
    return torch.stack([xy[..., 1], -xy[..., 0]], dim=-1)


class ReleasedPolicy(NavPolicy):
    config_class = ReleasedConfig

    def build(self, cfg: ReleasedConfig) -> None:
        self.model = cfg.model
        self.obs_keys = _READS[cfg.model]
        self.in_keys = list(self.obs_keys)
        self.net = _net(cfg.model, cfg.weights).eval()
        if cfg.weights:
            load_released(self.net, cfg.weights)
            self.pretrained_from = str(cfg.weights)
        else:
            log.info("released %s: no weights given, randomly initialised", cfg.model)

    def train(self, mode: bool = True):
        """The released backbones keep eval semantics (BatchNorm statistics are the release's); heads train."""
        super().train(mode)
        self.net.eval()
        return self

    def encoder_modules(self):
        n = self.net
        if self.model == "gnm":
            return [n.obs_mobilenet, n.goal_mobilenet]
        if self.model == "nomad":
            return [n.vision_encoder.obs_encoder, n.vision_encoder.goal_encoder]
        if self.model == "vint":
            return [n.obs_encoder, n.goal_encoder]
        return [n.obs_encoder]

    # ------------------------------------------------------------------ pipeline
    def stacked_frames(self, rgb: torch.Tensor) -> torch.Tensor:
        """uint8 `[N, T, H, W, 3]` -> `[N, 3 * context, h, w]`: normalised frames, oldest first, on channels."""
        x = self.images(rgb)
        return x.reshape(x.shape[0], -1, *x.shape[-2:])

    def goal_pose(self, pose: torch.Tensor) -> torch.Tensor:
        """`GOAL_POSE` (metres, cos, sin) -> LogoNav's goal: position clipped to 30 m, in 0.25 m units."""
        xy = pose[..., :2]
        d = xy.norm(dim=-1, keepdim=True)
        xy = torch.where(d > LOGONAV_GOAL_CLIP, xy / d.clamp_min(1e-9) * LOGONAV_GOAL_CLIP, xy)
        return torch.cat([xy / LOGONAV_GOAL_UNIT, pose[..., 2:4]], dim=-1)

    def step_unit(self, past: torch.Tensor) -> torch.Tensor:
        """CityWalker's unit `[N, 1, 1]`: the mean step between its past positions, at least `min_step`."""
        steps = (past[:, 1:] - past[:, :-1]).norm(dim=-1).mean(dim=1)
        return steps.clamp_min(self.config.min_step).view(-1, 1, 1)

    def citywalker_inputs(self, obs) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        frames = self.context_frames(obs[K.RGB])                     # [N, C, H, W, 3]
        n, c = frames.shape[:2]
        x = frames.reshape(n * c, *frames.shape[2:]).permute(0, 3, 1, 2).float().div_(255.0)
        crop = tuple(self.net.spec.crop)
        if tuple(x.shape[-2:]) != crop:
            x = F.interpolate(x, size=crop, mode="bilinear", align_corners=False, antialias=True)
        past = self._cw_past(obs)
        unit = self.step_unit(past)
        cord = to_citywalker_frame(torch.cat([past, obs[K.GOAL_VECTOR].view(n, 1, 2)], dim=1)) / unit
        return x.view(n, c, 3, *crop), cord, unit

    # ------------------------------------------------------------------ contract
    def encode(self, obs):
        if self.model in ("gnm", "vint"):
            return self.net.trunk(self.stacked_frames(obs[K.RGB]), self.image_tensor(obs[K.GOAL_IMAGE]))
        if self.model == "nomad":
            masked = ~obs[K.HAS_GOAL_IMAGE].reshape(-1).bool()
            return self.net.vision_encoder(self.stacked_frames(obs[K.RGB]), self.image_tensor(obs[K.GOAL_IMAGE]),
                                           masked)
        if self.model == "logonav":
            return self.net.trunk(self.stacked_frames(obs[K.RGB]), self.goal_pose(obs[K.GOAL_POSE]))
        frames, cord, _ = self.citywalker_inputs(obs)
        return self.net.trunk(frames, cord)

    def decode(self, feats, obs):
        cfg = self.config
        if self.model in ("gnm", "vint"):
            dist, a = self.net.heads(feats)
            wps = a[..., :2] * cfg.metres_per_unit
            return wps * (dist >= cfg.stop_distance).unsqueeze(-1).to(wps.dtype), {}
        if self.model == "nomad":
            n = feats.shape[0]
            zeros = torch.zeros(self.net.sampler.noise_shape(n, self.num_waypoints), device=feats.device)
            wps = self.net.waypoints(self.net.sample_actions(feats, noise=zeros)) * cfg.metres_per_unit
            stop = obs[K.HAS_GOAL_IMAGE].reshape(n).bool() & (self.net.dist_pred_net(feats).reshape(n) < cfg.stop_distance)
            return wps * (~stop).view(n, 1, 1).to(wps.dtype), {}
        if self.model == "logonav":
            return self.net.heads(feats)[..., :2] * LOGONAV_WAYPOINT_UNIT, {}
        wp, arrival = self.net.heads(feats)
        unit = self.step_unit(self._cw_past(obs))
        wps = from_citywalker_frame(wp) * unit
        go = (torch.sigmoid(arrival) <= cfg.arrival_threshold).to(wps.dtype).view(-1, 1, 1)
        return wps * go, {K.ARRIVAL_LOGIT: arrival}

    def _cw_past(self, obs) -> torch.Tensor:
        past, c = obs[K.PAST_POSITIONS], self.context
        n, t = past.shape[:2]
        return past[:, -c:] if t >= c else torch.cat([past[:, :1].expand(n, c - t, 2), past], dim=1)

    @torch.no_grad()
    def sample_waypoints(self, td, num_samples: int = 8, generator: torch.Generator | None = None) -> torch.Tensor:
        """NoMaD only: the release's stochastic DDPM samples, `[*B, S, K, 2]` metres (no stop rule applied)."""
        if self.model != "nomad":
            raise ValueError(f"sample_waypoints: {self.model} is deterministic; only nomad samples")
        obs, lead = self._gather(td)
        cond = self.encode(obs).repeat_interleave(num_samples, 0)
        wps = self.net.waypoints(self.net.sample_actions(cond, generator=generator)) * self.config.metres_per_unit
        return wps.view(*lead, num_samples, self.num_waypoints, 2)

