"""The one contract every navigation policy follows.

A policy is a `TensorDictModuleBase`: it reads observation keys (`wanderland_nav.keys`) and writes

* `WAYPOINTS` `[*B, K, 2]` its deterministic waypoint prediction (body frame, metres),
* `LOC`, `SCALE` `[*B, K, 2]` the mean / std of its Gaussian action distribution (LOC == WAYPOINTS),
* `STATE_VALUE` `[*B, 1]` the value head's estimate (for PPO's GAE),

and subclasses may add their own outputs (CityWalker's `ARRIVAL_LOGIT`).

Why a Gaussian over waypoints: PPO needs log-probabilities of the executed action. Every policy here
predicts a deterministic set of K body-frame waypoints; the action distribution is an independent
Normal around them with a learned, state-independent log-std per (waypoint, axis). The log-prob is
summed over the K*2 action dimensions (`WaypointNormal`). For NoMaD's diffusion head the mean is the
deterministic (DDIM, eta=0, x_T=0) denoised chain, see `policies/nomad/model.py`. PPO's default
(`algo.ppo.action_dist=tracked`, `wanderland_nav/rl/tracked_target.py`) does not use this K*2 Gaussian:
the env executes one waypoint per step, so PPO samples and scores only that one (2 dims).

Why the value head reads *detached* features: the paper fine-tunes released (or, here, behaviour-cloned)
policies with PPO; a freshly initialised critic back-propagating into the shared trunk would wreck the
pretrained features in the first updates. `value()` runs the trunk without gradients and trains only
the value MLP. `freeze_encoders()` additionally freezes the image encoders ("update only the policy");
`PolicyConfig.freeze_encoder` says when ("rl": the RL trainer calls it; "always": at construction).

Normalisation statistics (image mean/std, waypoint spacing, NoMaD's action min/max) are registered
buffers, so they travel in `state_dict()` and in every checkpoint.

Leading batch dims: `forward` accepts any `td.batch_size` (`[B]` from the env, `[B, T]` from a
collector, `[N]` in a PPO minibatch); internally everything is flattened to `[N, ...]`.
"""

from __future__ import annotations

import logging
import math
from contextlib import contextmanager
from typing import Iterable

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torch import distributions as D
from torch import nn

from policies.config import PolicyConfig
from policies.frame_memo import FrameMemo, distinct
from wanderland_nav import keys as K

log = logging.getLogger(__name__)

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def softplus_std(raw: torch.Tensor, min_std: float) -> torch.Tensor:
    """Exploration std from its raw parameter: `min_std + softplus(raw)` (smooth, never below min_std)."""
    return min_std + F.softplus(raw)


@torch.no_grad()
def fill_softplus_std(raw: torch.Tensor, std: float, min_std: float, owner: str) -> None:
    """Set every entry of `raw` so that `softplus_std(raw, min_std) == std` (the softplus inverse)."""
    if not std > min_std:
        raise ValueError(f"{owner}: std={std} must exceed min_std={min_std}")
    raw.fill_(math.log(math.expm1(std - min_std)))


class WaypointNormal(D.Independent):
    """Independent Normal over the last two dims (`[K, 2]` waypoints): one log-prob per sample.

    `deterministic_sample` is what TorchRL uses under `ExplorationType.DETERMINISTIC`: the mean.
    """

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor):
        super().__init__(D.Normal(loc, scale), 2)

    @property
    def deterministic_sample(self) -> torch.Tensor:
        return self.mean


def _flat(x: torch.Tensor, nlead: int) -> torch.Tensor:
    """Flatten the `nlead` leading batch dims into one: `[*B, ...] -> [N, ...]`."""
    return x.reshape(-1, *x.shape[nlead:])


