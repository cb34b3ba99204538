"""NavDP's policy-server contract (InternRobotics/NavDP, `utils_tasks/client_utils.py` and `baselines/*/*_server.py`),
both sides: `NavDPPolicy` calls a server of theirs as a protocol policy; `NavDPServer` serves any protocol policy
so their benchmark can call it.

The contract, as their client and servers speak it:

* `POST /navigator_reset`, JSON `{"intrinsic": 3x3, "stop_threshold": float, "batch_size": B}` -> `{"algo": name}`:
  a fresh batch of B envs;
* `POST /navigator_reset_env`, JSON `{"env_id": i}` -> `{"algo": name}`: env i starts a new episode;
* `POST /pointgoal_step` | `/imagegoal_step` | `/nogoal_step`, multipart form: file `image` (JPEG of the B RGB
  frames stacked vertically, `[B*H, W, 3]`), file `depth` (16-bit PNG, depth in units of 0.1 mm, clipped to
  65535), `/imagegoal_step` also file `goal` (JPEG, goal views stacked the same way), `/pointgoal_step` also field
  `goal_data` = JSON `{"goal_x": [B], "goal_y": [B]}` (metres, robot frame: x forward, y left), and fields
  `rgb_time`, `depth_time` -> JSON `{"trajectory": [B, L, C], "all_trajectory": [B, S, L, C], "all_values": [B, S]}`,
  the trajectory in the robot frame (x forward, y left, metres; C >= 2, the first two are x, y).

Colour order: their client writes the RGB array with OpenCV's `imencode`, which takes it for BGR, and their
servers decode with PIL and swap the channels back (`cv2.cvtColor(..., RGB2BGR)`): the JPEG bytes hold the image
with red and blue exchanged, and both ends see the array the env rendered. `encode_rgb` / `decode_rgb` do the
same (with PIL; JPEG quality 95, OpenCV's default), so their servers receive what their own client sends.

The client maps a trajectory of L points onto the K waypoints it declares: the points at K evenly spaced indices
of the trajectory after its first (their trajectories start at the robot; the last point is always kept), the
last repeated when L <= K. A stop (their servers zero the trajectory) stays a stop.
"""

from __future__ import annotations

import email.parser
import email.policy
import http.client
import io
import json
import logging
import math
import threading
import time
import uuid
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import urlsplit

import numpy as np
from PIL import Image

from wanderland_nav import keys
from wanderland_nav.external.protocol import NEW_EPISODE, ExternalPolicy, describe
from wanderland_nav.external.server import MAX_BODY_BYTES, drain_refused, is_loopback, request_refusal

log = logging.getLogger(__name__)

STEPS = {"point": "/pointgoal_step", "image": "/imagegoal_step", "none": "/nogoal_step"}
GOAL_KEY = {"point": keys.GOAL_VECTOR, "image": keys.GOAL_IMAGE, "none": None}
DEPTH_SCALE = 10000.0   # PNG units per metre (0.1 mm)
JPEG_QUALITY = 95       # OpenCV's imencode default
MAX_BATCH = 1024        # envs one /navigator_reset may ask for
MAX_PIXELS = 1 << 25    # pixels of one stacked image a server decodes (a PNG or JPEG inflates far beyond its bytes)


class NavDPError(RuntimeError):
    """A NavDP server that is unreachable, or answered outside the contract."""


# ---------------------------------------------------------------------------------------------- images
def encode_rgb(frames: np.ndarray) -> bytes:
    """uint8 `[B, H, W, 3]` RGB -> the JPEG their client sends (stacked vertically, channels as OpenCV writes them)."""
    stacked = np.ascontiguousarray(np.asarray(frames, dtype=np.uint8).reshape(-1, frames.shape[-2], 3)[..., ::-1])
    buf = io.BytesIO()
    Image.fromarray(stacked, "RGB").save(buf, format="JPEG", quality=JPEG_QUALITY)
    return buf.getvalue()


