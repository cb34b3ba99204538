"""The agent's head camera: intrinsics, poses, and batched rendering through the splat renderer.

Why a module of its own: the same camera renders the agents' observations, the goal views of
image-goal episodes and the benchmark, and it is where the nav frame meets the scene frame for
rendering (`geometry.agent_camera_poses` returns scene-frame `world_from_cam`, the renderer wants
`cam_from_world`, gsplat's `viewmats`).

Intrinsics: square pixels, principal point at the image centre. Pinhole: `f = (W/2) / tan(hfov/2)`;
fisheye (equidistant, `r = f * theta`, gsplat's fisheye model): `f = (W/2) / (hfov/2)`.
"""

from __future__ import annotations

import functools
import math
import os
from typing import Callable

import numpy as np
import torch

from wanderland_nav.envs.config import CameraConfig
from wanderland_nav.geometry import agent_camera_poses, invert_rigid, pinhole_intrinsics
from planners.threads import intra_op_threads, single_thread
from wanderland_nav.render import fused
from wanderland_nav.render.shards import map_single_threaded

Renderer = Callable[..., object]
"""`render(gaussians, cam_from_world[C,4,4], K[C,3,3], width, height, *, render_mode, background,
camera_model[, backend, threads]) -> obj with .rgb [C,H,W,3] float in [0,1], .depth [C,H,W,1] or None`
(render.render); `backend` is passed only when the camera's backend is not "torch", `threads` with "fused".
The "fused" backend (the default) is used where `render.fused.supports` the splat (CPU float32 Gaussians or a
hierarchy); anything else (another renderer's own scene object, a CUDA splat) gets the "torch" protocol."""


