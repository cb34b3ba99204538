"""rerun logging and replay on the prepared tiny demo, read back with rerun's own chunk reader.

A recording is only useful if the viewer finds what we think we logged: these tests open the `.rrd`
with `rerun.chunk.RrdReader` and check entities, the number of time points per timeline, and image
sizes, and they check the rollout file's round trip and its errors.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import torch

from wanderland_nav.evaluation.recording import RecordingEnv, RolloutRecorder, record_evaluation
from wanderland_nav.evaluation.rollouts import Rollout, RolloutFormatError, load_rollout, save_rollout

H = W = 24  # tiny camera: the CPU renderer stays well inside the test budget


@pytest.fixture(scope="module")
def demo(prepared_demo_scene, demo_episodes):
    from planners import NavMesh
    from wanderland_nav.render import Gaussians
    from wanderland_nav.scene import load_scene

    scene = load_scene(prepared_demo_scene)
    g = Gaussians.load(scene.gaussians_path)
    idx = torch.randperm(len(g), generator=torch.Generator().manual_seed(0))[:1000]
    return scene, NavMesh.load(scene.navmesh_path), g[idx]


@pytest.fixture(scope="module")
def env(demo):
    """2 agents, a 24 x 24 camera with depth, episodes cut at 4 steps (the CPU renderer is the cost)."""
    from wanderland_nav.envs import NavEnvConfig
    from wanderland_nav.envs.factory import make_nav_env
    from wanderland_nav.episodes import load_episodes

    scene, navmesh, g = demo
    c = NavEnvConfig()
    c.camera.width, c.camera.height, c.camera.history, c.camera.depth = W, H, 1, True
    c.termination.max_steps = 4
    return make_nav_env(scene, load_episodes(scene.episodes_path), navmesh, config=c, batch_size=2, gaussians=g)


@pytest.fixture(scope="module")
def recorded(env, tmp_path_factory):
    """3 expert episodes on 2 agents with frames and depth, saved (loaded back by the tests)."""
    from wanderland_nav.envs import ExpertPolicy

    path = tmp_path_factory.mktemp("ro") / "expert.npz"
    res, ro = record_evaluation(env, ExpertPolicy(env), path, num_episodes=3, name="expert", frames=True,
                                episodes_path=env.scene.episodes_path)
    return env, res, ro, path


def _chunks(path):
    return list(rr.chunk.RrdReader(str(path)).stream())


def _rows_by_entity(chunks, column: str, timeline: str | None = None) -> dict[str, list]:
    """entity -> list of (time or None, value) for `column` across chunks."""
    out: dict[str, list] = {}
    for c in chunks:
        rb = c.to_record_batch()
        if column not in rb.schema.names:
            continue
        times = rb.column(timeline).to_pylist() if timeline and timeline in rb.schema.names else [None] * rb.num_rows
        out.setdefault(c.entity_path.lstrip("/"), []).extend(zip(times, rb.column(column).to_pylist()))
    return out


def test_rollout_file_round_trip(recorded):
    env, res, ro, path = recorded
    back = load_rollout(path)
    T, B = back.num_steps, back.num_agents
    assert B == 2 and T == ro.num_steps >= 3
    assert back.rgb.shape == (T, B, H, W, 3) and back.rgb.dtype == np.uint8
    assert back.depth.shape == (T, B, H, W, 1)
    assert back.waypoints.shape == (T, B, env.config.kinematics.num_waypoints, 2)
    np.testing.assert_array_equal(back.position, ro.position)
    # each transition starts where the previous one ended unless the agent's episode ended in between
    cont = ~back.done[:-1]
    np.testing.assert_allclose(back.position[1:][cont], back.next_position[:-1][cont], atol=1e-5)
    # the 3 counted episodes' metrics were captured, and match what run_evaluation returned
    got = {(m["serial"], m["episode_id"]) for m in back.meta.metrics}
    assert {(r["serial"], r["episode_id"]) for r in res.records} <= got
    assert back.meta.camera["width"] == W and np.asarray(back.meta.K).shape == (3, 3)


def test_bad_rollout_files_name_file_and_field(recorded, tmp_path):
    _, _, ro, path = recorded
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(RolloutFormatError, match="trunc.npz.*truncated or corrupt"):
        load_rollout(trunc)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    bad = dict(arrays, reward=arrays["reward"][:, :1])
    np.savez(tmp_path / "shape.npz", **bad)
    with pytest.raises(RolloutFormatError, match=r"shape.npz: field 'reward' has shape"):
        load_rollout(tmp_path / "shape.npz")
    miss = {k: v for k, v in arrays.items() if k != "yaw"}
    np.savez(tmp_path / "miss.npz", **miss)
    with pytest.raises(RolloutFormatError, match=r"miss.npz: field 'yaw' missing"):
        load_rollout(tmp_path / "miss.npz")
    meta = json.loads(str(arrays["meta_json"]))
    np.savez(tmp_path / "ver.npz", **dict(arrays, meta_json=np.asarray(json.dumps({**meta, "version": 99}))))
    with pytest.raises(RolloutFormatError, match=r"ver.npz: field 'meta_json.version' is 99"):
        load_rollout(tmp_path / "ver.npz")
    with pytest.raises(RolloutFormatError, match="no such rollout file"):
        load_rollout(tmp_path / "nope.npz")


def test_replay_recording_reads_back(recorded, demo, tmp_path):
    """Scene + episodes + rollout -> .rrd; entities, time points per step and image sizes as logged."""
    from wanderland_nav.viz.recording import write_recording

    env, _, ro, path = recorded
    scene, navmesh, _ = demo
    ro = load_rollout(path)
    out = tmp_path / "replay.rrd"
    counts = write_recording(out, scene=scene, rollout=ro, episodes=env.episodes[:3], navmesh=navmesh,
                             max_points=2000, max_cameras=4)
    assert out.is_file() and not list(tmp_path.glob(".replay*"))  # renamed into place, no temporary left
    rd = rr.chunk.RrdReader(str(out))
    assert len(rd.recordings()) == 1 and len(rd.blueprints()) == 1  # one recording, with the default layout
    chunks = _chunks(out)
    ents = {c.entity_path.lstrip("/") for c in chunks}
    T = ro.num_steps
    expected = {"world", "world/points", "world/collision_mesh", "world/navmesh",
                "world/agents/agent_0", "world/agents/agent_1", "world/agents/agent_0/camera",
                "world/agents/agent_0/camera/depth", "world/agents/agent_0/waypoints",
                "plots/reward/agent_0", "plots/distance_to_goal/agent_1", "plots/metrics/NE", "plots/metrics/mean_SR"}
    assert expected <= ents, sorted(expected - ents)
    ep0 = f"world/episodes/ep_{env.episodes[0].episode_id}"
    assert {f"{ep0}/start", f"{ep0}/goal", f"{ep0}/goal_radius", f"{ep0}/reference_path"} <= ents
    assert sum(e.startswith("world/capture/") for e in ents) == counts["scene"]["cameras"] == 4
    # the scene frame's up axis: -y for the v1-layout demo
    vc = _rows_by_entity(chunks, "ViewCoordinates:xyz")["world"]
    want = rr.ViewCoordinates.RIGHT_HAND_Y_DOWN.as_arrow_array().to_pylist()
    assert vc and np.array_equal(np.asarray(vc[0][1]).ravel(), np.asarray(want).ravel())
    # one pose and one image per step, on both timelines
    poses = _rows_by_entity(chunks, "Transform3D:translation", "step")["world/agents/agent_1"]
    assert sorted(t for t, _ in poses) == list(range(T))
    sim = _rows_by_entity(chunks, "Transform3D:translation", "sim_time")["world/agents/agent_1"]
    assert len(sim) == T
    imgs = _rows_by_entity(chunks, "Image:buffer", "step")["world/agents/agent_0/camera"]
    assert len(imgs) == T and all(len(b[0]) == H * W * 3 for _, b in imgs)
    fmt = _rows_by_entity(chunks, "Image:format")["world/agents/agent_0/camera"][0][1][0]
    assert (fmt["width"], fmt["height"]) == (W, H)
    # the logged pixels are the recorded frames
    t3 = dict(imgs)[3][0]
    np.testing.assert_array_equal(np.asarray(t3, np.uint8).reshape(H, W, 3), ro.rgb[3, 0])
    # poses: scene-frame translation = nav position mapped back
    t5 = np.asarray(dict(poses)[min(5, T - 1)][0])
    np.testing.assert_allclose(t5, ro.position[min(5, T - 1), 1] @ np.asarray(scene.nav_from_scene), atol=1e-4)
    dist = _rows_by_entity(chunks, "Scalars:scalars", "step")["plots/distance_to_goal/agent_1"]
    np.testing.assert_allclose([v[0] for _, v in sorted(dist)], ro.distance_to_goal[:, 1], rtol=1e-6)
    # navmesh coloured by island: one colour per triangle's three vertices
    nav_cols = _rows_by_entity(chunks, "Mesh3D:vertex_colors")["world/navmesh"][0][1]
    assert len(nav_cols) == 3 * len(navmesh.tris)


def test_replay_entry_point_rerenders_frames_and_expert_paths(recorded, demo, tmp_path):
    """`replay rollout=` without frames re-renders them; `replay episodes=` renders the expert's camera."""
    from hydra import compose, initialize_config_dir

    from wanderland_nav import replay

    env, _, ro, path = recorded
    lean = tmp_path / "noframes.npz"
    short = Rollout(**{**ro.__dict__, "rgb": None, "depth": None})
    save_rollout(lean, short)
    conf = str(Path(replay.__file__).resolve().parents[1] / "conf")
    with initialize_config_dir(config_dir=conf, version_base="1.3"):
        cfg = compose("replay", overrides=[f"rollout={lean}", f"out={tmp_path / 'a.rrd'}", "lod_px=4",
                                           "agents=[0]", "max_points=500", "max_cameras=2",
                                           "frame_chunk=3"])
        replay.run(cfg)
        cfg2 = compose("replay", overrides=[f"episodes={env.scene.episodes_path}", f"out={tmp_path / 'b.rrd'}",
                                            "lod_px=4", "max_episodes=1", "camera.width=16", "path_stride=8",
                                            "camera.height=12", "max_points=500", "max_cameras=2"])
        replay.run(cfg2)
    a = _chunks(tmp_path / "a.rrd")
    imgs = _rows_by_entity(a, "Image:buffer", "step")
    assert len(imgs["world/agents/agent_0/camera"]) == ro.num_steps and "world/agents/agent_1/camera" not in imgs
    pix = [np.asarray(b[0], np.uint8) for _, b in imgs["world/agents/agent_0/camera"]]
    # real renders, not blank frames (one frame may face a single large splat: judge the sequence)
    assert all(p.size == H * W * 3 for p in pix) and np.mean([p.std() > 0 for p in pix]) >= 0.5
    b = _chunks(tmp_path / "b.rrd")
    ep = env.episodes[0]
    bimgs = _rows_by_entity(b, "Image:buffer", "step")["world/agents/agent_0/camera"]
    n_samples = len(np.unique(np.r_[np.arange(0, len(ep.gt_locations), 8), len(ep.gt_locations) - 1]))
    assert len(bimgs) == n_samples - 1 and len(bimgs[0][1][0]) == 16 * 12 * 3
    wps = _rows_by_entity(b, "Points3D:positions", "step")["world/agents/agent_0/waypoints"]
    first = np.asarray(sorted(wps, key=lambda r: r[0])[0][1])
    assert first.shape == (5, 3) and first[0, 0] > 0 and abs(first[0, 1]) < 1e-4  # next sample dead ahead


