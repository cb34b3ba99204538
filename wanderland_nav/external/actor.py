"""`ExternalActor`: a bring-your-own policy stepped by the evaluator, its failures counted per episode.

Each env step it hands the policy the keys it declared (numpy, `[B, ...]`) and writes its waypoints as
`keys.ACTION`. When a call fails (it raises, answers with the wrong shape or non-finite numbers, or gives no
answer within `timeout_s`), every agent of that step gets a NaN action: the env keeps them still and counts
the step (`nonfinite_actions`), so their episodes end as failures, never as silently shorter tables; the cause
is kept per episode (`failures`, keyed by the env's episode index) for the results. A call that hangs cannot be
stopped from Python, so after a time-out (or `max_consecutive_failures` failed calls in a row) the actor gives
up on the policy and fails the remaining steps at once: the evaluation always ends. Each call runs on a daemon
thread, so a call abandoned after its time limit never keeps the process alive once the evaluation is over.

A failure of the connection to a served policy (the server died, `RemotePolicyError.transport`) is recorded as
`transport_error` besides: such an evaluation measured the network, not the policy, and the benchmark does not
store it as finished.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase

from policies.config import EnvRequirements
from wanderland_nav import keys
from wanderland_nav.external.protocol import NEW_EPISODE, check_waypoints, describe


class _NoAnswer(Exception):
    """The policy's call did not return within the time limit (a policy's own TimeoutError is its failure)."""


@dataclass(frozen=True)
class Declared:
    """What the env is shaped to (`compose.build.shaped_env_config` reads `env_requirements()`)."""

    requirements: EnvRequirements

    def env_requirements(self) -> EnvRequirements:
        return self.requirements


class ExternalActor:
    """TensorDict -> TensorDict over a protocol policy (`external.protocol`). `default_image_size`: the camera
    size when the policy leaves `image_size` unset."""

    def __init__(self, policy, *, name: str = "external", timeout_s: float = 30.0, max_consecutive_failures: int = 3,
                 default_image_size: tuple[int, int] = (64, 64)):
        info = describe(policy)
        if not timeout_s > 0 or max_consecutive_failures < 1:
            raise ValueError(f"{name}: timeout_s={timeout_s} must be > 0 and max_consecutive_failures="
                             f"{max_consecutive_failures} >= 1")
        self.policy, self.name, self.timeout_s = policy, name, float(timeout_s)
        self.max_consecutive_failures = int(max_consecutive_failures)
        self.in_keys = list(info["observes"])
        self.num_waypoints = info["num_waypoints"]
        size = tuple(info["image_size"] or default_image_size)
        self.config = Declared(EnvRequirements(size, info["context"], self.num_waypoints))
        self.failures: dict[int, str] = {}  # env episode index -> the first cause of a failed step in it
        self.calls = 0
        self._given_up: str | None = None
        self._in_a_row = 0
        self.transport_error: str | None = None  # the first failed call that was the connection's, not the policy's

    def reset(self) -> None:
        """A fresh evaluation: failure records cleared (a policy given up on stays given up)."""
        self.failures = {}

    def close(self) -> None:
        """Nothing held: each call's thread ends with it (a hung one is a daemon, abandoned)."""

    def _call(self, obs):
        """`policy.act(obs)` on a daemon thread, waited for `timeout_s` (a ThreadPoolExecutor's worker would be
        joined at interpreter exit, so a hung call would keep the process alive after the table is written)."""
        done, box = threading.Event(), {}

        def run():
            try:
                box["out"] = self.policy.act(obs)
            except BaseException as e:  # handed to the caller's thread
                box["error"] = e
            finally:
                done.set()

        threading.Thread(target=run, name=f"policy-{self.name}-{self.calls}", daemon=True).start()
        if not done.wait(self.timeout_s):
            raise _NoAnswer
        if "error" in box:
            raise box["error"]
        return box["out"]

    def _act(self, obs: dict[str, np.ndarray], batch: int) -> np.ndarray | str:
        """The policy's waypoints `[B, K, 2]` or why there are none."""
        if self._given_up is not None:
            return self._given_up
        try:
            out = check_waypoints(self._call(obs), batch, self.num_waypoints)
        except _NoAnswer:
            self._given_up = f"no answer within {self.timeout_s:g} s (given up: later steps fail at once)"
            return self._given_up  # the hung call keeps its daemon thread; never waited for
        except Exception as e:  # the policy's own error, whatever it is, is a failed step
            out = f"raised {type(e).__name__}: {e}"
            if getattr(e, "transport", False) and self.transport_error is None:
                self.transport_error = str(e)
        if isinstance(out, str):
            self._in_a_row += 1
            if self._in_a_row >= self.max_consecutive_failures:
                self._given_up = f"{out} ({self._in_a_row} failed calls in a row: given up, later steps fail at once)"
                return self._given_up
            return out
        self._in_a_row = 0
        return out

    @torch.no_grad()
    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        batch = td.batch_size[0]
        missing = [k for k in self.in_keys if k not in td.keys()]
        if missing:
            raise KeyError(f"{self.name} reads {missing}, which the env does not carry (it has "
                           f"{sorted(k for k in td.keys() if isinstance(k, str))})")
        obs = {k: td.get(k).cpu().numpy() for k in self.in_keys}
        steps = td.get(keys.STEP_COUNT, None)
        obs[NEW_EPISODE] = (steps.reshape(batch) == 0).cpu().numpy() if steps is not None else \
            np.full(batch, self.calls == 0)
        self.calls += 1
        out = self._act(obs, batch)
        if isinstance(out, str):
            action = torch.full((batch, self.num_waypoints, 2), float("nan"))
            episodes = td.get(keys.EPISODE_INDEX, None)
            for e in (episodes.reshape(batch).tolist() if episodes is not None else []):
                self.failures.setdefault(int(e), out)
        else:
            action = torch.from_numpy(out)
        td.set(keys.ACTION, action.to(td.device))
        return td


class NavPolicyAsExternal:
    """A package `NavPolicy` behind the protocol (its mean waypoints): what the reference server serves for a
    trained checkpoint, and how the remote path is timed against the same policy in-process."""

    def __init__(self, policy):
        cfg = policy.config
        self.policy = policy.eval()
        self.observes = tuple(str(k) for k in policy.in_keys)
        self.num_waypoints, self.context, self.image_size = int(cfg.num_waypoints), int(cfg.context), tuple(cfg.image_size)
        self._lock = threading.Lock()

    @torch.no_grad()
    def act(self, obs):
        batch = len(next(iter(obs.values())))
        device = next(self.policy.parameters()).device
        td = TensorDict({k: torch.from_numpy(np.ascontiguousarray(obs[k])) for k in self.observes}, batch_size=[batch],
                        device=device)
        with self._lock:
            return self.policy.select_action(td).get(keys.ACTION).cpu().numpy()