def camera_intrinsics(cfg: CameraConfig) -> torch.Tensor:
    """`K [3, 3]` float32 for the configured resolution, field of view and camera model."""
    return torch.as_tensor(pinhole_intrinsics(cfg.width, cfg.height, cfg.hfov_deg, cfg.camera_model), dtype=torch.float32)


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def group_size(B: int, render_chunk: int) -> int:
    """Cameras per renderer call: at most `render_chunk`, and at most half of B, so that two threads
    have work at the training batch (B = 8). Never depends on the thread count (same images for any)."""
    return max(1, min(render_chunk, -(-B // 2)))


class AgentCamera:
    """Renders what agents at nav-frame poses see, `render_chunk` cameras per renderer call, groups on
    `workers()` threads."""

    def __init__(self, cfg: CameraConfig, nav_from_scene: np.ndarray, renderer: Renderer, gaussians, device):
        self.cfg = cfg
        self.device = torch.device(device)
        self.nav_from_scene = torch.as_tensor(np.asarray(nav_from_scene), dtype=torch.float32, device=self.device)
        self.K = camera_intrinsics(cfg).to(self.device)
        self.renderer = renderer
        self.gaussians = gaussians
        self.background = torch.tensor(cfg.background, dtype=torch.float32, device=self.device)
        self.caller_threads: int | None = None  # the env caller's intra-op threads while NavEnv runs its ops on one
        self.to(self.device)  # the Gaussians render where the camera is

    def to(self, device) -> "AgentCamera":
        """Intrinsics, pose frame, background and Gaussians (anything with `.to(device)`) onto `device`."""
        self.device = torch.device(device)
        self.nav_from_scene, self.K = self.nav_from_scene.to(self.device), self.K.to(self.device)
        self.background = self.background.to(self.device)
        if self.gaussians is not None and hasattr(self.gaussians, "to"):
            self.gaussians = self.gaussians.to(self.device)
        return self

    def cam_from_world(self, position_nav: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
        """position_nav `[B, 3]` (feet), yaw `[B]` -> `cam_from_world [B, 4, 4]` in the scene frame."""
        world_from_cam = agent_camera_poses(
            position_nav.float(),
            yaw.float(),
            height=self.cfg.mount_height,
            pitch=math.radians(self.cfg.pitch_deg),
            nav_from_scene=self.nav_from_scene,
        )
        return invert_rigid(world_from_cam)

    def workers(self) -> int:
        """Threads that render groups concurrently: `render_threads`, else the CPU cores this process may
        use. Not torch's intra-op count: each group runs on one intra-op thread with no barrier, so the
        groups use the cores even when `threads=1` keeps the small policy / env ops off the OpenMP pool
        (which collapses under load: experiments/env/README.md)."""
        return self.cfg.render_threads if self.cfg.render_threads is not None else available_cores()

    @torch.no_grad()
    def render(self, position_nav: torch.Tensor, yaw: torch.Tensor, rows: torch.Tensor | None = None, extra=None):
        """-> rgb uint8 `[B, H, W, 3]`, depth float32 `[B, H, W, 1]` (0 where empty) or None.

        rows: bool `[B]`, the cameras to render; the others get black frames and zero depth (agents whose
        frames nobody reads, e.g. an evaluation's episodes past the last one it counts). None: all.
        extra: per-camera Gaussians `[B, M]` (`render.overlay.CameraGaussians`: the pedestrians each camera's
        env instance holds), composited into the same renderer calls; None renders the scene alone.

        The fused backend renders all B cameras in one call, `workers()` cameras at a time (its memory is per
        camera). The others render groups of `group_size(B, render_chunk)` (one batched renderer call each,
        which bounds peak memory); the groups never depend on the thread count. On CPU with the eager
        backend, `workers()` threads render them concurrently on one intra-op thread each
        (`render.shards`): same images for any thread count."""
        if rows is not None and not bool(rows.all()):
            idx = rows.nonzero().squeeze(1)
            part_rgb, part_depth = self.render(position_nav.index_select(0, idx), yaw.index_select(0, idx),
                                               extra=None if extra is None else extra.rows_at(idx))
            rgb = part_rgb.new_zeros((rows.shape[0],) + part_rgb.shape[1:]).index_copy_(0, idx, part_rgb)
            depth = None if part_depth is None else part_depth.new_zeros(
                (rows.shape[0],) + part_depth.shape[1:]).index_copy_(0, idx, part_depth)
            return rgb, depth
        B = position_nav.shape[0]
        H, W = self.cfg.height, self.cfg.width
        rgb = torch.empty(B, H, W, 3, dtype=torch.uint8, device=self.device)
        depth = torch.empty(B, H, W, 1, dtype=torch.float32, device=self.device) if self.cfg.depth else None
        if B == 0 or not self.cfg.enabled:
            rgb.zero_()
            if depth is not None:
                depth.zero_()
            return rgb, depth
        viewmats = self.cam_from_world(position_nav, yaw)
        if self.backend() == "fused":
            self._render_group(viewmats, rgb, depth, 0, B, extra=extra)
            return rgb, depth
        size = group_size(B, self.cfg.render_chunk)
        groups = [(s, min(B, s + size)) for s in range(0, B, size)]
        render_group = lambda g: self._render_group(viewmats, rgb, depth, *g, extra=extra)  # noqa: E731
        if self.device.type == "cpu" and self.backend() == "torch":
            map_single_threaded(render_group, groups, self.workers())
        else:  # GPU and compiled kernels schedule their own threads (on CPU: the env caller's intra-op threads)
            with intra_op_threads(self.caller_threads or torch.get_num_threads()):
                for g in groups:
                    render_group(g)
        return rgb, depth

    def backend(self) -> str:
        """The backend the camera renders with: `render_backend`, except "fused" where the kernel does not take
        the splat (`render.fused.supports`) or cannot be built (one warning), which renders on the "torch" path."""
        b = self.cfg.render_backend
        if b == "fused" and not (fused.supports(self.gaussians, self.cfg.camera_model) and fused.available()):
            return "torch"
        return b

    def _render_group(self, viewmats: torch.Tensor, rgb: torch.Tensor, depth: torch.Tensor | None, s: int, e: int,
                      extra=None):
        """Render cameras `s:e` of `viewmats [B, 4, 4]` into rows `s:e` of `rgb` / `depth` (disjoint per group)."""
        H, W = self.cfg.height, self.cfg.width
        people = extra
        backend = self.backend()
        extra = {} if backend == "torch" else {"backend": backend}
        if backend == "fused":
            extra["threads"] = self.workers()
        if people is not None:
            extra["extra"] = people.rows(s, e)
        out = self.renderer(
            self.gaussians,
            viewmats[s:e],
            self.K.expand(e - s, 3, 3),
            W,
            H,
            render_mode="RGB+ED" if self.cfg.depth else "RGB",
            background=self.background,
            camera_model=self.cfg.camera_model,
            **extra,
        )
        rgb[s:e] = (out.rgb.clamp(0.0, 1.0) * 255.0 + 0.5).to(torch.uint8)
        if depth is not None:
            d = out.depth if out.depth is not None else torch.zeros(e - s, H, W, 1, device=self.device)
            depth[s:e] = torch.nan_to_num(d.float(), nan=0.0, posinf=0.0, neginf=0.0)


def one_intra_op_thread(method):
    """Run an env call, TorchRL's bookkeeping included, on one intra-op thread: apart from rendering, all
    its work is small `[B]` / `[B, T, H, W, 3]` tensor ops, which a thread pool only slows down, and on
    a loaded machine by milliseconds per op (`planners/threads.py`). The camera's render groups run on
    their own threads (`AgentCamera.workers`: one intra-op thread each; a compiled or GPU backend gets the
    caller's intra-op count back, `AgentCamera.caller_threads`). Measured in
    `experiments/env/README.md`. Nested entry points (`step_and_maybe_reset`
    calls `step`) keep the outermost caller's count."""

    @functools.wraps(method)
    def run(self, *args, **kwargs):
        if torch.get_num_threads() == 1 and self.camera.caller_threads is not None:  # nested, or a 1-thread caller
            return method(self, *args, **kwargs)
        self.camera.caller_threads = torch.get_num_threads()
        try:
            with single_thread():
                return method(self, *args, **kwargs)
        finally:
            self.camera.caller_threads = None

    return run
