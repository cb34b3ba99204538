"""`PolicyServer`: any protocol policy answering `remote.py`'s requests over HTTP (stdlib `http.server`).

Each client connection has its own thread, and the policy answers one request at a time (a stateful policy sees
its steps in order; an idle kept-alive connection blocks nobody); bound to `127.0.0.1` unless told otherwise.
A policy that raises answers `500` with its error; a request that is not an `.npz` answers `400`. The command
line is `python -m wanderland_nav.serve_policy` (a `target=` class or a trained `checkpoint=`).
"""

from __future__ import annotations

import json
import logging
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

from wanderland_nav.external.protocol import describe
from wanderland_nav.external.wire import CONTENT_TYPE, pack, unpack

log = logging.getLogger(__name__)


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"  # keep-alive: one connection per client

    def _send(self, status: int, body: bytes, ctype: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def _error(self, status: int, msg: str) -> None:
        self._send(status, json.dumps({"error": msg}).encode(), "application/json")

    def do_GET(self):  # noqa: N802 (http.server's naming)
        if self.path != "/info":
            return self._error(404, f"no {self.path}; GET /info, POST /act")
        self._send(200, json.dumps(self.server.info).encode(), "application/json")

    def do_POST(self):  # noqa: N802
        body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
        if self.path != "/act":
            return self._error(404, f"no {self.path}; GET /info, POST /act")
        try:
            obs = unpack(body, "request body")
        except ValueError as e:
            return self._error(400, str(e))
        try:
            with self.server.lock:
                out = np.asarray(self.server.policy.act(obs), dtype=np.float32)
        except Exception as e:  # the policy's error goes back to the client, the server keeps serving
            log.exception("policy raised")
            return self._error(500, f"policy raised {type(e).__name__}: {e}")
        self._send(200, pack({"waypoints": out}), CONTENT_TYPE)

    def log_message(self, fmt, *args):  # per-request lines to the logger, not stderr
        log.debug(fmt, *args)


class PolicyServer(ThreadingHTTPServer):
    """`PolicyServer(policy, host, port)`; `port=0` picks a free one (`url` says which). `serve_forever()` runs it."""

    daemon_threads = True

    def __init__(self, policy, host: str = "127.0.0.1", port: int = 0):
        self.policy, self.info, self.lock = policy, describe(policy), threading.Lock()
        super().__init__((host, int(port)), _Handler)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}"
