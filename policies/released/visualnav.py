"""GNM, ViNT and NoMaD as released in visualnav-transformer (`train/vint_train/models/...`), and LogoNav, the
policy of the MBRA release (Learning-to-Drive-Anywhere-with-MBRA), in plain torch.

Each network keeps the release's module tree, so `load_state_dict(strict=True)` takes the released weights
as they are, including the parameters the release carries but never uses (the EfficientNets' ImageNet
classifier `_fc`, the template `sa_layer` that `nn.TransformerEncoder` copied its layers from). The
numbers each release was built with are the `*_RELEASE` specs below (`train/config/{gnm,vint,nomad}.yaml`).

Inputs, as the releases take them: `obs` `[N, 3 * (context + 1), H, W]`, the context frames oldest first
and the current frame last, concatenated on channels, each normalised with the ImageNet mean / std;
`goal` `[N, 3, H, W]` likewise. Outputs are in the releases' normalised units (one unit = the waypoint
spacing the robot was trained at; see `policies.released.pipeline` for metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from policies.released.backbones import EfficientNetB0, mobilenet_v2_features
from policies.released.diffusion import ConditionalUnet1D, DDPMSampler


@dataclass(frozen=True)
class VisualNavSpec:
    """The settings a released checkpoint was trained with."""

    context: int                    # past frames (the model reads context + 1)
    image_size: tuple[int, int]     # (height, width) pixels
    len_traj_pred: int              # waypoints predicted
    learn_angle: bool               # GNM / ViNT: (x, y, cos, sin) per waypoint
    encoding_size: int
    heads: int = 4
    layers: int = 4
    ff_factor: int = 4
    down_dims: tuple[int, ...] = (64, 128, 256)
    diffusion_iters: int = 10
    action_min: tuple[float, float] = (-2.5, -4.0)   # NoMaD's ACTION_STATS (data_config.yaml)
    action_max: tuple[float, float] = (5.0, 4.0)


GNM_RELEASE = VisualNavSpec(context=5, image_size=(64, 85), len_traj_pred=5, learn_angle=True, encoding_size=1024)
VINT_RELEASE = VisualNavSpec(context=5, image_size=(64, 85), len_traj_pred=5, learn_angle=True, encoding_size=512)
NOMAD_RELEASE = VisualNavSpec(context=3, image_size=(96, 96), len_traj_pred=8, learn_angle=False, encoding_size=256)


class PositionalEncoding(nn.Module):
    """Sinusoidal token positions, a buffer `pos_enc` `[1, max_len, d]` (`vint/self_attention.py`)."""

    def __init__(self, d: int, max_len: int):
        super().__init__()
        pos = torch.arange(max_len, dtype=torch.float).unsqueeze(1)
        div = torch.exp(torch.arange(0, d, 2).float() * (-torch.log(torch.tensor(10000.0)) / d))
        enc = torch.zeros(max_len, d)
        enc[:, 0::2] = torch.sin(pos * div)
        enc[:, 1::2] = torch.cos(pos * div)
        self.register_buffer("pos_enc", enc.unsqueeze(0))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.pos_enc[:, : x.shape[1]]


def _encoder_stack(d: int, heads: int, layers: int, ff_factor: int) -> tuple[nn.Module, nn.Module]:
    layer = nn.TransformerEncoderLayer(d, heads, ff_factor * d, activation="gelu", batch_first=True, norm_first=True)
    return layer, nn.TransformerEncoder(layer, num_layers=layers, enable_nested_tensor=False)


def _frames(obs: torch.Tensor, context: int) -> torch.Tensor:
    """`[N, 3 * (context + 1), H, W]` -> `[(context + 1) * N, 3, H, W]`, frame-major as the releases batch them."""
    return torch.cat(torch.split(obs, 3, dim=1), dim=0)


def _tokens(feats: torch.Tensor, context: int, n: int) -> torch.Tensor:
    return feats.reshape(context + 1, n, -1).transpose(0, 1)          # [N, context + 1, D]


def _waypoints(raw: torch.Tensor, spec: VisualNavSpec) -> torch.Tensor:
    """GNM / ViNT head output `[N, K * P]` -> `[N, K, P]`: deltas cumulated into waypoints, (cos, sin) unit."""
    a = raw.reshape(raw.shape[0], spec.len_traj_pred, -1)
    xy = a[..., :2].cumsum(dim=1)
    if spec.learn_angle:
        return torch.cat([xy, F.normalize(a[..., 2:], dim=-1)], dim=-1)
    return xy


class ViNTNet(nn.Module):
    """ViNT (`vint/vint.py`, early fusion): `(obs, goal) -> (distance [N, 1], waypoints [N, K, 4])`."""

    def __init__(self, spec: VisualNavSpec = VINT_RELEASE):
        super().__init__()
        self.spec = spec
        d = spec.encoding_size
        self.obs_encoder = EfficientNetB0(3)
        self.goal_encoder = EfficientNetB0(6)
        self.compress_obs_enc = nn.Linear(1280, d) if d != 1280 else nn.Identity()
        self.compress_goal_enc = nn.Linear(1280, d) if d != 1280 else nn.Identity()
        self.decoder = _ViNTDecoder(d, spec)
        self.dist_predictor = nn.Sequential(nn.Linear(32, 1))
        self.action_predictor = nn.Sequential(nn.Linear(32, spec.len_traj_pred * (4 if spec.learn_angle else 2)))

    def trunk(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """-> the decoder's 32 features `[N, 32]` (what both heads read)."""
        c, n = self.spec.context, obs.shape[0]
        g = self.compress_goal_enc(self.goal_encoder(torch.cat([obs[:, 3 * c:], goal], dim=1))).unsqueeze(1)
        o = _tokens(self.compress_obs_enc(self.obs_encoder(_frames(obs, c))), c, n)
        return self.decoder(torch.cat([o, g], dim=1))

    def heads(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.dist_predictor(z), _waypoints(self.action_predictor(z), self.spec)

    def forward(self, obs: torch.Tensor, goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.heads(self.trunk(obs, goal))


class _ViNTDecoder(nn.Module):
    """`MultiLayerDecoder`: positions, transformer, then flatten and ReLU MLP to 32 features."""

    def __init__(self, d: int, spec: VisualNavSpec):
        super().__init__()
        seq = spec.context + 2
        self.positional_encoding = PositionalEncoding(d, seq)
        self.sa_layer, self.sa_decoder = _encoder_stack(d, spec.heads, spec.layers, spec.ff_factor)
        widths = [seq * d, d, 256, 128, 64, 32]
        self.output_layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(widths[:-1], widths[1:]))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.sa_decoder(self.positional_encoding(x)).reshape(x.shape[0], -1)
        for layer in self.output_layers:
            x = F.relu(layer(x))
        return x


class GNMNet(nn.Module):
    """GNM (`gnm/gnm.py`): MobileNetV2 over the stacked context, and over context + goal."""

    def __init__(self, spec: VisualNavSpec = GNM_RELEASE):
        super().__init__()
        self.spec = spec
        d = spec.encoding_size
        self.obs_mobilenet = mobilenet_v2_features(3 * (spec.context + 1))
        self.compress_observation = nn.Sequential(nn.Linear(1280, d), nn.ReLU())
        self.goal_mobilenet = mobilenet_v2_features(3 * (spec.context + 2))
        self.compress_goal = nn.Sequential(nn.Linear(1280, 1024), nn.ReLU(), nn.Linear(1024, d), nn.ReLU())
        self.linear_layers = nn.Sequential(nn.Linear(2 * d, 256), nn.ReLU(), nn.Linear(256, 32), nn.ReLU())
        self.dist_predictor = nn.Sequential(nn.Linear(32, 1))
        self.action_predictor = nn.Sequential(nn.Linear(32, spec.len_traj_pred * (4 if spec.learn_angle else 2)))

    def trunk(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        pool = lambda x: F.adaptive_avg_pool2d(x, 1).flatten(1)  # noqa: E731
        o = self.compress_observation(pool(self.obs_mobilenet(obs)))
        g = self.compress_goal(pool(self.goal_mobilenet(torch.cat([obs, goal], dim=1))))
        return self.linear_layers(torch.cat([o, g], dim=1))

    heads = ViNTNet.heads

    def forward(self, obs: torch.Tensor, goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.heads(self.trunk(obs, goal))


class NoMaDVisionEncoder(nn.Module):
    """`NoMaD_ViNT`: EfficientNet-B0s with GroupNorm, a transformer over context + goal tokens, the goal token
    masked for exploration, an average over the unmasked tokens -> `[N, encoding_size]`."""

    def __init__(self, spec: VisualNavSpec = NOMAD_RELEASE):
        super().__init__()
        self.spec = spec
        d = spec.encoding_size
        self.obs_encoder = EfficientNetB0(3, norm="group")
        self.goal_encoder = EfficientNetB0(6, norm="group")
        self.compress_obs_enc = nn.Linear(1280, d) if d != 1280 else nn.Identity()
        self.compress_goal_enc = nn.Linear(1280, d) if d != 1280 else nn.Identity()
        self.positional_encoding = PositionalEncoding(d, spec.context + 2)
        self.sa_layer, self.sa_encoder = _encoder_stack(d, spec.heads, spec.layers, spec.ff_factor)

    def forward(self, obs: torch.Tensor, goal: torch.Tensor, goal_masked: torch.Tensor) -> torch.Tensor:
        """`goal_masked` `[N]` bool: True ignores the goal (the release's `input_goal_mask = 1`)."""
        c, n = self.spec.context, obs.shape[0]
        g = self.compress_goal_enc(self.goal_encoder(torch.cat([obs[:, 3 * c:], goal], dim=1))).unsqueeze(1)
        o = _tokens(self.compress_obs_enc(self.obs_encoder(_frames(obs, c))), c, n)
        pad = torch.zeros(n, c + 2, dtype=torch.bool, device=obs.device)
        pad[:, -1] = goal_masked.to(device=obs.device, dtype=torch.bool).reshape(n)
        tok = self.sa_encoder(self.positional_encoding(torch.cat([o, g], dim=1)), src_key_padding_mask=pad)
        keep = (~pad).float()
        weight = keep * ((c + 2) / keep.sum(dim=1, keepdim=True))       # the release's avg_pool_mask rows
        return (tok * weight.unsqueeze(-1)).mean(dim=1)


class DenseNetwork(nn.Module):
    """NoMaD's temporal-distance head (`nomad/nomad.py`)."""

    def __init__(self, d: int):
        super().__init__()
        self.network = nn.Sequential(nn.Linear(d, d // 4), nn.ReLU(), nn.Linear(d // 4, d // 16), nn.ReLU(),
                                     nn.Linear(d // 16, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.network(x)


class NoMaDNet(nn.Module):
    """NoMaD: `vision_encoder`, `noise_pred_net` (1-D U-Net), `dist_pred_net`, and the release's sampler."""

    def __init__(self, spec: VisualNavSpec = NOMAD_RELEASE):
        super().__init__()
        self.spec = spec
        self.vision_encoder = NoMaDVisionEncoder(spec)
        self.noise_pred_net = ConditionalUnet1D(2, spec.encoding_size, spec.down_dims)
        self.dist_pred_net = DenseNetwork(spec.encoding_size)
        self.sampler = DDPMSampler(spec.diffusion_iters)
        self.register_buffer("action_min", torch.tensor(spec.action_min), persistent=False)
        self.register_buffer("action_max", torch.tensor(spec.action_max), persistent=False)

    def sample_actions(self, cond: torch.Tensor, *, noise: torch.Tensor | None = None,
                       generator: torch.Generator | None = None) -> torch.Tensor:
        """Conditioning `[N, D]` -> normalised deltas `[N, K, 2]` in [-1, 1] (one DDPM sample each)."""
        return self.sampler.sample(lambda x, t, c: self.noise_pred_net(x, t, c), cond, self.spec.len_traj_pred,
                                   noise=noise, generator=generator)

    def waypoints(self, ndeltas: torch.Tensor) -> torch.Tensor:
        """The release's `get_action`: [-1, 1] deltas -> cumulated waypoints in normalised units."""
        d = (ndeltas + 1) / 2 * (self.action_max - self.action_min) + self.action_min
        return d.cumsum(dim=1)

    def forward(self, obs: torch.Tensor, goal: torch.Tensor, goal_masked: torch.Tensor, *,
                noise: torch.Tensor | None = None, generator: torch.Generator | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (temporal distance `[N, 1]`, waypoints `[N, K, 2]` in normalised units)."""
        cond = self.vision_encoder(obs, goal, goal_masked)
        return self.dist_pred_net(cond), self.waypoints(self.sample_actions(cond, noise=noise, generator=generator))


# LogoNav as `train/train.py` of Learning-to-Drive-Anywhere-with-MBRA builds it for training (`IL_gps` with its
# defaults: 512-d tokens, 2 heads, 2 layers); LOGONAV_DEPLOY_CONFIG is the width its deployment loader's `il2_gps`
# branch reads from `LogoNav.yaml` (1024-d, 4 heads, 4 layers). `logonav_spec` picks the one a state dict's shapes say.
LOGONAV_RELEASE = VisualNavSpec(context=5, image_size=(96, 96), len_traj_pred=8, learn_angle=True, encoding_size=512,
                                heads=2, layers=2)
LOGONAV_DEPLOY_CONFIG = VisualNavSpec(context=5, image_size=(96, 96), len_traj_pred=8, learn_angle=True,
                                      encoding_size=1024, heads=4, layers=4)


class LogoNavNet(nn.Module):
    """LogoNav (`il/il.py` `IL_gps`), the point-goal policy distilled from MBRA's reannotated data:
    `(obs, goal_pose [N, 4]) -> waypoints [N, K, 4]`; `goal_pose` = (x, y in the goal unit, cos, sin of the
    goal's relative yaw) in the robot frame."""

    def __init__(self, spec: VisualNavSpec = LOGONAV_RELEASE):
        super().__init__()
        self.spec = spec
        d = spec.encoding_size
        self.obs_encoder = EfficientNetB0(3)
        self.compress_obs_enc = nn.Linear(1280, d) if d != 1280 else nn.Identity()
        self.compress_goal_enc = nn.Identity()
        self.decoder = _ViNTDecoder(d, spec)
        self.action_predictor = nn.Sequential(nn.Linear(32, spec.len_traj_pred * 4))
        self.local_goal = nn.Sequential(nn.Linear(4, d))

    def trunk(self, obs: torch.Tensor, goal_pose: torch.Tensor) -> torch.Tensor:
        c, n = self.spec.context, obs.shape[0]
        g = self.local_goal(goal_pose).unsqueeze(1)
        o = _tokens(self.compress_obs_enc(self.obs_encoder(_frames(obs, c))), c, n)
        return self.decoder(torch.cat([o, g], dim=1))

    def heads(self, z: torch.Tensor) -> torch.Tensor:
        return _waypoints(self.action_predictor(z), self.spec)

    def forward(self, obs: torch.Tensor, goal_pose: torch.Tensor) -> torch.Tensor:
        return self.heads(self.trunk(obs, goal_pose))


def logonav_spec(state_dict: dict[str, torch.Tensor]) -> VisualNavSpec:
    """The LogoNav spec whose widths and depth match `state_dict` (the training or the deployment one)."""
    width = state_dict["compress_obs_enc.weight"].shape[0] if "compress_obs_enc.weight" in state_dict else None
    for spec in (LOGONAV_RELEASE, LOGONAV_DEPLOY_CONFIG):
        if width == spec.encoding_size and f"decoder.sa_decoder.layers.{spec.layers - 1}.linear1.weight" in state_dict:
            return spec
    return LOGONAV_RELEASE
