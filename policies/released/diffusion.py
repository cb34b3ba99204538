"""NoMaD's diffusion head: the 1-D conditional U-Net of Diffusion Policy and the DDPM sampler of its release.

`ConditionalUnet1D` keeps the module names of `diffusion_policy.model.diffusion.conditional_unet1d`
(`diffusion_step_encoder`, `down_modules`, `mid_modules`, `up_modules`, `final_conv`), so NoMaD's
`noise_pred_net.*` weights load unchanged; it is the configuration NoMaD uses (global conditioning, no
local conditioning, FiLM bias only: `cond_predict_scale=False`).

`DDPMSampler` is the scheduler NoMaD trains and deploys with (diffusers' `DDPMScheduler` with
`num_train_timesteps = num_diffusion_iters`, `beta_schedule="squaredcos_cap_v2"`, `clip_sample=True`,
`prediction_type="epsilon"`, variance "fixed_small", all training steps at inference), written out here.
Its noise can be passed in (`noise`) so a sample is reproducible bit for bit.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


def sinusoidal_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Diffusion Policy's `SinusoidalPosEmb`: `[N]` steps -> `[N, dim]` (sin half, then cos half)."""
    half = dim // 2
    freqs = torch.exp(torch.arange(half, device=t.device) * -(math.log(10000) / (half - 1)))
    ang = t[:, None] * freqs[None, :]
    return torch.cat([ang.sin(), ang.cos()], dim=-1)


