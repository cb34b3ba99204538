"""Fit 3D Gaussians to posed images, initialised from the metric point cloud (paper Section 3.3).

One readable loop (INRIA 3DGS, with the paper's changes):
    init from LiDAR points -> depth prior from the initial Gaussians (cached) ->
    for step: pick camera(s) -> render RGB + expected depth -> loss (L1, D-SSIM, inverse depth,
    scale reg) on valid pixels -> Adam (one param group per attribute, Table I learning rates) ->
    [densify/prune] -> [checkpoint]
    -> export INRIA 3dgs.ply.

Options the paper ablates or that real captures need: `frozen_means` (means not optimised),
`pose_refine` (a per-camera se(3) correction optimised through the view-matrix gradients),
`densify.enabled` (clone/split/prune), validity masks from images_mask/.

Frames: Gaussians and cameras in the scene frame; `cam_from_world` [C, 4, 4] OpenCV axes.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from tqdm.auto import tqdm

from wanderland_nav.atomic import atomic_path
from wanderland_nav.errors import WanderlandInputError, torch_load
from wanderland_nav.geometry import quat_to_rotmat
from wanderland_nav.gsfit.cull import visible_gaussians
from wanderland_nav.gsfit.depth_prior import depth_priors
from wanderland_nav.gsfit.init import InitSettings, active_sh_degree, init_params
from wanderland_nav.gsfit.losses import LossWeights, inverse_depth_valid, total_loss
from wanderland_nav.gsfit.metrics import psnr
from wanderland_nav.gsfit.views import View, load_view, split_cameras, stack
from wanderland_nav.render import Gaussians, render

PARAM_NAMES = ("means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest")


@dataclass(frozen=True)
class LearningRates:
    """Adam learning rates per attribute; defaults are the paper's Table I."""

    means: float = 1.6e-5
    log_scales: float = 1e-3
    quats: float = 1e-3
    opacity_logits: float = 2e-2
    sh_dc: float = 5e-4
    sh_rest: float = 1.25e-4
    pose: float = 1e-4  # se(3) camera corrections (not in Table I; gsplat uses 1e-5..1e-4)
    means_scale_by_extent: bool = True  # INRIA: means lr x scene extent, so lr is scale-free
    means_final_ratio: float = 0.01  # exponential decay of the means lr to this fraction at the end


@dataclass(frozen=True)
class DensifySettings:
    """INRIA-style adaptive density control (off by default: LiDAR init is already dense)."""

    enabled: bool = False
    start: int = 500
    stop: int = 15_000
    every: int = 100
    grad_threshold: float = 2e-4  # mean NDC-space positional gradient that triggers clone/split
    percent_dense: float = 0.01  # clone if max scale <= this x extent, else split
    split_factor: float = 1.6  # split children have scale / this
    prune_opacity: float = 0.005
    prune_scale_extent: float | None = None  # prune Gaussians larger than this x extent (None: off;
    # LiDAR init legitimately makes large splats in sparse far regions)
    max_gaussians: int = 2_000_000


@dataclass(frozen=True)
class FitConfig:
    iterations: int = 3000
    seed: int = 0
    device: str = "cpu"
    downscale: float = 1.0  # image resolution divisor (CPU-friendly training)
    max_width: int | None = 128  # cap on the training width (pixels); None: full resolution
    holdout_every: int = 8  # every k-th train camera is held out as an interpolation view
    cameras_per_step: int = 1
    sh_increase_every: int = 1000
    frozen_means: bool = False
    use_depth: bool = True  # inverse-depth loss against the initial-Gaussian depth prior
    depth_min_alpha: float = 0.5  # prior pixels with less accumulated alpha are invalid
    pose_refine: bool = False
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    checkpoint_every: int = 1000  # 0 disables periodic checkpoints (a final one is always written)
    time_limit_s: float | None = None  # stop early (then checkpoint + export) after this wall time
    init: InitSettings = field(default_factory=InitSettings)
    lr: LearningRates = field(default_factory=LearningRates)
    loss: LossWeights = field(default_factory=LossWeights)
    densify: DensifySettings = field(default_factory=DensifySettings)


