"""Policies that live outside the package, evaluated in-process or behind a localhost HTTP server.

* `protocol.ExternalPolicy`: the base class (and the minimal protocol) a bring-your-own policy follows:
  numpy observations in, body-frame waypoints `[B, K, 2]` out;
* `actor.ExternalActor`: what the evaluator steps: any such policy (in-process or remote) as a
  TensorDict -> TensorDict callable, with a time limit per call and failures counted per episode;
* `remote.RemotePolicy` / `server.PolicyServer`: the same protocol over HTTP on a local address
  (`wire.py`: arrays as an uncompressed `.npz` body), stdlib only.
"""

from wanderland_nav.external.actor import ExternalActor
from wanderland_nav.external.protocol import NEW_EPISODE, PROTOCOL, ExternalPolicy, load_target
from wanderland_nav.external.remote import RemotePolicy, RemotePolicyError

__all__ = ["NEW_EPISODE", "PROTOCOL", "ExternalActor", "ExternalPolicy", "RemotePolicy", "RemotePolicyError",
           "load_target"]
