"""`RemotePolicy`: a policy served over HTTP at one given address, as an in-process protocol policy.

Requests (`server.py` answers them):

* `GET /info` -> JSON `{"protocol": "wanderland-nav-policy/1", "observes", "num_waypoints", "context", "image_size"}`;
* `POST /act`, body: the observation dict as `.npz` (`wire.py`, `Content-Type: application/x-npz`) -> `200` with
  an `.npz` holding `waypoints` float32 `[B, K, 2]`, or an error status with JSON `{"error": "..."}`.

One persistent HTTP/1.1 connection, reopened after an error; every request carries `timeout_s`. The client talks
to the address it is given and nowhere else. A server that is down, answers another protocol or malformed data
raises `RemotePolicyError` saying which; at construction that stops the run before any episode, during an
evaluation `ExternalActor` counts it as a failed step.
"""

from __future__ import annotations

import http.client
import json
import socket
from urllib.parse import urlsplit

import numpy as np

from wanderland_nav.external.protocol import PROTOCOL, describe
from wanderland_nav.external.wire import CONTENT_TYPE, pack, unpack


MAX_ANSWER_BYTES = 16 << 20  # waypoints [B, K, 2] float32: 64 kB for 1024 agents of 8 waypoints


class RemotePolicyError(RuntimeError):
    """The remote policy is unreachable, too slow, or answered something unusable. `transport`: the server could
    not be reached or dropped the connection (it died, or the network did), which says nothing about the policy:
    an evaluation with such a failure is not a result (`ExternalActor.transport_error`)."""

    def __init__(self, message: str, *, transport: bool = False):
        super().__init__(message)
        self.transport = transport


class RemotePolicy:
    """The protocol policy served at `url` (`http://host:port`); its declaration is read from `/info`."""

    def __init__(self, url: str, timeout_s: float = 30.0):
        parts = urlsplit(str(url))
        if parts.scheme != "http" or not parts.hostname or parts.path not in ("", "/"):
            raise ValueError(f"policy.url={url!r}: expected http://host:port")
        self.url, self.timeout_s = f"http://{parts.netloc}", float(timeout_s)
        self._host, self._port = parts.hostname, parts.port or 80
        self._conn: http.client.HTTPConnection | None = None
        try:
            self._declare(self._json("GET", "/info"))
        except RemotePolicyError:
            self.close()
            raise

    def _declare(self, info) -> None:
        """Take the declaration `/info` answered, or refuse it."""
        if not isinstance(info, dict) or info.get("protocol") != PROTOCOL:
            raise RemotePolicyError(f"{self.url}/info: protocol {info.get('protocol') if isinstance(info, dict) else info!r}, "
                                    f"expected {PROTOCOL!r} (is this a wanderland_nav policy server?)")
        try:
            self.observes = tuple(info["observes"])
            self.num_waypoints, self.context = int(info["num_waypoints"]), int(info["context"])
            self.image_size = tuple(info["image_size"]) if info.get("image_size") else None
            describe(self)  # the same checks and bounds as an in-process policy's
        except (KeyError, TypeError, ValueError) as e:
            raise RemotePolicyError(f"{self.url}/info: malformed declaration {info!r} ({e})") from None

    def _request(self, method: str, path: str, body: bytes | None = None,
                 content_type: str | None = None) -> tuple[int, str, bytes]:
        where = f"{self.url}{path}"
        headers = {"Content-Type": content_type} if content_type else {}
        try:
            if self._conn is None:
                self._conn = http.client.HTTPConnection(self._host, self._port, timeout=self.timeout_s)
            self._conn.request(method, path, body=body, headers=headers)
            resp = self._conn.getresponse()
            return resp.status, resp.getheader("Content-Type", ""), resp.read()
        except (socket.timeout, TimeoutError):
            self.close()
            raise RemotePolicyError(f"{where}: no answer within {self.timeout_s:g} s") from None
        except ConnectionRefusedError:
            self.close()
            raise RemotePolicyError(f"{where}: connection refused: no policy server is running there (start one with "
                                    "python -m wanderland_nav.serve_policy target=pkg.mod:Class port=<port>)",
                                    transport=True) from None
        except (OSError, http.client.HTTPException) as e:
            self.close()
            raise RemotePolicyError(f"{where}: {type(e).__name__}: {e}", transport=True) from None

    def _json(self, method: str, path: str):
        status, _, data = self._request(method, path)
        try:
            payload = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise RemotePolicyError(f"{self.url}{path}: status {status}, not JSON: {data[:80]!r}") from None
        if status != 200:
            raise RemotePolicyError(f"{self.url}{path}: status {status}: {payload}")
        return payload

    def act(self, obs) -> np.ndarray:
        status, ctype, data = self._request("POST", "/act", pack(obs), CONTENT_TYPE)
        where = f"{self.url}/act"
        if status != 200:
            try:
                msg = json.loads(data.decode("utf-8")).get("error", "")
            except (UnicodeDecodeError, json.JSONDecodeError, AttributeError):
                msg = repr(data[:80])
            raise RemotePolicyError(f"{where}: status {status}: {msg}")
        if not ctype.startswith(CONTENT_TYPE):
            raise RemotePolicyError(f"{where}: answered Content-Type {ctype!r}, expected {CONTENT_TYPE}")
        try:
            arrays = unpack(data, where, max_bytes=MAX_ANSWER_BYTES, keys=("waypoints",))
        except ValueError as e:
            raise RemotePolicyError(str(e)) from None
        if "waypoints" not in arrays:
            raise RemotePolicyError(f"{where}: answer has {sorted(arrays)}, no 'waypoints'")
        return arrays["waypoints"]

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
