"""Plausibility checks that catch a wrong frame before it becomes a silently wrong navmesh.

* `up_axis_evidence` / `check_up_axis`: which axis the data says is up. Two independent witnesses:
  the capture cameras' down vectors (OpenCV +y of each camera: people hold cameras roughly level, so
  the mean down vector points along -up) and the ground's normal distribution (local PCA normals of a
  point sample: floors, roads and ceilings share one normal axis, walls spread over the horizontal
  circle; the sign comes from the ground lying below the capture positions). A chosen axis that
  disagrees is logged as a loud warning naming both and where the choice came from.
* `empty_navmesh_reasons`: why a bake gave no walkable area (up axis, crop, agent size), so `prepare`
  can refuse to write it instead of replacing a good cached navmesh with an empty one.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.geometry import parse_up_axis
import torch

log = logging.getLogger(__name__)

AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
_ALIGNED_COS = np.cos(np.radians(25.0))  # a normal within 25 degrees of an axis counts for it


class EmptyNavMeshError(ValueError):
    """A navmesh bake produced no walkable area; the message says what to check."""


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return ("+" if v[i] > 0 else "-") + "xyz"[i]


def _ground_axis(points: np.ndarray, capture: np.ndarray, sample: int, seed: int) -> tuple[str | None, dict]:
    """Up axis from local normals of `sample` points (10 neighbours each) and the capture positions."""
    rng = np.random.default_rng(seed)
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 100:
        return None, {}
    q = p[rng.choice(len(p), size=min(sample, len(p)), replace=False)]
    _, nn = cKDTree(q).query(q, k=10)
    nb = q[nn] - q[nn].mean(1, keepdims=True)  # [S, 10, 3]
    w, vec = np.linalg.eigh(np.einsum("ski,skj->sij", nb, nb))  # ascending eigenvalues
    planar = w[:, 0] < 0.1 * w[:, 1]  # a flat neighbourhood: its normal is meaningful
    n = vec[planar, :, 0]  # [P, 3] unit normals (sign arbitrary)
    share = {a: float((np.abs(n[:, i]) > _ALIGNED_COS).mean()) if len(n) else 0.0 for i, a in enumerate("xyz")}
    axis = max(share, key=share.get)
    if share[axis] < 0.2:
        return None, share
    i = "xyz".index(axis)
    aligned = q[planar][np.abs(n[:, i]) > _ALIGNED_COS, i]
    ref = np.median(capture[:, i]) if len(capture) else np.median(q[:, i])
    below = float((aligned < ref).mean())  # the ground (most horizontal surface) lies under the sensor
    return ("+" if below >= 0.5 else "-") + axis, share


def up_axis_evidence(points, capture_positions, world_from_cams=None, *, sample: int = 20000,
                     seed: int = 0) -> dict:
    """`{"cameras": axis or None, "ground": axis or None, "ground_normal_share": {x, y, z}}`.

    points `[N,3]` and capture_positions `[M,3]` in the scene frame; world_from_cams `[C,4,4]` OpenCV
    camera poses (or None). An axis is one of `AXES`; None where the witness has nothing to say."""
    cams = None
    T = np.asarray(world_from_cams if world_from_cams is not None else np.zeros((0, 4, 4)), dtype=np.float64)
    if len(T):
        down = T[:, :3, 1].mean(0)  # OpenCV camera +y is image-down
        if np.linalg.norm(down) > 0.5:  # the cameras agree on a down direction
            cams = _axis_name(-down)
    ground, share = _ground_axis(points, np.asarray(capture_positions, dtype=np.float64).reshape(-1, 3),
                                 sample, seed)
    return {"cameras": cams, "ground": ground, "ground_normal_share": share}


def check_up_axis(scene, **kw) -> str | None:
    """Warn loudly when `scene.up_axis` disagrees with the data; returns the warning (None if it agrees)."""
    ev = up_axis_evidence(scene.points, scene.capture_positions(), scene.world_from_cams(), **kw)
    up = parse_up_axis(scene.up_axis)
    wrong = {k: v for k, v in (("capture cameras' down vectors", ev["cameras"]),
                               ("ground normals", ev["ground"])) if v is not None and v != up}
    if not wrong:
        return None
    msg = (f"{scene.root}: up axis {up} (from {scene.up_axis_source}) DISAGREES with the data: "
           + "; ".join(f"{k} say {v}" for k, v in wrong.items())
           + f". A wrong up axis gives a wrong collision mesh and an empty or wrong navmesh: set up_axis= or "
             f"scene_meta.json up_axis if {next(iter(wrong.values()))} is right.")
    log.warning("!" * 20 + " " + msg)
    return msg


def empty_navmesh_reasons(scene, navmesh_settings, collision_sidecar: dict) -> str:
    """What to check when a bake yields 0 m2: up axis (with the data's evidence), crop, agent size."""
    ev = up_axis_evidence(scene.points, scene.capture_positions(), scene.world_from_cams())
    seen = ", ".join(f"{k} say {v}" for k, v in (("cameras", ev["cameras"]), ("ground normals", ev["ground"]))
                     if v is not None) or "no evidence either way"
    s = navmesh_settings
    c = collision_sidecar or {}
    cs = c.get("settings", {})
    return (f"{scene.root}: the navmesh has no walkable area; nothing was written (a cached navmesh is kept). "
            f"Check: (1) up axis {scene.up_axis} from {scene.up_axis_source} ({seen}); "
            f"(2) crop: {c.get('points_kept', '?')} of {c.get('points_in', '?')} points kept within "
            f"crop_radius {cs.get('crop_radius', '?')} m and height_band {cs.get('height_band', '?')} of "
            f"{len(scene.capture_positions())} capture positions, {c.get('faces', '?')} collision faces; "
            f"(3) agent size: radius {s.agent_radius} m, height {s.agent_height} m, max climb "
            f"{s.agent_max_climb} m, max slope {s.agent_max_slope} deg (a floor narrower than 2 x radius "
            "or with less headroom is not walkable).")



class BlankSplatError(WanderlandInputError):
    """A splat that shows (nearly) nothing from its own capture cameras: a camera over it renders blank frames."""


def splat_visibility(gaussians, cameras, *, sample: int = 50_000, max_cameras: int = 32, min_px: float = 0.5,
                     seed: int = 0) -> dict:
    """How many of (a seeded sample of) the splat's Gaussians a capture camera would draw.

    A Gaussian counts as visible when all its parameters are finite, its opacity is at least 1/255 (one grey
    level), and in at least one of up to `max_cameras` evenly spaced capture cameras it lies in front, within the
    image (its 3-sigma footprint overlapping it) and at least `min_px` pixels across. -> counts of the sample:
    `sampled`, `nonfinite`, `transparent`, `unseen` (finite and opaque but in no view or too small), `visible`,
    and `cameras` used (0: the scene has none, and only finiteness and opacity are checked)."""

    n = len(gaussians)
    idx = torch.from_numpy(np.sort(np.random.default_rng(seed).choice(n, min(n, sample), replace=False)))
    mean, log_scale = gaussians.means[idx].float(), gaussians.log_scales[idx].float()
    params = torch.cat([mean, log_scale, gaussians.quats[idx], gaussians.opacity_logits[idx, None],
                        gaussians.sh_dc[idx]], 1).float()
    finite = torch.isfinite(params).all(1) & (gaussians.quats[idx].float().norm(dim=1) > 0)
    opaque = finite & (torch.sigmoid(gaussians.opacity_logits[idx].float()) >= 1 / 255)
    cams = list(cameras)[:: max(1, -(-len(cameras) // max_cameras))]
    seen = torch.ones_like(opaque) if not cams else torch.zeros_like(opaque)
    if cams:
        T = torch.as_tensor(np.stack([c.cam_from_world for c in cams]), dtype=torch.float32)  # [C, 4, 4]
        K = torch.as_tensor(np.stack([c.K for c in cams]), dtype=torch.float32)  # [C, 3, 3]
        wh = torch.tensor([[c.width, c.height] for c in cams], dtype=torch.float32)  # [C, 2]
        fisheye = torch.tensor([c.camera_model == "fisheye" for c in cams])[:, None]  # [C, 1]
        p = torch.einsum("cij,nj->cni", T[:, :3, :3], torch.nan_to_num(mean)) + T[:, None, :3, 3]  # [C, S, 3]
        dist = p.norm(dim=-1).clamp_min(1e-9)
        z = p[..., 2]
        f, c0 = K[:, None, [0, 1], [0, 1]], K[:, None, :2, 2]  # [C, 1, 2] focal lengths, principal point
        px = 3 * torch.nan_to_num(log_scale).exp().amax(1) * f[..., 0] / torch.where(fisheye, dist, z.clamp_min(1e-9))
        uv = f * p[..., :2] / z.clamp_min(1e-9)[..., None] + c0  # [C, S, 2] (pinhole)
        in_image = ((uv + px[..., None] >= 0) & (uv - px[..., None] <= wh[:, None])).all(-1) & (z > 1e-3)
        in_view = torch.where(fisheye, z / dist > -0.09, in_image)  # a fisheye: within 95 degrees of its axis
        seen = (in_view & (px >= min_px)).any(0)
    visible = opaque & seen
    return {"sampled": int(idx.numel()), "nonfinite": int((~finite).sum()), "transparent": int((finite & ~opaque).sum()),
            "unseen": int((opaque & ~seen).sum()), "visible": int(visible.sum()), "cameras": len(cams)}


#: below this share of visible Gaussians a splat is refused, below `SPLAT_WARN_SHARE` warned about
SPLAT_MIN_SHARE, SPLAT_WARN_SHARE = 0.01, 0.10


def check_splat_visible(gaussians, cameras, path) -> dict:
    """Refuse (`BlankSplatError`) a splat whose capture cameras would see almost none of its Gaussians, whatever
    the reason (zero or -inf opacities, NaN parameters, vanishing scales, a splat in another frame than the
    cameras); warn when few are seen. A camera over such a splat renders black frames, and a policy trained or
    evaluated on them says nothing about the scene. -> `splat_visibility`'s counts."""
    v = splat_visibility(gaussians, cameras)
    share = v["visible"] / max(v["sampled"], 1)
    what = (f"{v['visible']} of {v['sampled']} sampled Gaussians are visible from "
            + (f"{v['cameras']} capture cameras" if v["cameras"] else "anywhere (the scene has no capture cameras)")
            + f" ({v['nonfinite']} with non-finite parameters, {v['transparent']} with opacity below 1/255, "
              f"{v['unseen']} outside every view or under 0.5 px)")
    if share < SPLAT_MIN_SHARE:
        raise BlankSplatError(f"the camera would render blank frames: {what}; a splat in another frame than the "
                              "cameras (or up axis), zeroed opacities or scales give this; fix the splat or turn the "
                              "camera off (env.camera.enabled=false)", path=path)
    if share < SPLAT_WARN_SHARE:
        log.warning("%s: only %s; frames will be mostly background", path, what)
    return v