def test_rerun_logger_protocol(recorded, tmp_path):
    from wanderland_nav.compose import make_logger
    from wanderland_nav.compose.schema import LoggerGroup, RerunOptions
    from wanderland_nav.rl.loggers import Logger
    from wanderland_nav.viz.rerun_logger import scalar_entities

    env, _, ro, _ = recorded
    lg = make_logger(LoggerGroup(kind="rerun", rerun=RerunOptions(rollout_every=2, max_agents=1)), tmp_path, env.scene)
    assert isinstance(lg, Logger)
    for i in range(3):
        lg.log_scalars({"losses/objective": 0.5 - 0.1 * i, "eval/SR": 0.25 * i, "eval/NE": float("nan"),
                        "losses/critic": float("inf")}, step=8 * i)
    for i in range(3):  # every other rollout per tag is logged: calls 1 and 3 of "eval"
        lg.log_rollout(ro, step=8 * i, tag="eval")
    lg.log_rollout(ro, step=24, tag="BC")  # a tag's first call is always logged
    lg.close()
    assert lg.rollouts_logged == 3
    sc = scalar_entities(tmp_path / "rerun.rrd")
    np.testing.assert_allclose(sc["losses/objective"], [0.5, 0.4, 0.3])
    assert np.isnan(sc["eval/NE"]).all() and len(sc["eval/NE"]) == 3  # divergence shows: NaN logged as NaN
    assert np.isposinf(sc["losses/critic"]).all()
    chunks = _chunks(tmp_path / "rerun.rrd")
    poses = _rows_by_entity(chunks, "Transform3D:translation", "rollout_step")
    assert len(poses["world/rollouts/eval/agents/agent_0"]) == 2 * ro.num_steps
    assert "world/rollouts/eval/agents/agent_1" not in poses
    ents = {c.entity_path.lstrip("/") for c in chunks}
    assert {"world/points", "world/navmesh", "rollouts/eval/plots/reward/agent_0"} <= ents  # scene logged once


