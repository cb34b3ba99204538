"""Serve a policy over HTTP on a local address (the reference server of the bring-your-own-policy protocol).

    python -m wanderland_nav.serve_policy target=my_pkg.my_module:MyPolicy [port=8765]
    python -m wanderland_nav.serve_policy checkpoint=outputs/.../checkpoints/last.pt
    python -m wanderland_nav.serve_policy model=nomad weights=/weights/nomad.pth protocol=navdp port=8888

Prints `serving <policy> at http://127.0.0.1:<port>` once it accepts requests (`port=0`: a free port) and serves
until stopped. The evaluator reaches it with `policies=[{name: ..., url: http://127.0.0.1:<port>}]`; with
`protocol=navdp` it speaks NavDP's contract instead (`wanderland_nav.external.navdp`), for their benchmark or
`policies=[{name: ..., navdp_url: http://127.0.0.1:<port>}]`.
"""

from __future__ import annotations

from wanderland_nav.app import entry_point  # first: it readies the process (see app.py)

from omegaconf import DictConfig

from wanderland_nav.compose import policy_from_checkpoint, typed_config
from wanderland_nav.compose.schema import ServePolicyConfig
from wanderland_nav.external.actor import NavPolicyAsExternal
from wanderland_nav.external.protocol import load_target
from wanderland_nav.compose.policy_sources import released_policy
from wanderland_nav.external.navdp import NavDPServer
from wanderland_nav.external.server import PolicyServer


def make_server(cfg: DictConfig) -> PolicyServer | NavDPServer:
    """The bound (not yet serving) server of the composed config."""
    c: ServePolicyConfig = typed_config(cfg, ServePolicyConfig)
    if [bool(c.target), bool(c.checkpoint), bool(c.model)].count(True) != 1:
        raise ValueError("serve_policy: give exactly one of target=pkg.mod:Class, checkpoint=<file.pt> or "
                         "model=<released model> weights=<file>")
    if c.protocol not in ("wanderland", "navdp"):
        raise ValueError(f"serve_policy.protocol={c.protocol!r}: expected wanderland or navdp")
    if c.target:
        policy = load_target(c.target, c.kwargs)
    elif c.checkpoint:
        policy = NavPolicyAsExternal(policy_from_checkpoint(c.checkpoint, c.device)[0])
    else:
        policy = NavPolicyAsExternal(released_policy({"model": c.model, "weights": c.weights}, c.device)[0])
    server = NavDPServer if c.protocol == "navdp" else PolicyServer
    return server(policy, c.host, c.port, max_body_bytes=c.max_body_mb << 20, allowed_hosts=tuple(c.allowed_hosts))


def serve(cfg: DictConfig) -> None:
    """Serve the composed config's policy until stopped (Ctrl-C)."""
    server = make_server(cfg)
    print(f"serving {type(server.policy).__name__} at {server.url}", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()


main = entry_point("serve_policy", serve, argv=list)  # its overrides name no scene and no path to quote


if __name__ == "__main__":
    main()