class NavPolicy(TensorDictModuleBase):
    """Base class: preprocessing, the Gaussian head, the value head, freezing, BC targets.

    Built from a `PolicyConfig` (or its fields as keyword overrides). Subclasses set `config_class`
    and `obs_keys`, create their modules in `build(cfg)`, and implement `encode(obs) -> feats [N, ...]`
    (plus `pooled(feats) -> [N, D]` when the trunk returns tokens) and `decode(feats, obs) ->
    (waypoints [N, K, 2], extras {key: [N, ...]})`, and may override `bc_loss`. `obs` is a dict of flattened `[N, ...]`
    tensors holding the subclass's `in_keys`.
    """

    #: observation keys this policy reads; set by subclasses
    obs_keys: tuple[str, ...] = ()
    #: extra output keys beyond the common ones
    extra_out_keys: tuple[str, ...] = ()
    #: the `PolicyConfig` subclass this policy is built from; set by subclasses
    config_class: type[PolicyConfig] = PolicyConfig

    def __init__(self, config: PolicyConfig | None = None, *, min_std: float = 0.02, value_hidden: int = 128,
                 **overrides):
        super().__init__()
        if config is not None and overrides:
            raise TypeError(f"{type(self).__name__}: pass a {self.config_class.__name__} or field overrides, "
                            f"not both (got overrides {sorted(overrides)})")
        cfg = config if config is not None else self.config_class(**overrides)
        if cfg.init_std <= min_std:
            raise ValueError(f"init_std={cfg.init_std} must exceed min_std={min_std}")
        self.config = cfg
        self.num_waypoints = int(cfg.num_waypoints)
        self.context = int(cfg.context)
        self.image_size = tuple(cfg.image_size)
        self.feature_dim = int(cfg.feature_dim)
        self.min_std = float(min_std)
        self.in_keys = list(self.obs_keys)
        self.out_keys = [K.WAYPOINTS, K.LOC, K.SCALE, K.STATE_VALUE, *self.extra_out_keys]
        # normalisation statistics: buffers so they live in the state dict
        self.register_buffer("image_mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1))
        self.register_buffer("image_std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1))
        self.register_buffer("waypoint_spacing", torch.tensor(float(cfg.waypoint_spacing)))
        # std = min_std + softplus(raw): smooth, never below min_std, no exp blow-up
        self.std_param = nn.Parameter(torch.empty(self.num_waypoints, 2))
        self.set_std(cfg.init_std)
        self.value_head = nn.Sequential(
            nn.Linear(self.feature_dim, value_hidden), nn.Tanh(), nn.Linear(value_hidden, 1)
        )
        self.pretrained_from: str | None = None
        self.build(cfg)
        if cfg.freeze_encoder == "always":
            self.freeze_encoders(True)

    # ------------------------------------------------------------------ subclass API
    def build(self, cfg: PolicyConfig) -> None:
        """Create the architecture's modules from its config (called once by `__init__`)."""
        raise NotImplementedError

    def encode(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:  # -> [N, ...] trunk output
        raise NotImplementedError

    def pooled(self, feats: torch.Tensor) -> torch.Tensor:
        """Trunk output -> `[N, feature_dim]` value features (identity unless the trunk returns tokens)."""
        return feats

    def decode(self, feats: torch.Tensor, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict]:
        raise NotImplementedError

    def encoder_modules(self) -> list[nn.Module]:
        """Image encoders that `freeze_encoders` freezes."""
        return []

    # ------------------------------------------------------------------ preprocessing
    def context_frames(self, rgb: torch.Tensor) -> torch.Tensor:
        """uint8 `[N, T, H, W, 3]` -> uint8 `[N, C, H, W, 3]`: the newest `context` frames, the oldest repeated
        when fewer arrive (the env may render more or fewer frames than the released model used)."""
        if rgb.dim() != 5 or rgb.shape[-1] != 3:
            raise ValueError(f"{type(self).__name__}: '{K.RGB}' must be [*B, T, H, W, 3], got {tuple(rgb.shape)}")
        n, t = rgb.shape[:2]
        if t >= self.context:
            return rgb[:, t - self.context:]
        return torch.cat([rgb[:, :1].expand(n, self.context - t, *rgb.shape[2:]), rgb], dim=1)

    def images(self, rgb: torch.Tensor) -> torch.Tensor:
        """uint8 `[N, T, H, W, 3]` -> normalised float `[N, C, 3, h, w]` at this policy's context/size.

        We keep the newest `context` frames (`context_frames`) and resize, so the model always sees its own
        input convention.
        """
        rgb = self.context_frames(rgb)
        n = rgb.shape[0]
        return self.image_tensor(rgb.reshape(n * self.context, *rgb.shape[2:])).view(
            n, self.context, 3, *self.image_size
        )

    def frame_features(self, rgb: torch.Tensor, encoder: nn.Module) -> torch.Tensor:
        """uint8 `[N, T, H, W, 3]` -> `[N, C, D]`: `encoder` over the normalised context frames, each distinct
        image encoded once (`policies.frame_memo`): within this call always; across calls from the memo that
        `reuse_frame_features` holds, when `encoder` takes no gradient here. Same values as encoding every
        frame (to float rounding: the encoder sees another batch), same gradients."""
        frames = self.context_frames(rgb)                          # [N, C, H, W, 3]
        n, c = frames.shape[:2]
        flat = frames.reshape(n * c, *frames.shape[2:])            # [N*C, H, W, 3]
        encode = lambda imgs: encoder(self.image_tensor(imgs))     # noqa: E731  [M, H, W, 3] -> [M, D]
        memo = self.__dict__.get("_frame_memo")
        takes_grad = torch.is_grad_enabled() and any(p.requires_grad for p in encoder.parameters())
        if memo is not None and not takes_grad:
            feats = memo.features(encoder, flat, encode)
        else:
            rep, inverse = distinct(flat.reshape(n * c, -1))
            feats = encode(flat[rep])[inverse]
        return feats.view(n, c, -1)

    @contextmanager
    def reuse_frame_features(self, *rgb: torch.Tensor):
        """Within the block, frame features of the images in `rgb` (uint8 `[..., T, H, W, 3]` each, e.g. a PPO
        batch's `RGB` and its `next` `RGB`) are computed once per encoder and looked up by content
        (`frame_features`). For encoders that take no gradient (PPO with `freeze_encoder=rl`); a trained
        encoder still runs per call, on each call's distinct images."""
        frames = torch.cat([r.reshape(-1, *r.shape[-3:]) for r in rgb])
        self.__dict__["_frame_memo"] = FrameMemo(frames)
        try:
            yield
        finally:
            self.__dict__.pop("_frame_memo", None)

    def image_tensor(self, img: torch.Tensor) -> torch.Tensor:
        """uint8 `[M, H, W, 3]` -> normalised float `[M, 3, h, w]`."""
        x = img.permute(0, 3, 1, 2).float().div_(255.0)
        if tuple(x.shape[-2:]) != self.image_size:
            x = F.interpolate(x, size=self.image_size, mode="bilinear", align_corners=False, antialias=True)
        return (x - self.image_mean) / self.image_std

    def _gather(self, td: TensorDictBase) -> tuple[dict[str, torch.Tensor], torch.Size]:
        lead = td.batch_size
        obs = {}
        for key in self.obs_keys:
            if key not in td.keys():
                raise KeyError(f"{type(self).__name__} needs observation '{key}' but the TensorDict has "
                               f"{sorted(map(str, td.keys()))}")
            obs[key] = _flat(td.get(key), len(lead))
        return obs, lead

    # ------------------------------------------------------------------ PPO interface
    def scale(self) -> torch.Tensor:  # [K, 2]
        return softplus_std(self.std_param, self.min_std)

    def set_std(self, std: float) -> None:
        """Every waypoint coordinate's exploration std := `std` metres. PPO's `init_std` uses it: BC never
        trains the std, so a BC policy would otherwise explore with the config's `init_std`."""
        fill_softplus_std(self.std_param, std, self.min_std, type(self).__name__)

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        obs, lead = self._gather(td)
        feats = self.encode(obs)
        wps, extras = self.decode(feats, obs)
        value = self.value_head(self.pooled(feats).detach())
        td.set(K.WAYPOINTS, wps.view(*lead, self.num_waypoints, 2))
        td.set(K.LOC, wps.view(*lead, self.num_waypoints, 2))
        td.set(K.SCALE, self.scale().expand(*lead, self.num_waypoints, 2))
        td.set(K.STATE_VALUE, value.view(*lead, 1))
        for k, v in extras.items():
            td.set(k, v.view(*lead, *v.shape[1:]))
        return td

    def value(self, td: TensorDictBase) -> TensorDictBase:
        """Write `STATE_VALUE` only; the trunk runs without gradients (see module docstring)."""
        obs, lead = self._gather(td)
        with torch.no_grad():
            feats = self.encode(obs)
        td.set(K.STATE_VALUE, self.value_head(self.pooled(feats)).view(*lead, 1))
        return td

    @torch.no_grad()
    def value_features(self, td: TensorDictBase) -> torch.Tensor:
        """`[N, feature_dim]` trunk readout features, flattened over the batch dims, without gradients: what
        PPO's own critic (`wanderland_nav.rl.critic`) reads beside its own observations."""
        obs, _ = self._gather(td)
        return self.pooled(self.encode(obs))

    def dist(self, td: TensorDictBase) -> WaypointNormal:
        out = self(td.copy())
        return WaypointNormal(out.get(K.LOC), out.get(K.SCALE))

    @torch.no_grad()
    def select_action(self, td: TensorDictBase, deterministic: bool = True,
                      generator: torch.Generator | None = None) -> TensorDictBase:
        """Write `ACTION` `[*B, K, 2]`: the mean waypoints, or a sample from the Gaussian."""
        self(td)
        loc, scale = td.get(K.LOC), td.get(K.SCALE)
        if deterministic:
            action = loc.clone()
        else:
            action = loc + scale * torch.randn(loc.shape, generator=generator, device=loc.device)
        td.set(K.ACTION, action)
        return td

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Clear per-episode state for the envs in `mask`.

        The policies here are stateless between steps (their temporal context arrives as the env's
        `RGB`/`PAST_POSITIONS` history), so there is nothing to clear; kept so that recurrent policies
        plug into the same evaluation loop.
        """
        return None

    # ------------------------------------------------------------------ freezing / weights
    def freeze_encoders(self, frozen: bool = True) -> None:
        for m in self.encoder_modules():
            for p in m.parameters():
                p.requires_grad_(not frozen)

    def trainable_parameters(self) -> Iterable[nn.Parameter]:
        return [p for p in self.parameters() if p.requires_grad]

    # ------------------------------------------------------------------ behaviour cloning
    def bc_loss(self, td: TensorDictBase, target: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
        """Supervised loss against expert waypoints `target` `[*B, K, 2]` (body frame, metres).

        Default: smooth-L1 on waypoints divided by the waypoint spacing (scale-free, like the released
        models' normalised targets). Subclasses add their own heads' terms.
        """
        out = self(td.copy())
        pred = out.get(K.WAYPOINTS)
        loss = F.smooth_l1_loss(pred / self.waypoint_spacing, target / self.waypoint_spacing)
        return loss, {"waypoint_l1": float((pred - target).detach().abs().mean())}


def polar_fourier(xy: torch.Tensor, num_freqs: int, max_range: float) -> torch.Tensor:
    """Body-frame points `[..., 2]` (metres) -> `[..., 3 + 4*num_freqs]` features.

    Polar form (log-distance, cos, sin of the bearing) keeps far goals in range; Fourier features of the
    normalised (x, y) at octave frequencies give the transformer fine resolution near the agent
    (CityWalker embeds its coordinates this way).
    """
    d = xy.norm(dim=-1, keepdim=True)
    bearing = torch.atan2(xy[..., 1:2], xy[..., 0:1])
    polar = torch.cat([torch.log1p(d), torch.cos(bearing), torch.sin(bearing)], dim=-1)
    freqs = (2.0 ** torch.arange(num_freqs, device=xy.device, dtype=xy.dtype)) * math.pi
    ang = (xy / max_range).unsqueeze(-1) * freqs  # [..., 2, F]
    four = torch.cat([torch.sin(ang), torch.cos(ang)], dim=-1).flatten(-2)
    return torch.cat([polar, four], dim=-1)


def headings_from_waypoints(wps: torch.Tensor) -> torch.Tensor:
    """`[..., K, 2]` waypoints -> `[..., K, 2]` (cos, sin) of the heading of each segment from the
    previous waypoint (the origin for the first). Zero-length segments inherit the previous heading
    (forward for the first), so a standing expert yields a defined target."""
    prev = torch.cat([torch.zeros_like(wps[..., :1, :]), wps[..., :-1, :]], dim=-2)
    seg = wps - prev
    n = seg.norm(dim=-1, keepdim=True)
    unit = torch.where(n > 1e-4, seg / n.clamp_min(1e-4), torch.full_like(seg, float("nan")))
    # forward-fill NaNs along K (K is small: loop over K, not over agents)
    out = []
    last = torch.zeros_like(unit[..., 0, :])
    last[..., 0] = 1.0
    for k in range(unit.shape[-2]):
        u = unit[..., k, :]
        u = torch.where(torch.isnan(u), last, u)
        out.append(u)
        last = u
    return torch.stack(out, dim=-2)
