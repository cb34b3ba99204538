"""NavDP's policy-server contract, both sides.

`_StandInServer` below is written from NavDP's servers (`baselines/nomad/nomad_server.py`,
`baselines/navdp/navdp_server.py`, `baselines/nomad/base_agent.py` at InternRobotics/NavDP
cb33ff81724033e9e9147c473950ba8d74d6ddac): PIL decodes the JPEG, the channels are swapped back as their
`cv2.cvtColor(RGB2BGR)` does, the stack is reshaped `(B, -1, W, 3)`, depth is `convert('I') / 10000`, the
memory queue of each env is filled with copies of its first frame, answers are JSON lists. It wraps a protocol
policy, so the client's records can be compared with the same policy run in process.
"""

from __future__ import annotations

import io
import json
import threading
from email.parser import BytesParser
from email.policy import HTTP
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
from PIL import Image

from wanderland_nav import keys
from wanderland_nav.benchmark import run
from wanderland_nav.compose import compose_config
from wanderland_nav.external.examples import GoalVectorPolicy
from wanderland_nav.external.navdp import (NavDPError, NavDPPolicy, NavDPServer, decode_depth, decode_rgb, encode_depth,
                                           encode_rgb, multipart, waypoints_from_trajectory)
from wanderland_nav.external.protocol import NEW_EPISODE, ExternalPolicy

FIXTURE_NAV = "navigation.collision.voxel_size=0.25"


