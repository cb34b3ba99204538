"""The policy server refuses what a web page (or a hostile client) could send it; the client bounds a server."""

from __future__ import annotations

import http.client
import io
import logging
import threading
import zipfile

import numpy as np
import pytest

from wanderland_nav import keys
from wanderland_nav.external import ExternalPolicy, RemotePolicy, RemotePolicyError
from wanderland_nav.external.examples import GoalVectorPolicy
from wanderland_nav.external.protocol import NEW_EPISODE, describe
from wanderland_nav.external.server import PolicyServer
from wanderland_nav.external.wire import CONTENT_TYPE, pack, unpack


@pytest.fixture()
def server():
    s = PolicyServer(GoalVectorPolicy())
    s.max_body_bytes = s.max_array_bytes = 1 << 20  # 1 MiB: small enough to test
    t = threading.Thread(target=s.serve_forever, daemon=True)
    t.start()
    yield s
    s.shutdown()
    s.server_close()


def _obs():
    return {keys.GOAL_VECTOR: np.ones((2, 2), np.float32), NEW_EPISODE: np.ones(2, bool)}


def _post(server, body: bytes, headers: dict) -> tuple[int, str]:
    host, port = server.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=10)
    conn.putrequest("POST", "/act", skip_host=True, skip_accept_encoding=True)
    for k, v in headers.items():
        conn.putheader(k, v)
    conn.endheaders()
    if body:
        conn.send(body)
    resp = conn.getresponse()
    out = resp.status, resp.read().decode("utf-8", "replace")
    conn.close()
    return out


def _headers(server, body, **more):
    return {"Host": f"127.0.0.1:{server.server_address[1]}", "Content-Type": CONTENT_TYPE,
            "Content-Length": str(len(body)), **more}


def test_a_well_formed_request_is_answered(server):
    body = pack(_obs())
    status, _ = _post(server, body, _headers(server, body))
    assert status == 200
    for host in ("localhost:1", "[::1]:8765", "10.1.2.3:8765"):  # IP literals and localhost are never rebound names
        assert _post(server, body, _headers(server, body, Host=host))[0] == 200


def test_dns_rebinding_a_foreign_host_name_is_refused(server):
    body = pack(_obs())
    status, text = _post(server, body, _headers(server, body, Host=f"attacker.example:{server.server_address[1]}"))
    assert status == 403 and "Host 'attacker.example" in text
    assert _post(server, body, {k: v for k, v in _headers(server, body).items() if k != "Host"})[0] == 403
    host, port = server.server_address[:2]  # GET /info is guarded the same
    conn = http.client.HTTPConnection(host, port, timeout=10)
    conn.request("GET", "/info", headers={"Host": "attacker.example"})
    assert conn.getresponse().status == 403
    conn.close()


@pytest.mark.parametrize("ctype", [None, "text/plain", "application/x-www-form-urlencoded", "multipart/form-data"])
def test_a_cross_site_form_post_is_refused_by_its_content_type(server, ctype):
    body = pack(_obs())
    headers = _headers(server, body)
    if ctype is None:
        del headers["Content-Type"]
    else:
        headers["Content-Type"] = ctype
    status, text = _post(server, body, headers)
    assert status == 415 and "expected application/x-npz" in text


def test_an_oversized_body_is_refused_unread(server):
    status, text = _post(server, b"", _headers(server, b"", **{"Content-Length": str(2 << 30)}))
    assert status == 413 and "above the limit of 1048576 bytes" in text
    status, _ = _post(server, b"", {k: v for k, v in _headers(server, b"").items() if k != "Content-Length"})
    assert status == 411


def _bomb(declared: int) -> bytes:
    """An .npz whose one member deflates `declared` bytes of zeros into a few kilobytes."""
    buf = io.BytesIO()
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|u1", "fortran_order": False, "shape": (declared,)})
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf, zf.open(f"{keys.GOAL_VECTOR}.npy", "w",
                                                                         force_zip64=True) as f:
        f.write(header.getvalue())
        chunk = bytes(1 << 20)
        for _ in range(declared >> 20):
            f.write(chunk)
    return buf.getvalue()


def test_a_zip_bomb_is_refused_on_its_declared_size(server):
    body = _bomb(64 << 20)
    assert len(body) < 1 << 20  # under the body limit: only the declared size gives it away
    status, text = _post(server, body, _headers(server, body))
    assert status == 400 and "declare 67108992 bytes uncompressed" in text and "above the limit of 1048576" in text


