"""NoMaD-style model.

Trunk: every context frame through an observation CNN (-> C tokens), the current frame stacked with the
goal image (6 channels) through a goal CNN (-> 1 token, NoMaD's "obsgoal" encoder), optionally a
goal-vector token; a transformer over the tokens with the goal token masked out when the episode has
no goal image (NoMaD's goal masking: exploration vs goal reaching), then an average over the unmasked
tokens -> obs encoding `[N, D]`.

Heads: a temporal-distance MLP (steps to the goal), and a conditional 1-D conv denoiser that predicts the
noise on the 8 waypoint deltas normalised to [-1, 1] (DDPM, squared-cosine schedule, 10 steps).

PPO action distribution (a design choice of this project): the mean is the
**deterministic DDIM chain (eta = 0) started from x_T = 0**, unrolled through all diffusion steps with
gradients, then un-normalised and cumulated into metres; the std is the base class's learned
state-independent std. This keeps an exact log-prob (a diffusion sample has none in closed form) and lets
PPO move the denoiser itself, at the price of treating the multimodal head as unimodal around its
"central" sample. `sample_diffusion` still draws proper stochastic DDPM samples for evaluation/research.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from policies.base import NavPolicy, polar_fourier
from policies.encoders import SmallCNN
from policies.nomad.config import NoMaDConfig
from wanderland_nav import keys as K


def squaredcos_betas(steps: int) -> torch.Tensor:
    """diffusers' "squaredcos_cap_v2" schedule (NoMaD's), `[steps]`."""
    def abar(t):
        return math.cos((t / steps + 0.008) / 1.008 * math.pi / 2) ** 2
    return torch.tensor([min(1 - abar(i + 1) / abar(i), 0.999) for i in range(steps)], dtype=torch.float32)


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of integer steps `[N]` -> `[N, dim]`."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=t.device) / half)
    ang = t.float()[:, None] * freqs[None]
    return torch.cat([ang.sin(), ang.cos()], dim=-1)


class _FiLMBlock(nn.Module):
    def __init__(self, hidden: int, cond_dim: int):
        super().__init__()
        self.conv1 = nn.Conv1d(hidden, hidden, 3, padding=1)
        self.norm1 = nn.GroupNorm(8, hidden)
        self.film = nn.Linear(cond_dim, 2 * hidden)
        self.conv2 = nn.Conv1d(hidden, hidden, 3, padding=1)
        self.norm2 = nn.GroupNorm(8, hidden)

    def forward(self, x, cond):  # x [N, h, K], cond [N, c]
        y = F.mish(self.norm1(self.conv1(x)))
        scale, bias = self.film(cond).unsqueeze(-1).chunk(2, dim=1)
        y = y * (1 + scale) + bias
        y = F.mish(self.norm2(self.conv2(y)))
        return x + y


class NoisePredNet(nn.Module):
    """Conditional 1-D conv denoiser over `[N, K, 2]` (a compact stand-in for NoMaD's ConditionalUnet1D)."""

    def __init__(self, cond_dim: int, hidden: int = 128, blocks: int = 3):
        super().__init__()
        self.t_dim = 64
        self.t_mlp = nn.Sequential(nn.Linear(self.t_dim, 128), nn.Mish(), nn.Linear(128, 128))
        self.inp = nn.Conv1d(2, hidden, 1)
        self.blocks = nn.ModuleList(_FiLMBlock(hidden, cond_dim + 128) for _ in range(blocks))
        self.out = nn.Conv1d(hidden, 2, 1)

    def forward(self, x, t, cond):  # x [N, K, 2], t [N] long, cond [N, c] -> eps [N, K, 2]
        c = torch.cat([cond, self.t_mlp(timestep_embedding(t, self.t_dim))], dim=-1)
        h = self.inp(x.transpose(1, 2))
        for b in self.blocks:
            h = b(h, c)
        return self.out(h).transpose(1, 2)


class NoMaDPolicy(NavPolicy):
    obs_keys = (K.RGB, K.GOAL_IMAGE, K.HAS_GOAL_IMAGE, K.GOAL_VECTOR)

    config_class = NoMaDConfig

    def build(self, cfg: NoMaDConfig) -> None:
        if not cfg.use_goal_vector:  # released NoMaD: no goal coordinates read, so it fits the image-goal task
            self.obs_keys = tuple(k for k in self.obs_keys if k != K.GOAL_VECTOR)
            self.in_keys = list(self.obs_keys)
        self.obs_encoder = SmallCNN(cfg.dim)
        self.goal_encoder = SmallCNN(cfg.dim, in_channels=6)
        n_tok = cfg.context + 1 + int(cfg.use_goal_vector)
        self.pos_embed = nn.Parameter(torch.randn(1, n_tok, cfg.dim) * 0.02)
        if cfg.use_goal_vector:
            self.goal_vec_embed = nn.Sequential(nn.Linear(3 + 4 * 4, cfg.dim), nn.SiLU(), nn.Linear(cfg.dim, cfg.dim))
        layer = nn.TransformerEncoderLayer(cfg.dim, cfg.heads, 4 * cfg.dim, dropout=0.0, batch_first=True,
                                           norm_first=True, activation="gelu")
        self.transformer = nn.TransformerEncoder(layer, cfg.depth, enable_nested_tensor=False)
        self.dist_head = nn.Sequential(nn.Linear(cfg.dim, cfg.dim // 4), nn.ReLU(), nn.Linear(cfg.dim // 4, 1))
        self.noise_pred = NoisePredNet(cfg.dim, cfg.unet_hidden)
        betas = squaredcos_betas(cfg.diffusion_steps)
        self.register_buffer("betas", betas)
        self.register_buffer("alphas_cumprod", torch.cumprod(1 - betas, 0))
        self.register_buffer("action_min", torch.tensor(cfg.action_min, dtype=torch.float32))
        self.register_buffer("action_max", torch.tensor(cfg.action_max, dtype=torch.float32))

    def encoder_modules(self):
        return [self.obs_encoder, self.goal_encoder]

    # ---------------------------------------------------------------- normalisation
    def normalize_deltas(self, wps: torch.Tensor) -> torch.Tensor:
        """metres `[N, K, 2]` waypoints -> per-step deltas in spacing units, mapped to [-1, 1]."""
        prev = torch.cat([torch.zeros_like(wps[:, :1]), wps[:, :-1]], dim=1)
        d = (wps - prev) / self.waypoint_spacing
        return 2 * (d - self.action_min) / (self.action_max - self.action_min) - 1

    def unnormalize(self, x: torch.Tensor) -> torch.Tensor:
        """[-1, 1] deltas `[N, K, 2]` -> metres waypoints (cumulated)."""
        d = (x + 1) / 2 * (self.action_max - self.action_min) + self.action_min
        return d.cumsum(dim=1) * self.waypoint_spacing

    # ---------------------------------------------------------------- trunk
    def encode(self, obs):
        f_obs = self.frame_features(obs[K.RGB], self.obs_encoder)        # [N, C, D]
        n, c = f_obs.shape[:2]
        newest = self.image_tensor(obs[K.RGB][:, -1])                    # [N, 3, h, w]
        goal = self.image_tensor(obs[K.GOAL_IMAGE])                      # [N, 3, h, w]
        f_goal = self.goal_encoder(torch.cat([newest, goal], dim=1)).unsqueeze(1)
        tokens = [f_obs, f_goal]
        goal_mask = ~obs[K.HAS_GOAL_IMAGE].view(n).bool()                # True -> exploration
        pad = torch.zeros(n, c + 1, dtype=torch.bool, device=f_obs.device)
        pad[:, c] = goal_mask
        if self.config.use_goal_vector:
            tokens.append(self.goal_vec_embed(polar_fourier(obs[K.GOAL_VECTOR], 4, 50.0)).unsqueeze(1))
            pad = torch.cat([pad, torch.zeros(n, 1, dtype=torch.bool, device=f_obs.device)], dim=1)
        tok = self.transformer(torch.cat(tokens, dim=1) + self.pos_embed, src_key_padding_mask=pad)
        keep = (~pad).float().unsqueeze(-1)
        return (tok * keep).sum(1) / keep.sum(1)                         # [N, D] masked average

    # ---------------------------------------------------------------- diffusion
    def ddim_mean(self, cond: torch.Tensor) -> torch.Tensor:
        """Deterministic DDIM (eta=0) from x_T = 0, differentiable: `[N, D]` -> normalised `[N, K, 2]`."""
        n = cond.shape[0]
        x = torch.zeros(n, self.num_waypoints, 2, device=cond.device)
        ab = self.alphas_cumprod
        for t in reversed(range(len(ab))):
            eps = self.noise_pred(x, torch.full((n,), t, device=cond.device, dtype=torch.long), cond)
            x0 = ((x - (1 - ab[t]).sqrt() * eps) / ab[t].sqrt()).clamp(-1, 1)
            ab_prev = ab[t - 1] if t > 0 else torch.ones((), device=cond.device)
            x = ab_prev.sqrt() * x0 + (1 - ab_prev).sqrt() * eps
        return x

    @torch.no_grad()
    def sample_diffusion(self, td, num_samples: int = 1, generator: torch.Generator | None = None) -> torch.Tensor:
        """Stochastic DDPM samples: `[*B, S, K, 2]` body-frame waypoints in metres."""
        obs, lead = self._gather(td)
        cond = self.encode(obs).repeat_interleave(num_samples, 0)
        n = cond.shape[0]
        x = torch.randn(n, self.num_waypoints, 2, generator=generator, device=cond.device)
        ab, betas = self.alphas_cumprod, self.betas
        for t in reversed(range(len(ab))):
            eps = self.noise_pred(x, torch.full((n,), t, device=x.device, dtype=torch.long), cond)
            mean = (x - betas[t] / (1 - ab[t]).sqrt() * eps) / (1 - betas[t]).sqrt()
            if t > 0:
                var = betas[t] * (1 - ab[t - 1]) / (1 - ab[t])
                mean = mean + var.sqrt() * torch.randn(x.shape, generator=generator, device=x.device)
            x = mean.clamp(-1, 1)
        return self.unnormalize(x).view(*lead, num_samples, self.num_waypoints, 2)

    def decode(self, feats, obs):
        return self.unnormalize(self.ddim_mean(feats)), {}

    def temporal_distance(self, td) -> torch.Tensor:
        obs, lead = self._gather(td)
        return self.dist_head(self.encode(obs)).view(*lead, 1)

    def bc_loss(self, td, target):
        """NoMaD's objective: (1 - a) * noise MSE + a * temporal-distance MSE (goal-conditioned samples
        only), a = dist_weight. The distance label is `DISTANCE_TO_GOAL / spacing` (clipped) when the
        batch carries it."""
        obs, _ = self._gather(td)
        tgt = target.reshape(-1, self.num_waypoints, 2)
        cond = self.encode(obs)
        x0 = self.normalize_deltas(tgt).clamp(-1, 1)
        n = x0.shape[0]
        t = torch.randint(0, len(self.alphas_cumprod), (n,), device=x0.device)
        eps = torch.randn_like(x0)
        ab = self.alphas_cumprod[t].view(n, 1, 1)
        xt = ab.sqrt() * x0 + (1 - ab).sqrt() * eps
        diff = F.mse_loss(self.noise_pred(xt, t, cond), eps)
        metrics = {"diffusion_mse": float(diff.detach())}
        loss = diff
        if K.DISTANCE_TO_GOAL in td.keys(True):
            has_goal = obs[K.HAS_GOAL_IMAGE].view(n).float()
            label = (td.get(K.DISTANCE_TO_GOAL).reshape(n) / self.waypoint_spacing).clamp(0, self.config.max_distance)
            err = (self.dist_head(cond).view(n) - label) ** 2
            dist = (err * has_goal).sum() / has_goal.sum().clamp_min(1)
            a = self.config.dist_weight
            loss = (1 - a) * diff + a * dist
            metrics["dist_mse"] = float(dist.detach())
        return loss, metrics