class Conv1dBlock(nn.Module):
    """Conv1d -> GroupNorm -> Mish, under `block.0`, `block.1`."""

    def __init__(self, inp: int, out: int, kernel: int, groups: int = 8):
        super().__init__()
        self.block = nn.Sequential(nn.Conv1d(inp, out, kernel, padding=kernel // 2), nn.GroupNorm(groups, out),
                                   nn.Mish())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.block(x)


class _CondEncoder(nn.Module):
    """`Mish -> Linear` at indices 0, 1 (the release's index 2 is a parameter-free reshape)."""

    def __init__(self, cond_dim: int, channels: int):
        super().__init__()
        self.add_module("0", nn.Mish())
        self.add_module("1", nn.Linear(cond_dim, channels))

    def forward(self, cond: torch.Tensor) -> torch.Tensor:
        return getattr(self, "1")(F.mish(cond)).unsqueeze(-1)


class ConditionalResidualBlock1D(nn.Module):
    def __init__(self, inp: int, out: int, cond_dim: int, kernel: int = 3, groups: int = 8):
        super().__init__()
        self.blocks = nn.ModuleList([Conv1dBlock(inp, out, kernel, groups), Conv1dBlock(out, out, kernel, groups)])
        self.cond_encoder = _CondEncoder(cond_dim, out)
        self.residual_conv = nn.Conv1d(inp, out, 1) if inp != out else nn.Identity()

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        h = self.blocks[0](x) + self.cond_encoder(cond)
        return self.blocks[1](h) + self.residual_conv(x)


class _Resample(nn.Module):
    def __init__(self, dim: int, up: bool):
        super().__init__()
        self.conv = nn.ConvTranspose1d(dim, dim, 4, 2, 1) if up else nn.Conv1d(dim, dim, 3, 2, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(x)


class ConditionalUnet1D(nn.Module):
    """`[N, T, input_dim]` noisy sample, `[N]` (or scalar) step, `[N, global_cond_dim]` -> predicted noise."""

    def __init__(self, input_dim: int, global_cond_dim: int, down_dims=(64, 128, 256), step_embed_dim: int = 256,
                 kernel: int = 3, groups: int = 8):
        super().__init__()
        self.step_embed_dim = step_embed_dim
        cond = step_embed_dim + global_cond_dim
        dims = [input_dim, *down_dims]
        in_out = list(zip(dims[:-1], dims[1:]))
        block = lambda i, o: ConditionalResidualBlock1D(i, o, cond, kernel, groups)  # noqa: E731
        # registered in the release's order, so the state dict lists its keys as the release's does
        self.mid_modules = nn.ModuleList([block(dims[-1], dims[-1]), block(dims[-1], dims[-1])])
        self.diffusion_step_encoder = nn.Sequential(
            nn.Identity(), nn.Linear(step_embed_dim, 4 * step_embed_dim), nn.Mish(),
            nn.Linear(4 * step_embed_dim, step_embed_dim))
        # the release upsamples after every up stage (its "is_last" test never holds)
        self.up_modules = nn.ModuleList(
            nn.ModuleList([block(2 * o, i), block(i, i), _Resample(i, up=True)]) for i, o in reversed(in_out[1:]))
        self.down_modules = nn.ModuleList(
            nn.ModuleList([block(i, o), block(o, o), _Resample(o, up=False) if k < len(in_out) - 1 else nn.Identity()])
            for k, (i, o) in enumerate(in_out))
        self.final_conv = nn.Sequential(Conv1dBlock(down_dims[0], down_dims[0], kernel),
                                        nn.Conv1d(down_dims[0], input_dim, 1))

    def forward(self, sample: torch.Tensor, timestep: torch.Tensor | int, global_cond: torch.Tensor) -> torch.Tensor:
        x = sample.transpose(1, 2)                                   # [N, C, T]
        t = torch.as_tensor(timestep, device=x.device)
        t = t.reshape(-1).expand(x.shape[0]) if t.numel() == 1 else t
        feat = self.diffusion_step_encoder(sinusoidal_embedding(t, self.step_embed_dim))
        feat = torch.cat([feat, global_cond], dim=-1)
        skips = []
        for res1, res2, down in self.down_modules:
            x = res2(res1(x, feat), feat)
            skips.append(x)
            x = down(x)
        for mid in self.mid_modules:
            x = mid(x, feat)
        for res1, res2, up in self.up_modules:
            x = up(res2(res1(torch.cat([x, skips.pop()], dim=1), feat), feat))
        return self.final_conv(x).transpose(1, 2)


def squaredcos_cap_v2(steps: int, max_beta: float = 0.999) -> torch.Tensor:
    """diffusers' `betas_for_alpha_bar` cosine schedule, float32 `[steps]`."""
    def abar(t: float) -> float:
        return math.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2
    return torch.tensor([min(1 - abar((i + 1) / steps) / abar(i / steps), max_beta) for i in range(steps)],
                        dtype=torch.float32)


class DDPMSampler:
    """Ancestral DDPM sampling over all `steps` training steps (NoMaD: 10), clipping x0 to [-1, 1]."""

    def __init__(self, steps: int = 10):
        self.steps = int(steps)
        self.betas = squaredcos_cap_v2(self.steps)
        self.alphas_cumprod = torch.cumprod(1.0 - self.betas, dim=0)

    def noise_shape(self, n: int, horizon: int, dim: int = 2) -> tuple[int, ...]:
        """Shape of the `noise` argument of `sample`: the start sample, then one draw per step with t > 0."""
        return (self.steps, n, horizon, dim)

    def sample(self, denoiser, cond: torch.Tensor, horizon: int, dim: int = 2, *, noise: torch.Tensor | None = None,
               generator: torch.Generator | None = None) -> torch.Tensor:
        """`denoiser(x, t, cond) -> eps`; returns the normalised sample `[N, horizon, dim]`.

        `noise` `[steps, N, horizon, dim]`: `noise[0]` is x_T, `noise[k]` the draw added at the k-th step
        (steps T-1 .. 1 in order); drawn from `generator` when not given. Differentiable (wrap in `no_grad`
        for sampling only); all-zero `noise` gives the deterministic chain the PPO mean uses."""
        n = cond.shape[0]
        shape = self.noise_shape(n, horizon, dim)
        if noise is None:
            noise = torch.randn(shape, generator=generator, device=cond.device, dtype=cond.dtype)
        elif tuple(noise.shape) != shape:
            raise ValueError(f"DDPMSampler.sample: noise must be {shape}, got {tuple(noise.shape)}")
        ac = self.alphas_cumprod.to(cond.device)
        x = noise[0]
        for k, t in enumerate(range(self.steps - 1, -1, -1)):
            eps = denoiser(x, torch.tensor(t, device=cond.device), cond)
            a_t = ac[t]
            a_prev = ac[t - 1] if t > 0 else torch.ones((), device=cond.device)
            alpha = a_t / a_prev
            beta = 1 - alpha
            x0 = ((x - (1 - a_t).sqrt() * eps) / a_t.sqrt()).clamp(-1, 1)
            mean = (a_prev.sqrt() * beta / (1 - a_t)) * x0 + (alpha.sqrt() * (1 - a_prev) / (1 - a_t)) * x
            if t > 0:
                var = ((1 - a_prev) / (1 - a_t) * beta).clamp(min=1e-20)
                mean = mean + var.sqrt() * noise[k + 1]
            x = mean
        return x