def _default_render():
    return render


def _skew(w: torch.Tensor) -> torch.Tensor:
    """[C, 3] -> [C, 3, 3] cross-product matrices."""
    z = torch.zeros_like(w[:, 0])
    return torch.stack([z, -w[:, 2], w[:, 1], w[:, 2], z, -w[:, 0], -w[:, 1], w[:, 0], z], dim=-1).view(-1, 3, 3)


def se3_exp(xi: torch.Tensor) -> torch.Tensor:
    """Small rigid corrections [C, 6] (rotation vector, translation) -> [C, 4, 4].

    Rodrigues with a Taylor branch near zero so the gradient at the zero initialisation is exact.
    """
    w, v = xi[:, :3], xi[:, 3:]
    th2 = (w * w).sum(-1)
    th = torch.sqrt(th2.clamp_min(1e-12))
    small = th2 < 1e-6
    a = torch.where(small, 1 - th2 / 6, torch.sin(th) / th)
    b = torch.where(small, 0.5 - th2 / 24, (1 - torch.cos(th)) / th2.clamp_min(1e-12))
    S = _skew(w)
    R = torch.eye(3, dtype=xi.dtype, device=xi.device) + a[:, None, None] * S + b[:, None, None] * (S @ S)
    T = torch.zeros(xi.shape[0], 4, 4, dtype=xi.dtype, device=xi.device)
    T[:, :3, :3] = R
    T[:, :3, 3] = v
    T[:, 3, 3] = 1
    return T


def scene_extent(cam_centers: np.ndarray) -> float:
    """INRIA's `cameras_extent`: 1.1 x max distance of a camera centre from their mean (>= 1 m)."""
    c = np.asarray(cam_centers, dtype=np.float64)
    return max(1.0, 1.1 * float(np.linalg.norm(c - c.mean(0), axis=1).max()))