def _open_bounded(data: bytes) -> Image.Image:
    """The image, refused from its header (before any pixel is decoded) when it holds more than `MAX_PIXELS`."""
    img = Image.open(io.BytesIO(data))
    if img.width * img.height > MAX_PIXELS:
        raise ValueError(f"image of {img.width} x {img.height} pixels, above the limit of {MAX_PIXELS}")
    return img


def decode_rgb(data: bytes, batch: int) -> np.ndarray:
    """The JPEG -> uint8 `[B, H, W, 3]` as their servers hold it after their channel swap."""
    img = np.asarray(_open_bounded(data).convert("RGB"))[..., ::-1]
    if img.shape[0] % batch:
        raise ValueError(f"image of {img.shape[0]} rows does not stack {batch} frames")
    return np.ascontiguousarray(img.reshape(batch, -1, img.shape[1], 3))


def encode_depth(depth: np.ndarray) -> bytes:
    """float metres `[B, H, W]` (or `[B, H, W, 1]`) -> 16-bit PNG in 0.1 mm, stacked vertically."""
    d = np.asarray(depth, dtype=np.float32)
    d = d.reshape(-1, d.shape[2])  # [B, H, W] or [B, H, W, 1] -> [B*H, W]
    buf = io.BytesIO()
    Image.fromarray(np.clip(d * DEPTH_SCALE, 0, 65535.0).astype(np.uint16)).save(buf, format="PNG")
    return buf.getvalue()


def decode_depth(data: bytes, batch: int) -> np.ndarray:
    """The PNG -> float32 metres `[B, H, W, 1]` (their servers: `convert('I')`, / 10000)."""
    d = np.asarray(_open_bounded(data).convert("I")).astype(np.float32) / DEPTH_SCALE
    return d.reshape(batch, -1, d.shape[1], 1)


