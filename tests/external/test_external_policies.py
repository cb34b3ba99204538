"""The bring-your-own-policy protocol: declarations, the actor's failure handling, the wire, the HTTP server and
client (one server in a subprocess, as a user runs it; the failure cases against servers in a thread)."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict

from wanderland_nav import keys
from wanderland_nav.external import ExternalActor, ExternalPolicy, RemotePolicy, RemotePolicyError, load_target
from wanderland_nav.external.examples import FaultyPolicy, GoalVectorPolicy
from wanderland_nav.external.protocol import NEW_EPISODE, check_waypoints, describe
from wanderland_nav.external.server import PolicyServer
from wanderland_nav.external.wire import pack, unpack

REPO = Path(__file__).resolve().parents[2]


def _obs(batch=3):
    goal = np.array([[3.0, 0.0], [0.0, -0.4], [1.0, 1.0]], dtype=np.float32)[:batch]
    return {keys.GOAL_VECTOR: goal, NEW_EPISODE: np.ones(batch, dtype=bool)}


def _td(batch=3, episodes=(7, 8, 9)):
    return TensorDict({keys.GOAL_VECTOR: torch.from_numpy(_obs(batch)[keys.GOAL_VECTOR]),
                       keys.EPISODE_INDEX: torch.tensor(episodes[:batch]).view(batch, 1),
                       keys.STEP_COUNT: torch.tensor([0, 3, 0][:batch]).view(batch, 1)}, batch_size=[batch])


def test_goal_vector_policy_walks_the_straight_line_and_stops_at_the_goal():
    wps = GoalVectorPolicy(num_waypoints=4, spacing=0.5).act(_obs())
    assert wps.shape == (3, 4, 2)
    np.testing.assert_allclose(wps[0], [[0.5, 0], [1.0, 0], [1.5, 0], [2.0, 0]], atol=1e-6)
    np.testing.assert_allclose(wps[1], [[0, -0.4]] * 4, atol=1e-6)  # 0.4 m away: every waypoint at the goal
    np.testing.assert_allclose(wps[2, -1], [1.0, 1.0], atol=1e-5)  # 1.41 m away: the last two at the goal
    np.testing.assert_allclose(np.linalg.norm(wps[2, 1]), 1.0, atol=1e-5)


def test_declarations_are_checked():
    class NoKeys(ExternalPolicy):
        observes = ()

    class Peeks(ExternalPolicy):
        observes = (keys.RGB, "agent_position")

    with pytest.raises(ValueError, match=r"NoKeys.observes: \[\]"):
        describe(NoKeys())
    with pytest.raises(ValueError, match="'agent_position'"):
        describe(Peeks())
    info = describe(GoalVectorPolicy(3))
    assert info == {"protocol": "wanderland-nav-policy/1", "observes": ["goal_vector"], "num_waypoints": 3,
                    "context": 1, "image_size": None}
    with pytest.raises(ValueError, match="expected 'package.module:ClassName'"):
        load_target("wanderland_nav.external.examples.GoalVectorPolicy")
    assert isinstance(load_target("wanderland_nav.external.examples:GoalVectorPolicy", {"num_waypoints": 2}),
                      GoalVectorPolicy)


def test_check_waypoints_names_what_is_wrong():
    assert check_waypoints(np.zeros((2, 5, 2)), 2, 5).dtype == np.float32
    assert check_waypoints(np.zeros((2, 4, 2)), 2, 5) == "returned shape [2, 4, 2], expected [2, 5, 2]"
    assert "non-finite" in check_waypoints(np.full((2, 5, 2), np.inf), 2, 5)
    assert "not an array" in check_waypoints({"a": 1}, 2, 5)


def test_actor_writes_actions_and_tells_the_policy_which_agents_start_an_episode():
    seen = {}

    class Spy(GoalVectorPolicy):
        def act(self, obs):
            seen.update(obs)
            return super().act(obs)

    actor = ExternalActor(Spy(), name="spy")
    td = actor(_td())
    np.testing.assert_allclose(td.get(keys.ACTION).numpy(), GoalVectorPolicy().act(_obs()))
    assert set(seen) == {keys.GOAL_VECTOR, NEW_EPISODE}  # only the declared keys: no privileged ones
    assert seen[NEW_EPISODE].tolist() == [True, False, True]
    assert actor.failures == {}
    assert actor.config.env_requirements().num_waypoints == 5 and actor.in_keys == [keys.GOAL_VECTOR]


def test_actor_fails_the_step_per_episode_then_gives_up_after_failures_in_a_row():
    pol = FaultyPolicy("raise", at=1)
    actor = ExternalActor(pol, name="faulty", max_consecutive_failures=2)
    assert torch.isfinite(actor(_td()).get(keys.ACTION)).all()
    td = actor(_td(episodes=(4, 5, 6)))
    assert torch.isnan(td.get(keys.ACTION)).all()
    assert actor.failures == {e: "raised RuntimeError: policy failure on purpose" for e in (4, 5, 6)}
    actor(_td(episodes=(4, 5, 10)))
    assert "given up" in actor.failures[10] and pol.calls == 3
    actor(_td())
    assert pol.calls == 3  # given up: not called again


def test_actor_gives_up_on_a_hung_policy_after_one_time_limit():
    pol = FaultyPolicy("hang", at=0, hang_s=3.0)
    actor = ExternalActor(pol, timeout_s=0.2)
    t = time.perf_counter()
    for _ in range(5):
        assert torch.isnan(actor(_td()).get(keys.ACTION)).all()
    assert time.perf_counter() - t < 2.0 and pol.calls == 1
    assert actor.failures[7].startswith("no answer within 0.2 s")
    actor.close()


def test_wire_round_trip_keeps_dtypes_and_refuses_garbage():
    arrays = {"rgb": np.arange(2 * 3 * 8 * 8 * 3, dtype=np.uint8).reshape(2, 3, 8, 8, 3) % 255,
              "goal_vector": np.ones((2, 2), np.float32), NEW_EPISODE: np.array([True, False])}
    back = unpack(pack(arrays), "test")
    assert set(back) == set(arrays)
    for k in arrays:
        assert back[k].dtype == arrays[k].dtype and np.array_equal(back[k], arrays[k])
    with pytest.raises(ValueError, match="reply: not a .npz array bundle"):
        unpack(b"not an npz", "reply")


# --------------------------------------------------------------------------- over HTTP


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """`python -m wanderland_nav.serve_policy` in a subprocess on a free localhost port."""
    run_dir = tmp_path_factory.mktemp("serve")
    proc = subprocess.Popen([sys.executable, "-m", "wanderland_nav.serve_policy",
                             "target=wanderland_nav.external.examples:GoalVectorPolicy", "port=0",
                             f"hydra.run.dir={run_dir}"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env={**__import__("os").environ, "PYTHONPATH": str(REPO)})
    try:
        line = proc.stdout.readline()  # "serving GoalVectorPolicy at http://127.0.0.1:<port>"
        assert line.startswith("serving GoalVectorPolicy at http://127.0.0.1:"), line + proc.stdout.read()
        yield line.split(" at ")[1].strip()
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_remote_policy_in_a_subprocess_answers_like_the_in_process_one(served):
    remote = RemotePolicy(served, timeout_s=10)
    assert remote.observes == (keys.GOAL_VECTOR,) and remote.num_waypoints == 5 and remote.image_size is None
    for _ in range(3):  # one kept-alive connection
        np.testing.assert_array_equal(remote.act(_obs()), GoalVectorPolicy().act(_obs()).astype(np.float32))
    td = ExternalActor(remote, name="remote")(_td())
    np.testing.assert_allclose(td.get(keys.ACTION).numpy(), GoalVectorPolicy().act(_obs()))
    remote.close()


def _thread_server(server):
    t = threading.Thread(target=server.serve_forever, daemon=True)
    t.start()
    return server


def test_remote_errors_are_clear():
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(RemotePolicyError, match="connection refused: no policy server is running"):
        RemotePolicy(f"http://127.0.0.1:{port}", timeout_s=2)
    with pytest.raises(ValueError, match="expected http://host:port"):
        RemotePolicy("ftp://127.0.0.1:1")

    server = _thread_server(PolicyServer(FaultyPolicy("raise", at=1)))
    remote = RemotePolicy(server.url, timeout_s=5)
    assert remote.act(_obs()).shape == (3, 5, 2)
    with pytest.raises(RemotePolicyError, match="status 500: policy raised RuntimeError: policy failure on purpose"):
        remote.act(_obs())
    remote.close()
    server.shutdown()
    server.server_close()

    server = _thread_server(PolicyServer(FaultyPolicy("hang", at=0, hang_s=2.0)))
    remote = RemotePolicy(server.url, timeout_s=0.3)
    with pytest.raises(RemotePolicyError, match="no answer within 0.3 s"):
        remote.act(_obs())
    remote.close()
    server.shutdown()
    server.server_close()


class _Garbage(BaseHTTPRequestHandler):
    """Answers every request with the same bytes: not this protocol."""

    protocol_version = "HTTP/1.1"
    body, ctype = b'{"protocol": "wanderland-nav-policy/1", "observes": ["goal_vector"], "num_waypoints": 5, ' \
                  b'"context": 1, "image_size": null}', "application/json"

    def _answer(self):
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        body, ctype = (self.body, self.ctype) if self.path == "/info" else (b"garbage", "application/x-npz")
        self.send_response(200)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    do_GET = do_POST = _answer

    def log_message(self, *args):
        pass


def test_malformed_answers_are_named():
    server = _thread_server(HTTPServer(("127.0.0.1", 0), _Garbage))
    url = f"http://127.0.0.1:{server.server_address[1]}"
    remote = RemotePolicy(url, timeout_s=5)
    with pytest.raises(RemotePolicyError, match=r"/act: not a .npz array bundle"):
        remote.act(_obs())
    actor = ExternalActor(remote, name="garbage")  # during an evaluation: a failed step, counted per episode
    assert torch.isnan(actor(_td()).get(keys.ACTION)).all() and "not a .npz" in actor.failures[9]
    remote.close()  # the plain server answers one connection at a time
    _Garbage.body = b'{"protocol": "something else"}'
    with pytest.raises(RemotePolicyError, match="expected 'wanderland-nav-policy/1'"):
        RemotePolicy(url, timeout_s=5)
    server.shutdown()
    server.server_close()