def test_recorder_from_env_steps_and_tensordict(env, recorded, tmp_path):
    """`RolloutRecorder.add` fed by hand equals `rollout_from_tensordict` of the same steps stacked [B, T]."""
    import torch as th

    from wanderland_nav.envs import ExpertPolicy
    from wanderland_nav.evaluation.recording import rollout_from_tensordict

    pol = ExpertPolicy(env)
    rec = RolloutRecorder(env)
    renv = RecordingEnv(env, rec)
    env.config.camera.enabled = False  # blind: this test is about the bookkeeping
    try:
        td = renv.reset()
        steps = []
        for _ in range(5):
            td = pol(td)
            full, td = renv.step_and_maybe_reset(td)
            steps.append(full)
    finally:
        env.config.camera.enabled = True
    ro = rec.rollout()
    ro2 = rollout_from_tensordict(th.stack(steps, 1))
    np.testing.assert_array_equal(ro.position, ro2.position)
    np.testing.assert_array_equal(ro.done, ro2.done)
    assert ro.done[3].all()  # max_steps=4: every agent times out at its 4th step
    segs = ro.episode_segments()
    assert [(b, s, e) for b, _, s, e in segs] == [(0, 0, 4), (0, 4, 5), (1, 0, 4), (1, 4, 5)]
    # the training logger places a collector-style batch in the scene once a Rollout gave it the frame
    from wanderland_nav.viz.rerun_logger import RerunLogger

    lg = RerunLogger(tmp_path, scene=None, rollout_every=1)
    lg.log_rollout(th.stack(steps, 1), step=0, tag="train")  # no frame known yet: nav-frame space
    lg.log_rollout(ro, step=1, tag="eval")
    lg.log_rollout(th.stack(steps, 1), step=2, tag="train")
    lg.close()
    poses = _rows_by_entity(_chunks(tmp_path / "rerun.rrd"), "Transform3D:translation", "step")
    assert len(poses["rollouts/train/nav/agents/agent_0"]) == 5 and len(poses["world/rollouts/train/agents/agent_0"]) == 5
    got = np.asarray([v for t, v in poses["world/rollouts/train/agents/agent_1"]]).reshape(-1, 3)
    np.testing.assert_allclose(got, ro.position[:, 1] @ np.asarray(env.scene.nav_from_scene), atol=1e-5)