# ---------------------------------------------------------------------------------------------- forms
def multipart(fields: dict[str, str], files: dict[str, tuple[str, bytes, str]]) -> tuple[bytes, str]:
    """A `multipart/form-data` body (as `requests.post(files=..., data=...)` sends) and its Content-Type."""
    boundary = uuid.uuid4().hex
    out = io.BytesIO()
    for name, value in fields.items():
        out.write(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'.encode())
    for name, (filename, data, ctype) in files.items():
        out.write(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; filename="{filename}"\r\n'
                  f"Content-Type: {ctype}\r\n\r\n".encode())
        out.write(data)
        out.write(b"\r\n")
    out.write(f"--{boundary}--\r\n".encode())
    return out.getvalue(), f"multipart/form-data; boundary={boundary}"


def parse_form(body: bytes, content_type: str) -> dict[str, bytes]:
    """A `multipart/form-data` body -> `{field name: bytes}` (files and plain fields alike)."""
    if not content_type.startswith("multipart/form-data"):
        raise ValueError(f"expected multipart/form-data, got Content-Type {content_type!r}")
    msg = email.parser.BytesParser(policy=email.policy.HTTP).parsebytes(
        f"Content-Type: {content_type}\r\n\r\n".encode() + body)
    out = {}
    for part in msg.iter_parts():
        name = part.get_param("name", header="content-disposition")
        if name:
            out[name] = part.get_payload(decode=True) or b""
    return out


def waypoints_from_trajectory(traj: np.ndarray, k: int) -> np.ndarray:
    """`[B, L, C]` trajectory -> `[B, K, 2]`: x, y at K evenly spaced indices after the first, the last kept."""
    traj = np.asarray(traj, dtype=np.float32)
    if traj.ndim != 3 or traj.shape[1] < 1 or traj.shape[2] < 2:
        raise ValueError(f"trajectory must be [B, L, C >= 2], got shape {list(traj.shape)}")
    n = traj.shape[1]
    if n == 1:
        idx = np.zeros(k, dtype=int)
    else:
        idx = np.minimum(np.ceil(np.arange(1, k + 1) * (n - 1) / k).astype(int), n - 1)
    return traj[:, idx, :2]


def pinhole_intrinsic(height: int, width: int, hfov_deg: float) -> list[list[float]]:
    """The 3 x 3 intrinsic of a centred pinhole camera with horizontal field of view `hfov_deg`."""
    f = 0.5 * width / math.tan(math.radians(hfov_deg) / 2)
    return [[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]]


# ---------------------------------------------------------------------------------------------- client
class NavDPPolicy(ExternalPolicy):
    """A NavDP policy server at `url` as a protocol policy. `goal`: which step it calls (point / image / none),
    hence what it observes (RGB, depth and the goal vector / goal view / nothing)."""

    def __init__(self, url: str, goal: str = "point", num_waypoints: int = 8, image_size=None, hfov_deg: float = 90.0,
                 stop_threshold: float = -3.0, timeout_s: float = 30.0):
        parts = urlsplit(str(url))
        if parts.scheme != "http" or not parts.hostname or parts.path not in ("", "/"):
            raise ValueError(f"navdp_url={url!r}: expected http://host:port")
        if goal not in STEPS:
            raise ValueError(f"navdp goal={goal!r}: expected one of {sorted(STEPS)}")
        self.url, self.goal, self.timeout_s = f"http://{parts.netloc}", goal, float(timeout_s)
        self._host, self._port = parts.hostname, parts.port or 80
        self.observes = (keys.RGB, keys.DEPTH) + ((GOAL_KEY[goal],) if GOAL_KEY[goal] else ())
        self.num_waypoints, self.context = int(num_waypoints), 1
        self.image_size = tuple(image_size) if image_size else None
        self.hfov_deg, self.stop_threshold = float(hfov_deg), float(stop_threshold)
        self.algo: str | None = None
        self._batch: int | None = None
        self._conn: http.client.HTTPConnection | None = None
        self.seconds = {"encode": 0.0, "http": 0.0, "decode": 0.0}

    def _post(self, path: str, body: bytes, ctype: str):
        where = f"{self.url}{path}"
        try:
            if self._conn is None:
                self._conn = http.client.HTTPConnection(self._host, self._port, timeout=self.timeout_s)
            self._conn.request("POST", path, body=body, headers={"Content-Type": ctype})
            resp = self._conn.getresponse()
            status, data = resp.status, resp.read()
        except (OSError, http.client.HTTPException) as e:
            self.close()
            raise NavDPError(f"{where}: {type(e).__name__}: {e}") from None
        try:
            payload = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise NavDPError(f"{where}: status {status}, not JSON: {data[:80]!r}") from None
        if status != 200:
            raise NavDPError(f"{where}: status {status}: {payload}")
        return payload

    def _json(self, path: str, obj) -> dict:
        payload = self._post(path, json.dumps(obj).encode(), "application/json")
        if not isinstance(payload, dict) or "algo" not in payload:
            raise NavDPError(f"{self.url}{path}: answer {payload!r} has no 'algo'")
        return payload

    def reset(self, batch: int, height: int, width: int) -> None:
        """`/navigator_reset` for a fresh batch of `batch` envs."""
        self.algo = str(self._json("/navigator_reset", {"intrinsic": pinhole_intrinsic(height, width, self.hfov_deg),
                                                        "stop_threshold": self.stop_threshold,
                                                        "batch_size": int(batch)})["algo"])
        self._batch = int(batch)

    def act(self, obs) -> np.ndarray:
        rgb = np.asarray(obs[keys.RGB])[:, -1]                         # [B, H, W, 3] the current frame
        b, h, w = rgb.shape[:3]
        new = np.asarray(obs.get(NEW_EPISODE, np.ones(b, dtype=bool))).reshape(b)
        if self._batch != b:
            self.reset(b, h, w)
        else:
            for i in np.flatnonzero(new):
                self._json("/navigator_reset_env", {"env_id": int(i)})
        t0 = time.perf_counter()
        files = {"image": ("image.jpg", encode_rgb(rgb), "image/jpeg"),
                 "depth": ("depth.png", encode_depth(np.asarray(obs[keys.DEPTH])[:, -1]), "image/png")}
        now = str(time.time())
        fields = {"depth_time": now, "rgb_time": now}
        if self.goal == "point":
            g = np.asarray(obs[keys.GOAL_VECTOR], dtype=np.float64).reshape(b, 2)
            fields["goal_data"] = json.dumps({"goal_x": g[:, 0].tolist(), "goal_y": g[:, 1].tolist()})
        elif self.goal == "image":
            files["goal"] = ("goal.jpg", encode_rgb(np.asarray(obs[keys.GOAL_IMAGE])), "image/jpeg")
        body, ctype = multipart(fields, files)
        t1 = time.perf_counter()
        answer = self._post(STEPS[self.goal], body, ctype)
        t2 = time.perf_counter()
        if not isinstance(answer, dict) or "trajectory" not in answer:
            raise NavDPError(f"{self.url}{STEPS[self.goal]}: answer has no 'trajectory'")
        traj = np.asarray(answer["trajectory"], dtype=np.float32)
        if traj.ndim != 3 or traj.shape[0] != b:
            raise NavDPError(f"{self.url}{STEPS[self.goal]}: trajectory of shape {list(traj.shape)}, expected [{b}, L, C]")
        out = waypoints_from_trajectory(traj, self.num_waypoints)
        self.seconds["encode"] += t1 - t0
        self.seconds["http"] += t2 - t1
        self.seconds["decode"] += time.perf_counter() - t2
        return out

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None


# ---------------------------------------------------------------------------------------------- server
class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def _send_json(self, status: int, obj) -> None:
        body = json.dumps(obj).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_POST(self):  # noqa: N802 (http.server's naming)
        srv: NavDPServer = self.server
        form_path = self.path not in ("/navigator_reset", "/navigator_reset_env")
        refusal = request_refusal(self.headers, srv, ("multipart/form-data",) if form_path else ("application/json",))
        if refusal is not None:
            drain_refused(self, refusal[0])  # a body above the limit is never read
            return self._send_json(refusal[0], {"error": refusal[1]})
        body = self.rfile.read(int(self.headers["Content-Length"]))
        try:
            with srv.lock:
                if self.path == "/navigator_reset":
                    req = json.loads(body.decode("utf-8"))
                    srv.reset(int(req["batch_size"]))
                    return self._send_json(200, {"algo": srv.algo})
                if self.path == "/navigator_reset_env":
                    srv.reset_env(int(json.loads(body.decode("utf-8"))["env_id"]))
                    return self._send_json(200, {"algo": srv.algo})
                goal = {v: k for k, v in STEPS.items()}.get(self.path)
                if goal is None:
                    return self._send_json(404, {"error": f"no {self.path}; POST /navigator_reset, "
                                                          f"/navigator_reset_env, {', '.join(STEPS.values())}"})
                form = parse_form(body, self.headers.get("Content-Type", ""))
                traj = srv.step(goal, form)
        except (KeyError, ValueError, TypeError, json.JSONDecodeError) as e:
            return self._send_json(400, {"error": f"{self.path}: {type(e).__name__}: {e}"})
        except Exception as e:  # the policy's error goes back to the client; the server keeps serving
            log.exception("policy raised")
            return self._send_json(500, {"error": f"policy raised {type(e).__name__}: {e}"})
        b = traj.shape[0]
        traj = np.concatenate([np.zeros((b, 1, 2), np.float32), traj], axis=1)  # theirs start at the robot
        self._send_json(200, {"trajectory": traj.tolist(), "all_trajectory": traj[:, None].tolist(),
                              "all_values": np.zeros((b, 1)).tolist()})

    def log_message(self, fmt, *args):
        log.debug(fmt, *args)


class NavDPServer(ThreadingHTTPServer):
    """Any protocol policy behind NavDP's contract. The server keeps each env's last `context` frames (their
    servers keep the history; their requests carry the current frame), cleared by `/navigator_reset_env`, and flags
    `NEW_EPISODE` on an env's first step. Its answer: the robot's position then the policy's K waypoints as the
    trajectory (`[B, K + 1, 2]`, their trajectories start at the robot),
    `all_trajectory` that one trajectory, `all_values` zeros (a protocol policy has no value estimate; the
    visualnav baselines' servers answer zeros too). `stop_threshold` and the intrinsic are accepted and unused.
    A policy reading keys the contract does not carry (past positions, instructions) is refused."""

    daemon_threads = True

    def __init__(self, policy, host: str = "127.0.0.1", port: int = 0, algo: str | None = None, *,
                 max_body_bytes: int = MAX_BODY_BYTES, allowed_hosts: tuple[str, ...] = ()):
        info = describe(policy)
        carried = {keys.RGB, keys.DEPTH, keys.GOAL_VECTOR, keys.GOAL_IMAGE, keys.HAS_GOAL_IMAGE}
        missing = [k for k in info["observes"] if k not in carried]
        if missing:
            raise ValueError(f"{type(policy).__name__} reads {missing}, which NavDP's contract does not carry "
                             f"(it sends RGB, depth and a point or image goal)")
        self.policy, self.info, self.lock = policy, info, threading.Lock()
        self.algo = algo or type(policy).__name__
        self.batch = 0
        self.history: list[list[np.ndarray]] = []
        self.depths: list[list[np.ndarray]] = []
        self.new = np.zeros(0, dtype=bool)
        self.max_body_bytes, self.allowed_hosts = int(max_body_bytes), tuple(allowed_hosts)
        super().__init__((host, int(port)), _Handler)
        if not is_loopback(host):
            log.warning("serving %s (NavDP contract) on %s, not a loopback address: anyone who can reach port %d can "
                        "drive the policy", type(policy).__name__, host, self.server_address[1])

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}"

    def reset(self, batch: int) -> None:
        if not 1 <= batch <= MAX_BATCH:
            raise ValueError(f"batch_size={batch} outside [1, {MAX_BATCH}]")
        self.batch = batch
        self.history = [[] for _ in range(batch)]
        self.depths = [[] for _ in range(batch)]
        self.new = np.ones(batch, dtype=bool)

    def reset_env(self, i: int) -> None:
        if not 0 <= i < self.batch:
            raise ValueError(f"env_id={i} outside the batch of {self.batch} (call /navigator_reset first)")
        self.history[i], self.depths[i] = [], []
        self.new[i] = True

    def _stack(self, frames: list[list[np.ndarray]], current: np.ndarray) -> np.ndarray:
        """Append the current frames, keep `context`, repeat the oldest when fewer: `[B, context, ...]`."""
        c = self.info["context"]
        for i in range(self.batch):
            frames[i].append(current[i])
            del frames[i][:-c]
        return np.stack([np.stack([f[0]] * (c - len(f)) + f) for f in frames])

    def step(self, goal: str, form: dict[str, bytes]) -> np.ndarray:
        if self.batch == 0:
            raise ValueError("no /navigator_reset yet")
        obs = {keys.RGB: self._stack(self.history, decode_rgb(form["image"], self.batch))}
        if keys.DEPTH in self.info["observes"]:
            obs[keys.DEPTH] = self._stack(self.depths, decode_depth(form["depth"], self.batch))
        reads = self.info["observes"]
        if keys.GOAL_VECTOR in reads:
            if goal != "point":
                raise ValueError(f"the policy reads the goal vector; {STEPS[goal]} carries none")
            g = json.loads(form["goal_data"].decode("utf-8"))
            obs[keys.GOAL_VECTOR] = np.stack([g["goal_x"], g["goal_y"]], axis=1).astype(np.float32)
        if keys.GOAL_IMAGE in reads or keys.HAS_GOAL_IMAGE in reads:
            has = goal == "image"
            if keys.GOAL_IMAGE in reads and not has and keys.HAS_GOAL_IMAGE not in reads:
                raise ValueError(f"the policy reads a goal view; {STEPS[goal]} carries none")
            h, w = obs[keys.RGB].shape[2:4]
            obs[keys.GOAL_IMAGE] = decode_rgb(form["goal"], self.batch) if has else np.zeros((self.batch, h, w, 3), np.uint8)
            obs[keys.HAS_GOAL_IMAGE] = np.full((self.batch, 1), has)
        obs = {k: v for k, v in obs.items() if k in reads}
        obs[NEW_EPISODE] = self.new.copy()
        out = np.asarray(self.policy.act(obs), dtype=np.float32)
        self.new[:] = False
        return out