class Trainer:
    """Holds the Gaussians, optimiser and data of one fit; `train()` runs it to the end.

    `render_fn` follows `wanderland_nav.render.render`'s signature (injected so a gsplat backend
    can be swapped in); `log_fn(step, scalars, images)` receives training logs (e.g. rerun).
    """

    def __init__(self, scene, out_dir: str | Path, config: FitConfig = FitConfig(), *,
                 render_fn: Callable | None = None, log_fn: Callable | None = None,
                 progress: bool = True, resume: bool = True):
        self.cfg = config
        self.out_dir = Path(out_dir)
        self.render_fn = render_fn or _default_render()
        self.log_fn = log_fn
        self.progress = progress
        self.device = torch.device(config.device)
        torch.manual_seed(config.seed)

        cams = split_cameras(scene.cameras, config.holdout_every)
        self.views: dict[str, list[View]] = {
            k: [load_view(c, config.downscale, config.max_width) for c in v] for k, v in cams.items()}
        train = self.views["train"]
        if config.cameras_per_step > 1 and len({v.shape_key for v in train}) > 1:
            raise ValueError("fit.cameras_per_step > 1 needs all training cameras at one size and model")
        centers = np.stack([np.linalg.inv(v.cam_from_world.double().numpy())[:3, 3] for v in train])
        self.extent = scene_extent(centers)

        p = init_params(scene.points, scene.colors, config.init, config.seed)
        self.params = {k: torch.nn.Parameter(p[k].to(self.device)) for k in PARAM_NAMES}
        self.initial_gaussians = self.gaussians().detach()
        self.pose_deltas = torch.nn.Parameter(torch.zeros(len(train), 6, device=self.device))

        self.depth_prior: list[torch.Tensor] | None = None
        if config.use_depth and config.loss.depth > 0:
            self.depth_prior = depth_priors(self.initial_gaussians, train, self.render_fn,
                                            cache_path=self.out_dir / "depth_prior.pt",
                                            min_alpha=config.depth_min_alpha)

        self.step = 0
        self.gen = torch.Generator().manual_seed(config.seed)
        self._order: list[int] = []
        self._reset_density_stats()
        self.optimizer = self._make_optimizer()
        if resume and self.checkpoint_path.exists():
            self.load_checkpoint(self.checkpoint_path)

    # ---- model ---------------------------------------------------------------------------
    def gaussians(self, sh_degree: int | None = None):
        """Current Gaussians (sharing storage with the parameters), SH truncated to `sh_degree`."""
        rest = self.params["sh_rest"]
        if sh_degree is not None:
            rest = rest[:, : (sh_degree + 1) ** 2 - 1]
        return Gaussians(self.params["means"], self.params["log_scales"], self.params["quats"],
                         self.params["opacity_logits"], self.params["sh_dc"], rest)

    def _lr(self, name: str) -> float:
        lr = getattr(self.cfg.lr, name)
        if name == "means" and self.cfg.lr.means_scale_by_extent:
            lr *= self.extent
        return lr

    def _make_optimizer(self) -> torch.optim.Adam:
        groups = []
        for name in PARAM_NAMES:
            if name == "means" and self.cfg.frozen_means:
                # frozen means keep requires_grad only when densification needs their gradient
                self.params[name].requires_grad_(self.cfg.densify.enabled)
                continue
            groups.append({"params": [self.params[name]], "lr": self._lr(name), "name": name})
        if self.cfg.pose_refine:
            groups.append({"params": [self.pose_deltas], "lr": self.cfg.lr.pose, "name": "pose"})
        else:
            self.pose_deltas.requires_grad_(False)
        return torch.optim.Adam(groups, lr=0.0, eps=1e-15)

    def _set_means_lr(self) -> None:
        """Exponential decay of the means learning rate to `means_final_ratio` at the last step."""
        t = min(1.0, self.step / max(1, self.cfg.iterations))
        for g in self.optimizer.param_groups:
            if g["name"] == "means":
                g["lr"] = self._lr("means") * (self.cfg.lr.means_final_ratio ** t)

    # ---- data ----------------------------------------------------------------------------
    def _next_cameras(self) -> list[int]:
        """Cameras for this step: a fresh seeded permutation every epoch, as INRIA does."""
        out = []
        while len(out) < self.cfg.cameras_per_step:
            if not self._order:
                self._order = torch.randperm(len(self.views["train"]), generator=self.gen).tolist()
            out.append(self._order.pop())
        return out

    def _viewmats(self, views: list[View], idx: list[int] | None) -> torch.Tensor:
        vm = torch.stack([v.cam_from_world for v in views]).to(self.device)
        if self.cfg.pose_refine and idx is not None:
            vm = se3_exp(self.pose_deltas[idx]) @ vm
        return vm

    def _background(self, c: int) -> torch.Tensor:
        return torch.tensor(self.cfg.background, dtype=torch.float32, device=self.device).expand(c, 3)

    # ---- one step ------------------------------------------------------------------------
    def train_step(self) -> dict[str, float]:
        cfg = self.cfg
        idx = self._next_cameras()
        views = [self.views["train"][i] for i in idx]
        batch = {k: t.to(self.device) for k, t in stack(views).items()}
        need_depth = self.depth_prior is not None
        sh = active_sh_degree(self.step, cfg.sh_increase_every, cfg.init.sh_degree)
        w, h, model = views[0].shape_key
        viewmats = self._viewmats(views, idx)
        g = visible_gaussians(self.gaussians(sh), viewmats, batch["K"], w, h, camera_model=model)
        out = self.render_fn(g, viewmats, batch["K"], w, h,
                             render_mode="RGB+ED" if need_depth else "RGB",
                             background=self._background(len(idx)), camera_model=model)
        prior = valid = None
        if need_depth:
            prior = torch.stack([self.depth_prior[i] for i in idx]).to(self.device)
            valid = inverse_depth_valid(prior, batch["masks"])
        loss, parts = total_loss(out.rgb, batch["images"], batch["masks"], weights=cfg.loss,
                                 log_scales=self.params["log_scales"], depth=out.depth,
                                 depth_prior=prior, depth_valid=valid)
        loss.backward()
        if cfg.densify.enabled:
            self._accumulate_density_stats(batch["cam_from_world"][0], batch["K"][0], w)
        self._set_means_lr()
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        self.params["means"].grad = None
        self.step += 1
        d = cfg.densify
        if d.enabled and d.start <= self.step < d.stop and self.step % d.every == 0:
            self.densify_and_prune()
        with torch.no_grad():
            parts["psnr"] = float(psnr(out.rgb.detach().clamp(0, 1), batch["images"], batch["masks"]).mean())
        parts["sh_degree"] = sh
        if self.log_fn is not None:
            self.log_fn(self.step, parts, {"render": out.rgb[0].detach(), "target": batch["images"][0]})
        return parts

    # ---- densify / prune -----------------------------------------------------------------
    def _reset_density_stats(self) -> None:
        n = len(self.params["means"]) if hasattr(self, "params") else 0
        self._grad_accum = torch.zeros(n, device=self.device)
        self._grad_count = torch.zeros(n, device=self.device)

    @torch.no_grad()
    def _accumulate_density_stats(self, cam_from_world: torch.Tensor, K: torch.Tensor, width: int) -> None:
        """Approximate INRIA's NDC-space positional gradient from the 3D means gradient.

        |dL/dpixel| = |dL/dmean3d| * z / f for a lateral move; NDC scales pixels by W / 2.
        """
        g = self.params["means"].grad
        if g is None:
            return
        z = (self.params["means"] @ cam_from_world[:3, :3].T + cam_from_world[:3, 3])[:, 2]
        gn = g.norm(dim=-1) * z.clamp_min(1e-3) * (0.5 * width / K[0, 0])
        seen = (g.abs().sum(-1) > 0) & (z > 0)
        self._grad_accum += torch.where(seen, gn, torch.zeros_like(gn))
        self._grad_count += seen.float()

    @torch.no_grad()
    def densify_and_prune(self) -> dict[str, int]:
        """Clone small / split large high-gradient Gaussians, prune transparent or huge ones."""
        d = self.cfg.densify
        p = {k: v.detach() for k, v in self.params.items()}
        n = len(p["means"])
        avg = self._grad_accum / self._grad_count.clamp_min(1)
        smax = p["log_scales"].exp().max(dim=-1).values
        high = avg >= d.grad_threshold
        budget = max(0, d.max_gaussians - n) // 2  # never exceed the cap (a split adds 2, removes 1)
        if int(high.sum()) > budget:
            top = torch.topk(torch.where(high, avg, torch.full_like(avg, -1.0)), budget).indices
            high = torch.zeros_like(high)
            high[top] = True
        clone = high & (smax <= d.percent_dense * self.extent)
        split = high & ~clone
        prune = torch.sigmoid(p["opacity_logits"]) < d.prune_opacity
        if d.prune_scale_extent is not None:
            prune |= smax > d.prune_scale_extent * self.extent
        keep = ~(prune | split)  # split parents are replaced by their two children
        extra: dict[str, list[torch.Tensor]] = {k: [p[k][clone]] for k in PARAM_NAMES}
        if split.any():
            ps = {k: p[k][split] for k in PARAM_NAMES}
            R = quat_to_rotmat(torch.nn.functional.normalize(ps["quats"], dim=-1))  # [S, 3, 3]
            std = ps["log_scales"].exp()
            for _ in range(2):  # two children sampled inside the parent
                eps = torch.randn(std.shape, generator=self.gen).to(std) * std
                for k in PARAM_NAMES:
                    if k == "means":
                        extra[k].append(ps[k] + (R @ eps[..., None])[..., 0])
                    elif k == "log_scales":
                        extra[k].append(ps[k] - math.log(d.split_factor))
                    else:
                        extra[k].append(ps[k])
        self._replace_params(keep, {k: torch.cat(v) for k, v in extra.items()})
        self._reset_density_stats()
        return {"cloned": int(clone.sum()), "split": int(split.sum()), "pruned": int((prune & ~split).sum()),
                "total": len(self.params["means"])}

    def _replace_params(self, keep: torch.Tensor, extra: dict[str, torch.Tensor]) -> None:
        """Select `keep` rows, append `extra` rows, and carry Adam moments along (zeros for new)."""
        for group in self.optimizer.param_groups:
            name = group["name"]
            if name == "pose":
                continue
            old = group["params"][0]
            new = torch.nn.Parameter(torch.cat([old.detach()[keep], extra[name]]))
            state = self.optimizer.state.pop(old, None)
            if state:
                for key in ("exp_avg", "exp_avg_sq"):
                    state[key] = torch.cat([state[key][keep], torch.zeros_like(extra[name])])
                self.optimizer.state[new] = state
            group["params"][0] = new
            self.params[name] = new
        for name in PARAM_NAMES:  # frozen means are not in the optimiser
            if self.params[name].shape[0] != len(self.params["sh_dc"]):
                old = self.params[name]
                self.params[name] = torch.nn.Parameter(torch.cat([old.detach()[keep], extra[name]]),
                                                       requires_grad=old.requires_grad)

    # ---- checkpoints ---------------------------------------------------------------------
    @property
    def checkpoint_path(self) -> Path:
        return self.out_dir / "checkpoints" / "latest.pt"

    def save_checkpoint(self) -> Path:
        blob = {
            "step": self.step,
            "params": {k: v.detach().cpu() for k, v in self.params.items()},
            "pose_deltas": self.pose_deltas.detach().cpu(),
            "optimizer": self.optimizer.state_dict(),
            "generator": self.gen.get_state(),
            "order": list(self._order),
            "grad_accum": self._grad_accum.cpu(),
            "grad_count": self._grad_count.cpu(),
            "config": asdict(self.cfg),
        }
        with atomic_path(self.checkpoint_path) as tmp:
            torch.save(blob, tmp)
        return self.checkpoint_path

    def load_checkpoint(self, path: Path) -> None:
        blob = torch_load(path, what="gsfit checkpoint", map_location=self.device)
        try:
            params = blob["params"]
            for k in PARAM_NAMES:
                self.params[k] = torch.nn.Parameter(params[k].to(self.device))
            self.pose_deltas = torch.nn.Parameter(blob["pose_deltas"].to(self.device))
            self.optimizer = self._make_optimizer()
            self.optimizer.load_state_dict(blob["optimizer"])
            self.step = int(blob["step"])
            self.gen.set_state(blob["generator"])
            self._order = list(blob["order"])
            self._grad_accum = blob["grad_accum"].to(self.device)
            self._grad_count = blob["grad_count"].to(self.device)
        except (KeyError, TypeError, ValueError, RuntimeError) as e:
            raise WanderlandInputError(f"not a compatible gsfit checkpoint ({e})", path=path) from e

    # ---- the loop ------------------------------------------------------------------------
    def train(self) -> dict[str, float]:
        """Run to `iterations` (or the time limit), checkpoint, export 3dgs.ply; returns a summary."""
        cfg = self.cfg
        t0, c0 = time.perf_counter(), time.process_time()
        bar = tqdm(total=cfg.iterations, initial=self.step, disable=not self.progress, desc="fit", dynamic_ncols=True)
        ema = None
        while self.step < cfg.iterations:
            parts = self.train_step()
            ema = parts["psnr"] if ema is None else 0.9 * ema + 0.1 * parts["psnr"]
            bar.update(1)
            if self.step % 10 == 0:
                bar.set_postfix(loss=f"{parts['total']:.4f}", psnr=f"{ema:.2f}", n=len(self.params["means"]))
            if cfg.checkpoint_every and self.step % cfg.checkpoint_every == 0:
                self.save_checkpoint()
            if cfg.time_limit_s is not None and time.perf_counter() - t0 > cfg.time_limit_s:
                break
        bar.close()
        self.save_checkpoint()
        self.export(self.out_dir / "3dgs.ply")
        # process CPU time (all threads) next to wall time: on a shared machine wall time says little
        return {"step": self.step, "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
                "num_gaussians": len(self.params["means"]),
                "train_psnr_ema": float(ema) if ema is not None else float("nan")}

    def export(self, path: Path) -> Path:
        """INRIA 3dgs.ply of the current Gaussians (full stored SH degree), written atomically."""
        self.gaussians().detach().to("cpu").save(path)
        return Path(path)
