"""`PolicyServer`: any protocol policy answering `remote.py`'s requests over HTTP (stdlib `http.server`).

Each client connection has its own thread, and the policy answers one request at a time (a stateful policy sees
its steps in order; an idle kept-alive connection blocks nobody); bound to `127.0.0.1` unless told otherwise.
A policy that raises answers `500` with its error; a request that is not an `.npz` answers `400`. The command
line is `python -m wanderland_nav.serve_policy` (a `target=` class or a trained `checkpoint=`).

Checked on every request, as local web services (Jupyter's server) do, because any web page a browser on this
machine opens can send requests to `127.0.0.1`:

* `Host` must be an IP address, `localhost`, or one of `allowed_hosts` (else `403`): a page that rebinds its
  own DNS name to 127.0.0.1 sends its name as `Host`, and is refused (DNS rebinding); an `Origin`, which
  browsers send with every cross-site POST and script clients never do, must name the same (else `403`);
* `POST /act` must say `Content-Type: application/x-npz` (else `415`): an HTML form can only send
  `application/x-www-form-urlencoded`, `multipart/form-data` or `text/plain`, and a script on another origin
  setting any other type needs a CORS pre-flight, which this server never grants;
* its `Content-Length` must be given (`411`) and at most `max_body_bytes` (`413`, the body left unread);
* its arrays are bounded before they are decompressed or allocated (`wire.unpack`: the sizes the zip declares
  at most `max_array_bytes`, each `.npy` header's shape within its member, only the declared observation keys
  and `new_episode`), else `400`.

A server bound to any other address than a loopback one says so with a warning: the policy then answers anyone
who can reach the port.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import urlsplit

import numpy as np

from wanderland_nav.external.protocol import NEW_EPISODE, describe
from wanderland_nav.external.wire import CONTENT_TYPE, pack, unpack

log = logging.getLogger(__name__)

MAX_BODY_BYTES = 64 << 20  # 64 MiB: eight agents' 8-frame 224 x 224 RGB history is under 10 MiB
LOOPBACK_NAMES = ("localhost", "localhost.")


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host.strip("[]"))
        return True
    except ValueError:
        return False


def host_allowed(header: str | None, allowed: tuple[str, ...] = ()) -> bool:
    """Whether a request's `Host` header names this server without a DNS name a web page could rebind."""
    try:
        host = urlsplit(f"//{header}").hostname if header else None  # "[::1]:8765" -> "::1"
    except ValueError:
        return False
    return bool(host) and (_is_ip(host) or host in LOOPBACK_NAMES or host in {h.lower() for h in allowed})


def is_loopback(host: str) -> bool:
    if host.lower() in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def request_refusal(headers, server, content_types: tuple[str, ...] | None = None) -> tuple[int, str] | None:
    """Why a request is refused (`(status, message)`), or None: `Host` and `Origin` must name this machine
    without a DNS name a page could rebind (a browser sends `Origin` on every cross-site POST, a script client
    none); with `content_types` (a POST), its `Content-Type` must be one of them and its `Content-Length` given
    and at most `server.max_body_bytes`. One check for every server of the project's."""
    allowed = server.allowed_hosts
    if not host_allowed(headers.get("Host"), allowed):
        return 403, (f"Host {headers.get('Host')!r} refused: expected an IP address, localhost or one of "
                     f"allowed_hosts {list(allowed)}")
    origin = headers.get("Origin")
    if origin is not None and not host_allowed(urlsplit(origin).netloc or None, allowed):
        return 403, f"Origin {origin!r} refused: a page of another site may not drive the policy"
    if content_types is None:
        return None
    ctype = (headers.get("Content-Type") or "").split(";")[0].strip().lower()
    length = headers.get("Content-Length")
    limit = server.max_body_bytes
    if ctype not in content_types:
        return 415, f"Content-Type {ctype or None!r}: expected {' or '.join(content_types)}"
    if length is None or not length.strip().isdigit():
        return 411, "Content-Length required"
    if int(length) > limit:
        return 413, f"body of {int(length)} bytes, above the limit of {limit} bytes"
    return None


def drain_refused(handler, status: int) -> None:
    """Read a refused request's body when it is within the limit (never a 413's), so the connection closes cleanly:
    a socket closed with unread bytes sends a reset, which can reach the client before it reads the refusal."""
    handler.close_connection = True
    length = handler.headers.get("Content-Length") or ""
    if status != 413 and length.strip().isdigit() and int(length) <= handler.server.max_body_bytes:
        handler.rfile.read(int(length))


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

    def _host_refused(self) -> bool:
        refusal = request_refusal(self.headers, self.server)
        if refusal is None:
            return False
        drain_refused(self, refusal[0])
        self._error(*refusal)
        return True

    def do_GET(self):  # noqa: N802 (http.server's naming)
        if self._host_refused():
            return
        if self.path != "/info":
            return self._error(404, f"no {self.path}; GET /info, POST /act")
        self._send(200, json.dumps(self.server.info).encode(), "application/json")

    def do_POST(self):  # noqa: N802
        refusal = request_refusal(self.headers, self.server, (CONTENT_TYPE,))
        if refusal is not None:
            drain_refused(self, refusal[0])  # a body above the limit is never read
            return self._error(*refusal)
        body = self.rfile.read(int(self.headers["Content-Length"]))
        if self.path != "/act":
            return self._error(404, f"no {self.path}; GET /info, POST /act")
        try:
            obs = unpack(body, "request body", max_bytes=self.server.max_array_bytes,
                         keys={*self.server.info["observes"], NEW_EPISODE})
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
    """`PolicyServer(policy, host, port)`; `port=0` picks a free one (`url` says which). `serve_forever()` runs it.

    max_body_bytes: the largest request body read; max_array_bytes: the most its arrays may hold uncompressed
    (default: `max_body_bytes`, since the client sends them uncompressed); allowed_hosts: host names besides
    IP addresses and localhost that a request's `Host` may carry (a name this machine is reached by)."""

    daemon_threads = True

    def __init__(self, policy, host: str = "127.0.0.1", port: int = 0, *, max_body_bytes: int = MAX_BODY_BYTES,
                 max_array_bytes: int | None = None, allowed_hosts: tuple[str, ...] = ()):
        self.policy, self.info, self.lock = policy, describe(policy), threading.Lock()
        self.max_body_bytes = int(max_body_bytes)
        self.max_array_bytes = int(max_array_bytes if max_array_bytes is not None else max_body_bytes)
        self.allowed_hosts = tuple(allowed_hosts)
        super().__init__((host, int(port)), _Handler)
        if not is_loopback(host):
            log.warning("serving %s on %s, not a loopback address: anyone who can reach port %d can drive the policy "
                        "(bind 127.0.0.1 unless the evaluator runs on another machine)", type(policy).__name__, host,
                        self.server_address[1])

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}"
