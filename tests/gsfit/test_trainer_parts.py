"""Trainer pieces that need no rasterizer: views, se(3), config, densify surgery, checkpoints."""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch
from PIL import Image
from scipy.spatial.transform import Rotation

from wanderland_nav.errors import WanderlandInputError
from wanderland_nav.gsfit.init import InitSettings
from wanderland_nav.gsfit.trainer import DensifySettings, FitConfig, Trainer, se3_exp
from wanderland_nav.gsfit.views import load_view, scaled_intrinsics, split_cameras, target_size
from wanderland_nav.scene.types import Camera, Scene


def _scene(root, n_cams=10, w=40, h=30, n_points=300):
    g = np.random.default_rng(0)
    K = np.array([[30.0, 0, 20.0], [0, 30.0, 15.0], [0, 0, 1]])
    cams = []
    for i in range(n_cams):
        T = np.eye(4)
        T[0, 3] = 0.2 * i
        p = root / "images" / f"f{i:02d}.png"
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(g.integers(0, 256, (h, w, 3), dtype=np.uint8)).save(p)
        m = root / "images_mask" / f"f{i:02d}.png"
        m.parent.mkdir(parents=True, exist_ok=True)
        mask = np.full((h, w), 255, np.uint8)
        mask[:, : w // 4] = 0  # left quarter invalid
        Image.fromarray(mask).save(m)
        cams.append(Camera(name=f"f{i:02d}", world_from_cam=T, K=K, width=w, height=h, image_path=p,
                           mask_path=m, split="val" if i >= n_cams - 2 else "train"))
    pts = g.uniform(-1, 1, (n_points, 3)).astype(np.float32) + np.array([0.9, 0, 4], np.float32)
    cols = g.integers(0, 256, (n_points, 3)).astype(np.uint8)
    return Scene(name="synthetic", root=root, version="v1", up_axis="-y", points=pts, colors=cols, cameras=cams)


def test_views_resize_intrinsics_and_splits(tmp_path):
    sc = _scene(tmp_path)
    K = sc.cameras[0].K
    K2 = scaled_intrinsics(K, 0.5, 0.5)
    # the image centre maps to the image centre
    assert np.allclose(K2[:2, 2], [10.0, 7.5]) and K2[0, 0] == 15.0 and K2[1, 1] == 15.0
    assert target_size(40, 30, 1.0, 20) == (20, 15) and target_size(40, 30, 2.0, None) == (20, 15)
    v = load_view(sc.cameras[0], max_width=20)
    assert v.image.shape == (15, 20, 3) and v.mask.shape == (15, 20, 1) and v.mask.dtype == torch.bool
    assert not v.mask[:, :5].any() and v.mask[:, 5:].all()
    assert torch.allclose(v.cam_from_world @ torch.from_numpy(sc.cameras[0].world_from_cam).float(), torch.eye(4))
    sp = split_cameras(sc.cameras, holdout_every=4)
    assert [c.name for c in sp["interp"]] == ["f02", "f06"]
    assert len(sp["train"]) == 6 and [c.name for c in sp["extrap"]] == ["f08", "f09"]
    assert len(split_cameras(sc.cameras, 0)["train"]) == 8
    bad = Camera(name="x", world_from_cam=np.eye(4), K=K, width=40, height=30, image_path=tmp_path / "nope.png")
    with pytest.raises(ValueError, match="nope.png"):
        load_view(bad)


def test_se3_exp_matches_rotvec_and_has_gradient():
    xi = torch.tensor([[0.1, -0.2, 0.3, 1.0, 2.0, 3.0], [0, 0, 0, 0, 0, 0], [1e-5, 0, 0, 0, 0, 0]],
                      dtype=torch.float64)
    T = se3_exp(xi)
    for i in range(3):
        R = Rotation.from_rotvec(xi[i, :3].numpy()).as_matrix()
        assert np.allclose(T[i, :3, :3].numpy(), R, atol=1e-10)
    assert torch.equal(T[0, :3, 3], xi[0, 3:])
    z = torch.zeros(1, 6, requires_grad=True)
    (se3_exp(z)[0, 0, 1]).backward()  # d R01 / d w_z = -1 at identity
    assert torch.allclose(z.grad, torch.tensor([[0.0, 0, -1, 0, 0, 0]]))


def test_fit_config_is_typed_at_compose_time():
    """The hand-written dict validator is gone: `compose.typed_config` names the bad key and builds FitConfig."""
    from omegaconf.errors import ConfigKeyError

    from wanderland_nav.compose import compose_config, typed_config
    from wanderland_nav.compose.schema import FitRunConfig

    with pytest.raises(ConfigKeyError, match="fit.iterationz"):
        typed_config({"fit": {"iterationz": 3}}, FitRunConfig)
    with pytest.raises(ConfigKeyError, match="fit.lr.mean"):
        typed_config({"fit": {"lr": {"mean": 1.0}}}, FitRunConfig)
    c = typed_config(compose_config("fit", ["fit.frozen_means=true", "fit.lr.sh_dc=1e-3"]), FitRunConfig)
    cfg = c.fit
    assert isinstance(cfg, FitConfig) and cfg.background == (0.0, 0.0, 0.0)
    assert cfg.frozen_means and cfg.lr.sh_dc == 1e-3 and cfg.lr.means == 1.6e-5 and cfg.loss.depth == 0.02


def _trainer(tmp_path, **kw):
    cfg = FitConfig(iterations=10, use_depth=False, holdout_every=0, init=InitSettings(num_points=200),
                    **kw)
    return Trainer(_scene(tmp_path / "scene"), tmp_path / "out", cfg, render_fn=lambda *a, **k: None,
                   progress=False)


def test_optimizer_groups_follow_table_one_and_frozen_means(tmp_path):
    t = _trainer(tmp_path)
    lrs = {g["name"]: g["lr"] for g in t.optimizer.param_groups}
    assert lrs["sh_dc"] == 5e-4 and lrs["sh_rest"] == 1.25e-4 and lrs["opacity_logits"] == 2e-2
    assert lrs["quats"] == 1e-3 and lrs["log_scales"] == 1e-3
    assert abs(lrs["means"] - 1.6e-5 * t.extent) < 1e-12 and "pose" not in lrs
    t2 = _trainer(tmp_path / "b", frozen_means=True, pose_refine=True)
    names = {g["name"] for g in t2.optimizer.param_groups}
    assert "means" not in names and "pose" in names and not t2.params["means"].requires_grad


def test_densify_and_prune_carries_adam_state(tmp_path):
    t = _trainer(tmp_path, densify=DensifySettings(enabled=True, grad_threshold=1.0, percent_dense=0.01))
    n = len(t.params["means"])
    # pretend Adam has run one step so there is state to carry
    for p in t.params.values():
        p.grad = torch.ones_like(p)
    t.optimizer.step()
    t.optimizer.zero_grad()
    with torch.no_grad():
        t.params["opacity_logits"][:5] = -10.0  # transparent -> pruned
        t.params["log_scales"][5:8] = np.log(0.001)  # small + high gradient -> cloned
        t.params["log_scales"][8:10] = np.log(0.5)  # large + high gradient -> split in two
    t._grad_accum[5:10] = 10.0
    t._grad_count[:] = 1.0
    before = t.params["sh_dc"][5:10].detach().clone()
    stats = t.densify_and_prune()
    assert stats == {"cloned": 3, "split": 2, "pruned": 5, "total": n - 5 + 3 - 2 + 4}
    assert len(t.params["means"]) == stats["total"]
    for g in t.optimizer.param_groups:
        p = g["params"][0]
        assert p is t.params[g["name"]]
        st = t.optimizer.state[p]
        assert st["exp_avg"].shape == p.shape
        assert st["exp_avg"][-7:].abs().sum() == 0 and st["exp_avg"][0].abs().sum() > 0  # new rows start at 0
    # the kept originals of the cloned rows and the children carry the parents' colours
    assert torch.allclose(t.params["sh_dc"][-7:-4], before[:3])
    assert torch.allclose(t.params["log_scales"][-4:].exp(), torch.full((4, 3), 0.5 / 1.6), atol=1e-6)


def test_checkpoint_resume_round_trip(tmp_path):
    t = _trainer(tmp_path)
    with torch.no_grad():
        t.params["sh_dc"] += 0.25
    t.step = 7
    t._next_cameras()
    path = t.save_checkpoint()
    assert path.exists()
    t2 = _trainer(tmp_path)  # same out_dir: resumes
    assert t2.step == 7 and torch.equal(t2.params["sh_dc"], t.params["sh_dc"].detach())
    assert t2._next_cameras() == t._next_cameras()  # camera order continues identically
    t3 = Trainer(_scene(tmp_path / "scene"), tmp_path / "out", t.cfg, render_fn=lambda *a, **k: None,
                 progress=False, resume=False)
    assert t3.step == 0
    path.write_bytes(b"garbage")
    with pytest.raises(WanderlandInputError, match=re.escape(str(path)) + ": not a readable gsfit checkpoint"):
        _trainer(tmp_path)


def test_frustum_mask_is_conservative():
    from wanderland_nav.gsfit.cull import frustum_mask

    K = torch.tensor([[[20.0, 0, 20], [0, 20.0, 15], [0, 0, 1]]])  # 40x30 image: half-angles atan(1), atan(.75)
    vm = torch.eye(4)[None]
    means = torch.tensor([[0, 0, 5.0],     # straight ahead
                          [0, 0, -5.0],    # behind
                          [9.0, 0, 5.0],   # far right: 36 px beyond the edge
                          [5.3, 0, 5.0],   # 1 px beyond the right edge, its footprint reaches in
                          [0, 6.0, 5.0],   # 9 px below the bottom edge, tiny
                          [0, 0.3, 0.2],   # in front but off-screen below; near, so its footprint is huge
                          [0, 0, 0.005]])  # inside the near plane: culled like the renderer does
    ls = torch.log(torch.tensor([0.01, 0.01, 0.01, 0.01, 0.001, 0.05, 1.0]))[:, None].expand(7, 3)
    keep = frustum_mask(means, ls, vm, K, 40, 30)
    assert keep.tolist() == [True, False, False, True, False, True, False]
    assert frustum_mask(means, ls, vm, K, 40, 30, camera_model="fisheye").all()