def test_a_header_claiming_a_huge_shape_and_unknown_keys_are_refused(server):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf, zf.open(f"{keys.GOAL_VECTOR}.npy", "w") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (10**6, 10**6)})
        f.write(bytes(64))
    body = buf.getvalue()
    status, text = _post(server, body, _headers(server, body))
    assert status == 400 and "declares shape [1000000, 1000000]" in text and "holds 64 bytes" in text
    body = pack({**_obs(), "payload": np.zeros(3)})
    status, text = _post(server, body, _headers(server, body))
    assert status == 400 and "unexpected arrays ['payload']" in text
    with pytest.raises(ValueError, match="not a .npz array bundle"):
        unpack(b"garbage", "x")


def test_binding_beyond_loopback_warns(caplog):
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.external.server"):
        s = PolicyServer(GoalVectorPolicy(), host="0.0.0.0")
    s.server_close()
    assert "not a loopback address: anyone who can reach port" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="wanderland_nav.external.server"):
        PolicyServer(GoalVectorPolicy()).server_close()
    assert caplog.text == ""


@pytest.mark.parametrize("field,value,match", [("image_size", [100_000, 100_000], r"image_size: expected \(height, width\) in \[8, 2048\]"),
                                               ("context", 10**6, r"context=1000000 in \[1, 64\]"),
                                               ("num_waypoints", 10**6, r"num_waypoints=1000000 must be in \[1, 64\]")])
def test_a_remote_declaration_past_the_bounds_is_refused(server, field, value, match):
    server.info = {**server.info, field: value}  # what a hostile or broken server answers on /info
    with pytest.raises(RemotePolicyError, match=match):
        RemotePolicy(server.url, timeout_s=5)

    class Greedy(ExternalPolicy):
        observes = (keys.GOAL_VECTOR,)

    setattr(Greedy, field, value)
    with pytest.raises(ValueError, match=match):  # an in-process one is held to the same bounds
        describe(Greedy())


@pytest.fixture()
def navdp_server():
    from wanderland_nav.external.navdp import NavDPServer
    s = NavDPServer(GoalVectorPolicy(), max_body_bytes=1 << 20)
    threading.Thread(target=s.serve_forever, daemon=True).start()
    yield s
    s.shutdown()
    s.server_close()


def _navdp_post(server, path: str, body: bytes, **headers) -> tuple[int, str]:
    host, port = server.server_address[:2]
    conn = http.client.HTTPConnection(host, port, timeout=10)
    conn.request("POST", path, body=body, headers={"Content-Length": str(len(body)), **headers})  # `Content-Length` may lie
    resp = conn.getresponse()
    out = resp.status, resp.read().decode("utf-8", "replace")
    conn.close()
    return out


def test_the_navdp_server_refuses_what_a_page_could_send(navdp_server):
    reset = b'{"intrinsic": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "stop_threshold": -3, "batch_size": 2}'
    assert _navdp_post(navdp_server, "/navigator_reset", reset, **{"Content-Type": "application/json"})[0] == 200
    # a page of another site: a form post (multipart, no pre-flight) carries its Origin
    status, text = _navdp_post(navdp_server, "/pointgoal_step", b"--x--\r\n",
                               **{"Content-Type": "multipart/form-data; boundary=x", "Origin": "http://evil.example"})
    assert status == 403 and "Origin" in text
    # DNS rebinding: the page's own name as Host
    status, text = _navdp_post(navdp_server, "/navigator_reset", reset,
                               **{"Content-Type": "application/json", "Host": "evil.example:8888"})
    assert status == 403 and "Host" in text
    # the resets take JSON only, the steps a multipart form only
    assert _navdp_post(navdp_server, "/navigator_reset", reset, **{"Content-Type": "text/plain"})[0] == 415
    assert _navdp_post(navdp_server, "/nogoal_step", reset, **{"Content-Type": "application/json"})[0] == 415
    # a body above the cap is refused before it is read (declared, not sent: the server never reads it)
    status, text = _navdp_post(navdp_server, "/navigator_reset", b"",
                               **{"Content-Type": "application/json", "Content-Length": str(2 << 30)})
    assert status == 413 and "above the limit of 1048576 bytes" in text
    # a batch nobody runs
    big = reset.replace(b'"batch_size": 2', b'"batch_size": 100000000')
    status, text = _navdp_post(navdp_server, "/navigator_reset", big, **{"Content-Type": "application/json"})
    assert status == 400 and "batch_size" in text


def test_the_navdp_image_decoder_refuses_a_pixel_bomb_from_its_header():
    from PIL import Image

    from wanderland_nav.external.navdp import MAX_PIXELS, decode_depth, decode_rgb
    buf = io.BytesIO()
    Image.new("L", (8192, 8192)).save(buf, format="PNG")  # 64 M pixels in a few kB
    assert len(buf.getvalue()) < 1 << 20 and 8192 * 8192 > MAX_PIXELS
    for decode in (decode_rgb, decode_depth):
        with pytest.raises(ValueError, match="pixels"):
            decode(buf.getvalue(), 1)
