"""A resumable benchmark stores only results: a dead policy server's evaluation is not one, a rerun with every
evaluation stored needs no server, and a hung in-process policy never keeps the process alive."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from wanderland_nav.benchmark import run
from wanderland_nav.compose import compose_config
from wanderland_nav.external.examples import GoalVectorPolicy
from wanderland_nav.external.server import PolicyServer, _Handler

FIXTURE_NAV = "navigation.collision.voxel_size=0.25"
REPO = Path(__file__).resolve().parents[2]


def _cfg(scene, out, url):
    return compose_config("benchmark", [f"scene={scene}", FIXTURE_NAV, f"out={out}", "progress=false", "batch_size=4",
                                        "num_episodes=4", "env.termination.max_steps=60", "tasks=[pointgoal]",
                                        f"policies=[{{name: served, url: '{url}'}}]"])


class _DiesAfter(_Handler):
    """Answers `die_after` requests to /act, then drops the connection and stops listening (a crashed server)."""

    def do_POST(self):  # noqa: N802
        self.server.acts += 1
        if self.server.acts > self.server.die_after:
            self.server.socket.close()
            self.close_connection = True
            return  # no answer: the client sees the connection closed
        super().do_POST()


def _serve(port=0, die_after=None):
    server = PolicyServer(GoalVectorPolicy(), port=port)
    if die_after is not None:
        server.RequestHandlerClass, server.acts, server.die_after = _DiesAfter, 0, die_after
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def _stop(server):
    server.shutdown()
    server.server_close()


def test_a_dead_server_leaves_no_finished_evaluation_and_a_stored_benchmark_needs_no_server(
        prepared_demo_scene, demo_episodes, tmp_path):
    dying = _serve(die_after=5)
    url, port = dying.url, dying.server_address[1]
    res = run(_cfg(prepared_demo_scene, tmp_path, url))
    _stop(dying)
    stored = tmp_path / "runs" / "pointgoal" / "served.json"
    assert not stored.exists() and ("pointgoal", "served") not in res["results"]
    assert list(res["unfinished"]) == [("pointgoal", "served")]
    assert "pointgoal/served: not finished, nothing of it stored" in res["table"]
    assert "connection refused" in res["table"] or "RemoteDisconnected" in res["table"]

    healthy = _serve(port=port)  # the server back: the evaluation runs, and is stored
    try:
        res = run(_cfg(prepared_demo_scene, tmp_path, url))
    finally:
        _stop(healthy)
    recs = res["results"][("pointgoal", "served")]
    assert len(recs) == 4 and not any(r["policy_error"] for r in recs) and stored.is_file()

    again = run(_cfg(prepared_demo_scene, tmp_path, url))  # the server down, every evaluation stored
    assert again["results"] == res["results"] and not again["unfinished"]


def test_a_hung_in_process_policy_does_not_keep_the_process_alive(tmp_path):
    script = textwrap.dedent("""
        import numpy as np, torch
        from tensordict import TensorDict
        from wanderland_nav import keys
        from wanderland_nav.external import ExternalActor
        from wanderland_nav.external.examples import FaultyPolicy
        actor = ExternalActor(FaultyPolicy("hang", at=0, hang_s=120.0), timeout_s=0.2)
        td = TensorDict({keys.GOAL_VECTOR: torch.ones(2, 2)}, batch_size=[2])
        assert torch.isnan(actor(td).get(keys.ACTION)).all()
        actor.close()
        print("done", flush=True)
    """)
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "done" in proc.stdout, proc.stderr
    assert time.perf_counter() - t < 45.0  # the interpreter exits without waiting the 120 s hang
