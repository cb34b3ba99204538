"""Pedestrians: the crowd on the demo navmesh (on the mesh, apart, deterministic), their Gaussians where
they are, and the env's hooks (off: the same task bit for bit; on: collisions and social metrics counted)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from wanderland_nav import keys
from wanderland_nav.envs.pedestrians.config import PedestrianConfig
from wanderland_nav.envs.pedestrians.crowd import Crowd


@pytest.fixture(scope="module")
def demo(prepared_demo_scene, demo_episodes):
    from planners import NavMesh
    from wanderland_nav.episodes import load_episodes
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    return scene, NavMesh.load(scene.navmesh_path), load_episodes(scene.episodes_path)


def _crowd(demo, count=12, B=2, seed=3):
    scene, nm, eps = demo
    starts = [e.start_position for e in eps]
    crowd = Crowd(PedestrianConfig(count=count), nm, scene.nav_from_scene, starts, B, 0.5)
    crowd.seed(seed)
    robot = crowd._nav(torch.as_tensor(np.asarray(starts[:B]), dtype=torch.float32))
    crowd.reset(torch.arange(B), robot)
    return crowd, robot


def test_crowd_walks_on_the_navmesh_apart_and_deterministically(demo):
    scene, nm, _ = demo
    a, robot = _crowd(demo)
    b, _ = _crowd(demo)
    start = a.pos.clone()
    min_gap = float("inf")
    for _ in range(30):
        a.step(robot, torch.zeros(2, 2))
        b.step(robot, torch.zeros(2, 2))
        assert torch.equal(a.pos, b.pos)  # same seed, same crowd
        assert bool(torch.as_tensor(nm.is_navigable(a._scene(a.pos.reshape(-1, 3)))).all())
        d = (a.pos[:, :, None, :2] - a.pos[:, None, :, :2]).norm(dim=-1) + torch.eye(a.P) * 1e3
        min_gap = min(min_gap, float(d.min()))
    walked = (a.pos - start)[..., :2].norm(dim=-1)
    assert float(walked.median()) > 3.0  # 15 s at ~1.3 m/s, minus pauses and turns
    assert min_gap > 2 * a.cfg.radius - 0.15, min_gap  # bodies may touch, not pass through each other
    c, _ = _crowd(demo, seed=4)
    assert not torch.equal(c.pos, start)


def test_people_keep_away_from_a_standing_robot(demo):
    crowd, robot = _crowd(demo, count=16)
    closest = float("inf")
    for _ in range(40):
        crowd.step(robot, torch.zeros(2, 2))
        closest = min(closest, float(crowd.distances(robot).min()))
    assert closest > crowd.cfg.radius + crowd.cfg.robot_radius - 0.1, closest


def test_body_gaussians_project_where_the_person_stands(demo):
    from wanderland_nav.envs.pedestrians.bodies import PARTS
    from wanderland_nav.geometry import invert_rigid, pinhole_intrinsics
    from wanderland_nav.render.gaussians import Gaussians
    from wanderland_nav.render import render

    scene, _, _ = demo
    crowd, robot = _crowd(demo, count=1, B=1)
    g = crowd.gaussians()
    assert g.means.shape == (1, PARTS, 3)
    # camera 4 m behind the person (nav frame -x), looking +x at 1 m height
    R = crowd.R
    p = crowd.pos[0, 0]
    cam_nav = p + torch.tensor([-4.0, 0.0, 1.0])
    # OpenCV axes in nav: x right = -y_nav, y down = -z_nav, z forward = +x_nav
    axes_nav = torch.tensor([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]).T  # columns
    world_from_cam = torch.eye(4)
    world_from_cam[:3, :3] = R.T @ axes_nav
    world_from_cam[:3, 3] = cam_nav @ R
    K = torch.as_tensor(pinhole_intrinsics(64, 64, 60.0, "pinhole"), dtype=torch.float32)
    scene_g = Gaussians(torch.zeros(1, 3) + 1e3, torch.full((1, 3), -5.0), torch.tensor([[1.0, 0, 0, 0]]),
                        torch.full((1,), -10.0), torch.zeros(1, 3), torch.zeros(1, 0, 3))
    out = render(scene_g, invert_rigid(world_from_cam[None]), K[None], 64, 64, render_mode="RGB+ED", extra=g)
    alpha = out.alpha[0, ..., 0] if out.alpha is not None else out.rgb[0].sum(-1)
    ys, xs = torch.nonzero(alpha > 0.5, as_tuple=True)
    assert xs.numel() > 20
    assert abs(float(xs.float().mean()) - 31.5) < 3  # centred: the person is straight ahead
    d = out.depth[0, ..., 0][alpha > 0.5]
    assert 3.6 < float(d.median()) < 4.4  # at 4 m
    f = 32 / math.tan(math.radians(30))
    top = 31.5 - f * (1.6 * 0.92 - 1.0) / 4.0  # the head (above 1.47 m for the shortest person) over the 1 m camera
    assert int(ys.min()) < top and int(ys.max()) > 31.5 + f * 0.75 / 4.0  # and the legs reach down near the feet


def _env(demo, count=None, camera=False, B=2, episode_metrics=False, **ped):
    """A NavEnv on the demo with `count` people (None: no crowd block at all, the default)."""
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.envs.factory import make_nav_env

    scene, nm, eps = demo
    c = NavEnvConfig()
    c.camera.enabled = camera
    c.camera.width = c.camera.height = 16
    c.camera.history = 1
    c.termination.max_steps = 40
    c.pedestrians = PedestrianConfig(count=count, **ped) if count is not None else None
    c.episode_metrics = episode_metrics
    kw = {}
    if camera:
        from wanderland_nav.render import Gaussians

        g = Gaussians.load(scene.gaussians_path)
        kw["gaussians"] = g[torch.randperm(len(g), generator=torch.Generator().manual_seed(0))[:500]]
    return make_nav_env(scene, eps, nm, config=c, batch_size=B, **kw)


def _rollout(env, steps=12):
    from wanderland_nav.envs import ExpertPolicy

    expert = ExpertPolicy(env)
    env.set_seed(5)
    td = env.reset()
    out = []
    for _ in range(steps):
        td = expert(td)
        td, nxt = env.step_and_maybe_reset(td)
        out.append(td["next"].clone())
        td = nxt
    return torch.stack(out)


def test_off_by_default_is_the_pedestrian_free_task_bit_for_bit(demo):
    from wanderland_nav.envs import NavEnvConfig

    assert NavEnvConfig().pedestrians is None  # no crowd unless env/pedestrians=crowd selects one
    plain, off = _env(demo, camera=True), _env(demo, count=0, camera=True)
    assert off.crowd is None and set(off.observation_spec.keys(True)) == set(plain.observation_spec.keys(True))
    a, b = _rollout(plain), _rollout(off)
    assert (a == b).all()
    on = _rollout(_env(demo, count=6, camera=True))
    assert not torch.equal(on[keys.RGB], a[keys.RGB])  # the people are seen


def test_a_person_on_the_robot_is_an_intervention_with_its_own_cause(demo):
    env = _env(demo, count=3, episode_metrics=True)
    env.set_seed(0)
    td = env.reset()
    env.crowd.pos = env._pos[:, None, :].expand(-1, env.crowd.P, -1).clone()  # scripted: everyone on the robot
    td["action"] = torch.zeros(env.action_spec.shape)
    td = env.step(td)["next"]
    assert td["done"].all()
    (m0, m1) = sorted(env.pop_finished_metrics(), key=lambda m: m.serial)
    for m in (m0, m1):
        assert m.intervention and m.intervention_cause == "pedestrian" and m.person_collisions == 1
        assert m.min_person_distance < 0.6 and m.intimate_seconds == 0.5 and m.pedestrians == 3
        assert m.min_time_to_collision == 0.0 and m.personal_seconds == m.social_seconds == 0.0
        assert m.stalled_seconds == 0.5 and m.jerk == 0.0  # the zero action: it stood still from rest
    assert td[keys.EPISODE_PERSON_COLLISIONS].flatten().tolist() == [1, 1]  # the TorchRL view, at done
    assert td[keys.EPISODE_INTIMATE_SECONDS].flatten().tolist() == [0.5, 0.5]
    for key in keys.EPISODE_SOCIAL_KEYS:  # the TorchRL view and the records agree on every social metric
        np.testing.assert_allclose(td[key].flatten().numpy(), [getattr(m0, key[1]), getattr(m1, key[1])],
                                   rtol=1e-5, err_msg=key[1])
    from wanderland_nav.evaluation.tables import comparison_table

    table = comparison_table({"x": [m0.to_dict(), m1.to_dict()]})
    assert "person_collisions" in table.split("\n")[0] and "min_person_distance" in table


def test_crowd_in_the_env_is_deterministic_and_penalises_personal_space(demo):
    a = _rollout(_env(demo, count=8, personal_space=50.0, personal_space_penalty=0.5))
    b = _rollout(_env(demo, count=8, personal_space=50.0, personal_space_penalty=0.5))
    assert (a == b).all()
    c = _rollout(_env(demo, count=8))
    assert torch.allclose(a["reward"], c["reward"] - 0.5, atol=1e-5)  # the crowd is the same; every step is inside


def test_people_are_recorded_and_replayed_as_moving_points(demo, tmp_path):
    import rerun as rr

    from wanderland_nav.envs import ExpertPolicy
    from wanderland_nav.evaluation.recording import record_evaluation
    from wanderland_nav.evaluation.rollouts import load_rollout
    from wanderland_nav.viz.recording import write_recording

    env = _env(demo, count=4)
    path = tmp_path / "ro.npz"
    record_evaluation(env, ExpertPolicy(env), path, num_episodes=2, name="expert")
    ro = load_rollout(path)
    T = ro.num_steps
    assert ro.pedestrians.shape == (T, 2, 4, 3)
    assert float(np.abs(np.diff(ro.pedestrians, axis=0)).max()) > 0.1  # they move
    scene, nm, eps = demo
    out = tmp_path / "replay.rrd"
    write_recording(out, scene=scene, rollout=ro, episodes=eps[:2], navmesh=nm, max_points=200, max_cameras=0)
    rows = []
    for c in rr.chunk.RrdReader(str(out)).stream():
        rb = c.to_record_batch()
        if c.entity_path.lstrip("/") == "world/pedestrians/agent_1" and "Points3D:positions" in rb.schema.names:
            rows += list(zip(rb.column("step").to_pylist(), rb.column("Points3D:positions").to_pylist()))
    assert sorted(t for t, _ in rows) == list(range(T))
    t, pts = rows[-1]
    want = (ro.pedestrians[t, 1] + [0.0, 0.0, 0.9]) @ np.asarray(scene.nav_from_scene)
    np.testing.assert_allclose(np.asarray(pts, np.float64), want, atol=1e-4)


def test_the_expert_waits_for_a_person_ahead_not_behind(demo):
    from wanderland_nav.envs import ExpertPolicy

    env = _env(demo, count=1, B=2)
    env.set_seed(0)
    td = env.reset()
    expert = ExpertPolicy(env)
    free = expert(td.clone())["action"]
    ahead = env._pos.clone()  # agent 0: a person on its next waypoint; agent 1: one 1 m behind it
    wp0 = free[0, 0]
    c, s = torch.cos(env._yaw), torch.sin(env._yaw)
    ahead[0, 0] += c[0] * wp0[0] - s[0] * wp0[1]
    ahead[0, 1] += s[0] * wp0[0] + c[0] * wp0[1]
    ahead[1, 0] -= c[1] * 1.0
    ahead[1, 1] -= s[1] * 1.0
    env.crowd.pos = ahead[:, None, :].clone()
    env.crowd.vel = torch.zeros(2, 1, 2)
    act = expert(td.clone())["action"]
    assert torch.equal(act[0], torch.zeros_like(act[0])) and bool(free[0].abs().sum() > 0)  # waits
    assert torch.equal(act[1], free[1])  # walks on


def test_two_people_walking_head_on_pass_each_other_without_overlap():
    from wanderland_nav.envs.pedestrians.social_force import integrate

    cfg = PedestrianConfig(count=2)
    pos = torch.tensor([[[-4.0, 0.05], [4.0, -0.05]]])
    vel = torch.zeros(1, 2, 2)
    desired = torch.tensor([[[1.3, 0.0], [-1.3, 0.0]]])
    far = torch.full((1, 1, 2), 1e3)  # no robot nearby
    closest = float("inf")
    for _ in range(16):  # 8 s
        pos, vel, _ = integrate(pos, vel, desired, torch.full((1, 2), 1.3 * 1.3), torch.full((1, 2), cfg.radius),
                                torch.ones(1, 2, dtype=torch.bool), far, torch.zeros(1, 1, 2),
                                torch.full((1, 1), cfg.robot_radius), 0.5, cfg)
        closest = min(closest, float((pos[0, 0] - pos[0, 1]).norm()))
    assert float(pos[0, 0, 0]) > 3.0 and float(pos[0, 1, 0]) < -3.0  # both got past
    assert closest > 2 * cfg.radius - 0.05, closest  # by stepping aside, not through each other


class _Corridor:
    """A straight walkable band |y| <= half (nav = scene frame, z = 0) with the navmesh calls `Crowd` makes:
    straight-line paths (the goal is always visible) and motion clipped to the band, as the navmesh slides a
    body along its boundary."""

    def __init__(self, half: float, goal_xy):
        self.half, self.goal = half, torch.tensor([[*goal_xy, 0.0]], dtype=torch.float64)

    def island_of(self, points):
        return np.zeros(np.asarray(points).shape[:-1], dtype=np.int64)

    def random_navigable_points(self, n, seed, island=None):
        return np.tile(np.array([[-20.0, 0.0, 0.0]]), (n, 1))

    def distance_field(self, pool):
        corridor = self

        class Field:
            def __len__(self):
                return 1

            def next_point(self, points, goal_index):
                p = torch.as_tensor(points, dtype=torch.float64)
                return (p - corridor.goal)[:, :2].norm(dim=-1), corridor.goal.expand(len(p), 3).clone()

        return Field()

    def move_along_surface(self, start, target):
        t = torch.as_tensor(target, dtype=torch.float32)
        end = torch.cat([t[:, :1], t[:, 1:2].clamp(-self.half, self.half), t[:, 2:]], 1)
        return end, (end != t).any(-1).numpy()


@pytest.mark.parametrize("rule", ["old", "new"])
def test_a_person_passing_a_robot_by_the_boundary_does_not_walk_into_it(rule, monkeypatch):
    """The scene of the expert's collisions while it waited: a robot standing in a passage whose walkable band
    (0.9 m) leaves a person no room to pass, the person walking toward it. The old rule (the robot repelled only as
    a person is, the boundary slide taken as it comes) squeezes the person past into contact; with the robot's
    obstacle repulsion and the stop of a slide that would end at the robot, the person waits clear of it."""
    import wanderland_nav.envs.pedestrians.crowd as crowd_module

    cfg = PedestrianConfig(count=1, pause_probability=0.0)
    if rule == "old":
        cfg.robot_obstacle_strength = 0.0
        monkeypatch.setattr(crowd_module, "_ROBOT_BUFFER", -math.inf)
    nm = _Corridor(0.45, (6.0, 0.0))
    crowd = Crowd(cfg, nm, np.eye(3), [[0.0, 0.0, 0.0]], 1, 0.5)
    robot = torch.tensor([[0.0, 0.1, 0.0]])
    crowd.reset(torch.arange(1), robot)
    crowd.pos = torch.tensor([[[-4.0, 0.0, 0.0]]])
    crowd.v0 = torch.full((1, 1), 1.34)
    closest = min(float(crowd.step(robot, torch.zeros(1, 2))) for _ in range(16))  # 8 s
    contact = cfg.radius + cfg.robot_radius
    if rule == "old":
        assert closest < contact, closest
    else:
        assert closest > contact + 0.05, closest
        assert float(crowd.pos[0, 0, 0]) < 0.0  # still on its side: it waited rather than pushed past


def test_no_people_is_a_component_whose_hooks_change_nothing():
    from pathlib import Path

    import wanderland_nav.envs.nav_env as nav_env_module
    from wanderland_nav.envs.pedestrians.component import NoPedestrians, make_pedestrians

    none = make_pedestrians(PedestrianConfig(count=0), None, None, None, 2, 0.5, "cpu")
    assert isinstance(none, NoPedestrians) and none.crowd is None and none.episode_keys == ()
    flags = [torch.tensor([True, False]), torch.tensor([False, True]), torch.tensor([False, False]), torch.tensor([0, 2])]
    out = none.step(torch.zeros(2, 3), torch.zeros(2, 3), torch.zeros(2), *flags)
    assert all(a is b for a, b in zip(out[:3], flags[1:])) and out[3] == 0.0
    assert none.gaussians(None, "cpu") is None and none.finished_columns(torch.arange(2)) == {}
    # the env's body asks the component, never whether there is a crowd
    body = Path(nav_env_module.__file__).read_text()
    assert "crowd is" not in body and "social is" not in body and "pedestrians.count" not in body