class _StandIn(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def _json(self, obj, status=200):
        body = json.dumps(obj).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_POST(self):  # noqa: N802
        srv = self.server
        body = self.rfile.read(int(self.headers["Content-Length"]))
        srv.calls.append(self.path)
        if self.path == "/navigator_reset":
            req = json.loads(body)
            srv.resets.append(req)
            srv.batch = int(req["batch_size"])
            srv.memory = [[] for _ in range(srv.batch)]
            return self._json({"algo": "standin"})
        if self.path == "/navigator_reset_env":
            i = int(json.loads(body)["env_id"])
            srv.memory[i] = []
            srv.env_resets.append(i)
            return self._json({"algo": "standin"})
        msg = BytesParser(policy=HTTP).parsebytes(b"Content-Type: " + self.headers["Content-Type"].encode() + b"\r\n\r\n" + body)
        form = {p.get_param("name", header="content-disposition"): p.get_payload(decode=True) for p in msg.iter_parts()}
        image = np.asarray(Image.open(io.BytesIO(form["image"])).convert("RGB"))[..., ::-1]   # cv2 RGB2BGR
        image = image.reshape((srv.batch, -1, image.shape[1], 3))
        depth = np.asarray(Image.open(io.BytesIO(form["depth"])).convert("I"))[:, :, None].astype(np.float32) / 10000.0
        srv.depths.append(depth.reshape((srv.batch, -1, depth.shape[1], 1)))
        for i in range(srv.batch):  # base_agent.callback_obs
            if len(srv.memory[i]) < srv.context:
                srv.memory[i] = [image[i]] * srv.context
            else:
                srv.memory[i].pop(0)
                srv.memory[i].append(image[i])
        obs = {keys.RGB: np.stack([np.stack(m) for m in srv.memory]), NEW_EPISODE: np.zeros(srv.batch, bool)}
        if self.path == "/pointgoal_step":
            goal = json.loads(form["goal_data"])
            obs[keys.GOAL_VECTOR] = np.stack([goal["goal_x"], goal["goal_y"]], axis=1).astype(np.float32)
        wps = np.asarray(srv.policy.act({k: v for k, v in obs.items() if k in srv.policy.observes}), np.float32)
        traj = np.concatenate([np.zeros((srv.batch, 1, 2), np.float32), wps], axis=1)  # theirs start at the robot
        self._json({"trajectory": traj.tolist(), "all_trajectory": traj[:, None].tolist(),
                    "all_values": np.zeros((srv.batch, 1)).tolist()})

    def log_message(self, *args):
        pass


@pytest.fixture
def standin():
    servers = []

    def start(policy, context=1):
        srv = ThreadingHTTPServer(("127.0.0.1", 0), _StandIn)
        srv.policy, srv.context, srv.calls, srv.resets, srv.env_resets, srv.depths = policy, context, [], [], [], []
        threading.Thread(target=srv.serve_forever, daemon=True).start()
        servers.append(srv)
        return srv, f"http://127.0.0.1:{srv.server_address[1]}"
    yield start
    for s in servers:
        s.shutdown()
        s.server_close()


def _frames(b=3, h=24, w=32, seed=0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    base = np.stack([xx * 4, yy * 5, 200 - (xx + yy) * 2], -1)          # smooth colour ramps, red != blue
    return np.stack([np.clip(base + 20 * i + rng.integers(0, 3, base.shape), 0, 255) for i in range(b)]).astype(np.uint8)


def test_images_cross_the_wire_as_their_client_sends_them():
    rgb = _frames()
    data = encode_rgb(rgb)
    plain = np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(int)
    assert plain.shape == (3 * 24, 32, 3)                     # stacked vertically
    back = decode_rgb(data, 3).astype(int)
    assert np.abs(back - rgb).mean() < 3.0                    # JPEG at quality 95
    # the bytes hold red and blue exchanged (OpenCV took the RGB array for BGR), the decode swaps them back
    flat = rgb.reshape(-1, 32, 3).astype(int)
    assert np.abs(plain[..., 0] - flat[..., 2]).mean() < 3.0 < np.abs(plain[..., 0] - flat[..., 0]).mean()
    depth = np.array([[[0.0, 1.23456], [7.0, 9.0]]], np.float32).repeat(2, 0)
    d = decode_depth(encode_depth(depth), 2)
    assert d.shape == (2, 2, 2, 1) and np.allclose(d[..., 0], np.floor(np.clip(depth * 1e4, 0, 65535)) / 1e4, atol=1e-6)  # truncated, as theirs
    assert d[0, 1, 1, 0] == pytest.approx(6.5535)             # 9 m clips at 65535 units
    with pytest.raises(ValueError, match="does not stack 5 frames"):
        decode_rgb(encode_rgb(_frames(b=3)), 5)


def test_trajectory_to_waypoints():
    traj = np.arange(11, dtype=np.float32)[None, :, None].repeat(3, -1)          # [1, 11, 3], first point the robot
    assert waypoints_from_trajectory(traj, 5)[0, :, 0].tolist() == [2, 4, 6, 8, 10]
    assert waypoints_from_trajectory(traj[:, :3], 4)[0, :, 0].tolist() == [1, 1, 2, 2]
    assert waypoints_from_trajectory(traj[:, :1], 2).shape == (1, 2, 2)
    with pytest.raises(ValueError, match=r"\[B, L, C >= 2\]"):
        waypoints_from_trajectory(np.zeros((2, 4)), 3)


def _step_obs(b, new):
    return {keys.RGB: _frames(b)[:, None], keys.DEPTH: np.full((b, 1, 24, 32, 1), 2.5, np.float32),
            keys.GOAL_VECTOR: np.array([[3.0, 0.0], [0.0, -0.4], [1.0, 1.0]], np.float32)[:b],
            NEW_EPISODE: np.asarray(new)}


def test_client_follows_their_reset_semantics_and_matches_in_process(standin):
    policy = GoalVectorPolicy()
    srv, url = standin(policy)
    client = NavDPPolicy(url, goal="point", num_waypoints=5, hfov_deg=90.0, stop_threshold=-3.0)
    assert client.observes == (keys.RGB, keys.DEPTH, keys.GOAL_VECTOR)
    for new in ([True, True, True], [False, False, False], [False, True, False]):
        got = client.act(_step_obs(3, new))
        np.testing.assert_array_equal(got, policy.act(_step_obs(3, new)).astype(np.float32))
    assert len(srv.resets) == 1 and srv.resets[0]["batch_size"] == 3 and srv.resets[0]["stop_threshold"] == -3.0
    assert np.allclose(srv.resets[0]["intrinsic"], [[16.0, 0, 16.0], [0, 16.0, 12.0], [0, 0, 1]])
    assert srv.env_resets == [1]                      # only env 1 started a new episode after the first step
    assert srv.calls.count("/pointgoal_step") == 3
    assert np.allclose(srv.depths[0], 2.5)
    client.act(_step_obs(2, [True, True]))            # another batch size: a fresh /navigator_reset
    assert len(srv.resets) == 2 and srv.resets[1]["batch_size"] == 2
    client.close()


def test_client_errors_are_named(standin):
    with pytest.raises(ValueError, match="expected http://host:port"):
        NavDPPolicy("localhost:8888")
    with pytest.raises(ValueError, match="navdp goal='pixel'"):
        NavDPPolicy("http://127.0.0.1:1", goal="pixel")
    dead = NavDPPolicy("http://127.0.0.1:9", timeout_s=2)
    with pytest.raises(NavDPError, match=r"http://127.0.0.1:9/navigator_reset: ConnectionRefusedError"):
        dead.act(_step_obs(3, [True] * 3))


class _FirstFrameProbe(ExternalPolicy):
    """Reads RGB history and depth; answers the mean colour of its oldest frame as waypoints (so the frames the
    server assembled are visible in the answer)."""

    observes = (keys.RGB, keys.DEPTH, keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE)
    num_waypoints, context = 2, 3

    def __init__(self):
        self.seen = []

    def act(self, obs):
        self.seen.append({k: np.array(v) for k, v in obs.items()})
        m = obs[keys.RGB][:, 0].reshape(len(obs[keys.RGB]), -1, 3).mean(1)[:, :2]
        return np.stack([m, m + obs[keys.HAS_GOAL_IMAGE].astype(np.float32)], 1)


def test_our_server_speaks_their_contract():
    policy = _FirstFrameProbe()
    srv = NavDPServer(policy, algo="probe")
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        client = NavDPPolicy(srv.url, goal="image", num_waypoints=2)
        frames = [_frames(seed=s) for s in range(4)]
        obs = lambda f, new: {keys.RGB: f[:, None], keys.DEPTH: np.ones((3, 1, 24, 32, 1), np.float32),  # noqa: E731
                              keys.GOAL_IMAGE: frames[3], NEW_EPISODE: np.asarray(new)}
        client.act(obs(frames[0], [True] * 3))
        assert client.algo == "probe"
        first = policy.seen[0]
        assert first[keys.RGB].shape == (3, 3, 24, 32, 3) and first[NEW_EPISODE].all()
        assert np.abs(first[keys.RGB][:, 0].astype(int) - frames[0]).mean() < 3  # the history filled with frame 0
        assert first[keys.HAS_GOAL_IMAGE].all() and np.abs(first[keys.GOAL_IMAGE].astype(int) - frames[3]).mean() < 3
        client.act(obs(frames[1], [False] * 3))
        client.act(obs(frames[2], [False, True, False]))
        last = policy.seen[-1]
        assert last[NEW_EPISODE].tolist() == [False, True, False]
        assert np.abs(last[keys.RGB][0, 0].astype(int) - frames[0][0]).mean() < 3   # env 0: frames 0, 1, 2
        assert np.abs(last[keys.RGB][1, 0].astype(int) - frames[2][1]).mean() < 3   # env 1 restarted: only frame 2
        # what their client reads back: trajectory [B, K, 2], all_trajectory [B, 1, K, 2], all_values [B, 1]
        body, ctype = multipart({"depth_time": "0", "rgb_time": "0"},
                                {"image": ("image.jpg", encode_rgb(frames[0]), "image/jpeg"),
                                 "depth": ("depth.png", encode_depth(np.ones((3, 24, 32))), "image/png")})
        import http.client
        conn = http.client.HTTPConnection("127.0.0.1", srv.server_address[1], timeout=10)
        conn.request("POST", "/nogoal_step", body=body, headers={"Content-Type": ctype})
        ans = json.loads(conn.getresponse().read())
        traj = np.asarray(ans["trajectory"])
        assert traj.shape == (3, 3, 2) and not traj[:, 0].any()    # the robot, then the K = 2 waypoints
        np.testing.assert_allclose(traj[:, 1:], policy.act(policy.seen[-1]), atol=1e-6)
        assert np.asarray(ans["all_trajectory"]).shape == (3, 1, 3, 2) and np.asarray(ans["all_values"]).shape == (3, 1)
        conn.request("POST", "/pixelgoal_step", body=body, headers={"Content-Type": ctype})
        assert conn.getresponse().status == 404
        conn.close()
    finally:
        srv.shutdown()
        srv.server_close()
    with pytest.raises(ValueError, match=r"reads \['past_positions'\], which NavDP's contract does not carry"):
        NavDPServer(type("Past", (ExternalPolicy,), {"observes": (keys.PAST_POSITIONS,), "act": lambda s, o: o})())


def test_benchmark_records_through_navdp_equal_in_process(prepared_demo_scene, demo_episodes, tmp_path, standin):
    """A policy that reads no image: the same records in process and behind a server of NavDP's contract."""
    _, url = standin(GoalVectorPolicy())
    pol = (f"[{{name: direct, target: 'wanderland_nav.external.examples:GoalVectorPolicy'}}, "
           f"{{name: navdp, navdp_url: '{url}', num_waypoints: 5}}]")
    cfg = compose_config("benchmark", [f"scene={prepared_demo_scene}", FIXTURE_NAV, f"out={tmp_path}", "progress=false",
                                       "batch_size=4", "num_episodes=4", "env.termination.max_steps=40",
                                       f"policies={pol}", "tasks=[pointgoal]"])
    res = run(cfg)
    direct, via = res["results"][("pointgoal", "direct")], res["results"][("pointgoal", "navdp")]
    assert len(via) == 4 and all(r["policy_error"] == "" for r in via)
    strip = lambda rs: [{k: v for k, v in r.items() if k not in ("seconds", "wall_seconds")} for r in rs]  # noqa: E731
    assert strip(via) == strip(direct)


def test_our_client_and_server_together_equal_in_process():
    policy = GoalVectorPolicy(num_waypoints=6)
    srv = NavDPServer(policy)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        client = NavDPPolicy(srv.url, goal="point", num_waypoints=6)
        for new in ([True] * 3, [False, True, False]):
            np.testing.assert_array_equal(client.act(_step_obs(3, new)), policy.act(_step_obs(3, new)).astype(np.float32))
        client.close()
    finally:
        srv.shutdown()
        srv.server_close()


def test_serve_policy_speaks_navdp():
    from wanderland_nav.serve_policy import make_server

    srv = make_server(compose_config("serve_policy", ["target=wanderland_nav.external.examples:GoalVectorPolicy",
                                                      "protocol=navdp", "port=0"]))
    assert isinstance(srv, NavDPServer)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        client = NavDPPolicy(srv.url, goal="point", num_waypoints=5)
        np.testing.assert_array_equal(client.act(_step_obs(3, [True] * 3)),
                                      GoalVectorPolicy().act(_step_obs(3, [True] * 3)).astype(np.float32))
        assert client.algo == "GoalVectorPolicy"
        client.close()
    finally:
        srv.shutdown()
        srv.server_close()
    with pytest.raises(ValueError, match="protocol='grpc'"):
        make_server(compose_config("serve_policy", ["target=wanderland_nav.external.examples:GoalVectorPolicy",
                                                    "protocol=grpc"]))
    with pytest.raises(ValueError, match="exactly one of"):
        make_server(compose_config("serve_policy", ["model=nomad", "checkpoint=x.pt"]))
