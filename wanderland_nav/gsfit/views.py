"""Posed training/evaluation images at a chosen resolution, as tensors ready for `render()`.

Why a separate step: images are decoded and resized once (not every iteration), the intrinsics
are rescaled consistently with the pixels, and the held-out sets the paper evaluates on are
made explicit:
- "train": the scene's train split minus every `holdout_every`-th camera;
- "interp": those held-out cameras, which lie *inside* the training trajectory (interpolation);
- "extrap": the scene's val split, which the demo places off the trajectory (extrapolation).

Tensors: images [H, W, 3] float32 in [0, 1], masks [H, W, 1] bool (True = valid pixel),
cam_from_world [4, 4] float32 (scene frame -> OpenCV camera), K [3, 3] float32.

Lens distortion (`Camera.distortion`) is removed here (`gsfit.undistort`): the view holds the image
resampled onto the ideal pinhole / equidistant-fisheye model the renderer draws, and says so
(`View.undistorted`, one log line per distortion model).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
from PIL import Image

from wanderland_nav.gsfit.undistort import has_distortion, undistort_view_arrays

log = logging.getLogger(__name__)
_LOGGED_MODELS: set[str] = set()  # distortion models already announced in the log


@dataclass
class View:
    name: str
    image: torch.Tensor  # [H, W, 3] float32 in [0, 1]
    mask: torch.Tensor  # [H, W, 1] bool
    cam_from_world: torch.Tensor  # [4, 4]
    K: torch.Tensor  # [3, 3]
    width: int
    height: int
    camera_model: str
    undistorted: bool = False  # the image was resampled from the camera's distortion onto the ideal model

    @property
    def shape_key(self) -> tuple[int, int, str]:
        return (self.width, self.height, self.camera_model)


def scaled_intrinsics(K: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """Intrinsics after resizing by (sx, sy): K' = diag(sx, sy, 1) K.

    COLMAP / gsplat convention: pixel i covers [i, i+1) and its centre is i + 0.5 (the demo and
    Wanderland write cx = W / 2), so continuous image coordinates simply scale.
    """
    return np.diag([sx, sy, 1.0]) @ np.asarray(K, dtype=np.float64)


def target_size(width: int, height: int, downscale: float, max_width: int | None) -> tuple[int, int]:
    """Output (w, h): divide by `downscale`, then cap the width at `max_width` keeping the aspect."""
    if downscale <= 0:
        raise ValueError(f"fit.downscale must be positive, got {downscale}")
    w, h = width / downscale, height / downscale
    if max_width is not None and w > max_width:
        h, w = h * max_width / w, float(max_width)
    return max(1, int(round(w))), max(1, int(round(h)))


def _read_rgb(path: Path, size: tuple[int, int], what: str) -> torch.Tensor:
    try:
        with Image.open(path) as im:
            im = im.convert("RGB")
            if im.size != size:
                im = im.resize(size, Image.Resampling.BOX if im.size[0] > size[0] else Image.Resampling.BILINEAR)
            a = np.asarray(im, dtype=np.uint8)
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: cannot read {what}: {e}") from e
    return torch.from_numpy(a.astype(np.float32) / 255.0)


def _read_mask(path: Path | None, size: tuple[int, int]) -> torch.Tensor:
    """Validity mask: non-zero = valid (images_mask/ convention); all-valid when there is none."""
    if path is None or not Path(path).exists():
        return torch.ones((size[1], size[0], 1), dtype=torch.bool)
    try:
        with Image.open(path) as im:
            a = np.asarray(im.convert("L").resize(size, Image.Resampling.NEAREST))
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: cannot read mask: {e}") from e
    return torch.from_numpy(a > 127)[..., None]


def load_view(camera, downscale: float = 1.0, max_width: int | None = None) -> View:
    """One scene `Camera` -> `View` (image and mask resized, K rescaled)."""
    if camera.image_path is None or not Path(camera.image_path).exists():
        raise ValueError(f"camera {camera.name}: image_path {camera.image_path} does not exist")
    w, h = target_size(camera.width, camera.height, downscale, max_width)
    K = scaled_intrinsics(camera.K, w / camera.width, h / camera.height)
    world_from_cam = np.asarray(camera.world_from_cam, dtype=np.float64)
    if world_from_cam.shape != (4, 4):
        raise ValueError(f"camera {camera.name}: world_from_cam must be [4,4], got {world_from_cam.shape}")
    image = _read_rgb(Path(camera.image_path), (w, h), "image")
    mask = _read_mask(camera.mask_path, (w, h))
    distortion = getattr(camera, "distortion", None)
    undistorted = has_distortion(camera.camera_model, distortion)
    if undistorted:  # distortion coefficients act on normalised coordinates: unchanged by the resize
        image, mask = undistort_view_arrays(image, mask, K, distortion, camera.camera_model)
        kind = "OpenCV fisheye k1..k4" if camera.camera_model == "fisheye" else "OpenCV radial-tangential k1,k2,p1,p2"
        if kind not in _LOGGED_MODELS:
            _LOGGED_MODELS.add(kind)
            log.info("camera %s (and others with %s distortion): images undistorted onto the ideal %s model "
                     "for fitting; pixels with no source are masked out", camera.name, kind, camera.camera_model)
    return View(
        name=camera.name, image=image, mask=mask,
        cam_from_world=torch.from_numpy(np.linalg.inv(world_from_cam).astype(np.float32)),
        K=torch.from_numpy(K.astype(np.float32)),
        width=w, height=h, camera_model=camera.camera_model, undistorted=undistorted,
    )


def split_cameras(cameras: Sequence, holdout_every: int) -> dict[str, list]:
    """{"train", "interp", "extrap"} camera lists (see module docstring); order preserved.

    holdout_every <= 0 keeps every train camera for training (no interpolation set).
    """
    train_all = [c for c in cameras if c.split == "train"]
    extrap = [c for c in cameras if c.split == "val"]
    if holdout_every > 0:
        interp = [c for i, c in enumerate(train_all) if i % holdout_every == holdout_every // 2]
        held = {id(c) for c in interp}
        train = [c for c in train_all if id(c) not in held]
    else:
        interp, train = [], train_all
    if not train:
        raise ValueError("no training cameras: the scene has no camera with split == 'train'")
    return {"train": train, "interp": interp, "extrap": extrap}


def stack(views: Sequence[View]) -> dict[str, torch.Tensor]:
    """Batch views of one shape: images [C,H,W,3], masks [C,H,W,1], cam_from_world [C,4,4], K [C,3,3]."""
    keys = {v.shape_key for v in views}
    if len(keys) != 1:
        raise ValueError(f"cannot batch views of different sizes/camera models: {sorted(keys)}")
    return {
        "images": torch.stack([v.image for v in views]),
        "masks": torch.stack([v.mask for v in views]),
        "cam_from_world": torch.stack([v.cam_from_world for v in views]),
        "K": torch.stack([v.K for v in views]),
    }
