"""The benchmark's policy sources: one adapter class each behind ONE interface (habitat's `Agent` under its
`Benchmark`), so the runner never asks what kind of policy it holds.

A source is named in `benchmark.policies` by the one key it owns (`{name: n, <kind>: value, ...}`):

| kind | adapter | what it is | env it is evaluated in |
|---|---|---|---|
| `reference` | `ReferenceSource` | the privileged navmesh expert or uniform random actions | the benchmark's, camera off |
| `checkpoint` | `CheckpointSource` | a trained package policy (`train`'s `last.pt`) | the one it was trained in |
| `target` | `TargetSource` | an in-process protocol policy (`pkg.mod:Class`, `external.protocol`) | the benchmark's |
| `url` | `ServedSource` | a protocol policy behind `serve_policy`'s localhost HTTP | the benchmark's |
| `model` | `ReleasedSource` | a released GNM / ViNT / NoMaD / MBRA / CityWalker file (`weights=`) in its own architecture | the benchmark's, shaped by the model |
| `navdp_url` | `NavDPSource` | a policy server of NavDP's contract (`external.navdp`) | the benchmark's |

An entry's keys are refused when its source does not know them, naming the nearest (`timeout` for `timeout_s`
would otherwise run with no limit). A served source (`url`, `navdp_url`) is contacted only when one of its
evaluations must run: a rerun whose evaluations are all stored needs no server (`reads` comes from them).

Adding a source is one small subclass of `PolicySource` with its `kind`, registered with `@policy_source`:
build what acts in `__init__`, say what it `reads`, hand the evaluator an `actor(env)`. The base class shapes
the env to what the policy declares (`compose.shaped_env_config`), turns the camera off for a policy that never
looks, and applies the task's settings (`tasks.task_env_config`).
"""

from __future__ import annotations

import difflib
from typing import Any, ClassVar

from wanderland_nav import keys
from wanderland_nav.benchmark.tasks import Task, task_env_config
from wanderland_nav.cache import file_sha256
from wanderland_nav.compose.build import blind_env_config, check_env_carries, shaped_env_config
from wanderland_nav.compose.checkpoints import trained_policy
from wanderland_nav.compose.policy_sources import RELEASED_KEYS, released_policy, released_weights_policies
from wanderland_nav.envs.config import NavEnvConfig
from wanderland_nav.envs.experts import ExpertPolicy, RandomPolicy
from wanderland_nav.evaluation import PolicyActor
from wanderland_nav.external import ExternalActor, RemotePolicy, load_target
from wanderland_nav.external.navdp import NavDPPolicy

IMAGE_KEYS = {keys.RGB, keys.DEPTH, keys.GOAL_IMAGE}
#: kind -> adapter class, in the order the error messages list them
SOURCES: dict[str, type[PolicySource]] = {}
COMMON_KEYS = frozenset({"name", "timeout_s", "max_consecutive_failures"})


def policy_source(cls):
    """Register a `PolicySource` subclass under its `kind` (the key of `benchmark.policies` entries it owns)."""
    if not cls.kind or cls.kind in SOURCES or cls.kind in ("name", "timeout_s", "max_consecutive_failures"):
        raise ValueError(f"policy source {cls.__name__}: kind {cls.kind!r} is empty, taken or reserved")
    SOURCES[cls.kind] = cls
    return cls


class PolicySource:
    """One policy of the benchmark. `spec`: its `benchmark.policies` entry as configured; `settings`: the
    benchmark's config (`BenchmarkConfig`: device, seed, default time limit, camera size, ...).

    What the runner reads: `name`, `spec`, `reads` (observation keys, checked against each task), `content` (a
    digest of what the spec points at, part of each stored evaluation's key), `trained_goal_input` (the point-goal
    input a trained policy learnt with, "" when none), `checks_episodes` (refuse episodes that cannot pose the task),
    `env_config(task, base)`, `actor(env)`, `failures()` and `close()`."""

    kind: ClassVar[str] = ""
    extra_keys: ClassVar[frozenset] = frozenset()  # the keys an entry may hold besides `name`, its kind and limits
    reads: tuple[str, ...] | None = ()  # None: a served policy not contacted yet (`ensure`)
    content: str = ""
    trained_goal_input: str = ""
    checks_episodes: bool = True

    def __init__(self, name: str, spec: dict, settings, where: str = "benchmark policies"):
        self.name, self.spec, self.settings, self.where = name, spec, settings, where

    @classmethod
    def entry_keys(cls) -> frozenset:
        return COMMON_KEYS | {cls.kind} | cls.extra_keys

    def ensure(self) -> None:
        """Contact what the policy lives behind, if that waits for an evaluation to run (served sources)."""

    def transport_error(self) -> str | None:
        """Why the last evaluation is no result (its policy server unreachable), else None."""
        return None

    # what the env is shaped to: the trained env (a checkpoint) or the benchmark's, by this policy, at this size
    trained_env: NavEnvConfig | None = None
    image_size: Any = None

    def shaped_by(self):
        """What declares the env requirements (`config.env_requirements()`): the policy or its actor."""
        raise NotImplementedError

    def env_config(self, task: Task, base: NavEnvConfig) -> NavEnvConfig:
        """The env this policy is evaluated in on `task` (`base`: the benchmark's `env`)."""
        env = shaped_env_config(self.trained_env if self.trained_env is not None else base, self.shaped_by(),
                                self.image_size)
        if not set(self.reads) & IMAGE_KEYS:  # a policy that never looks gets no rendering
            env = blind_env_config(env)
        env = task_env_config(task, env)
        check_env_carries(self.reads, env, f"benchmark {task.label}/{self.name}")  # depth rendered, or refused
        return env

    def actor(self, env):
        """What the evaluator steps in `env` (a TensorDict -> TensorDict callable writing `keys.ACTION`)."""
        raise NotImplementedError

    def failures(self) -> dict[int, str]:
        """Env episode index -> the cause of its first failed policy call (the last evaluation's)."""
        return {}

    def close(self) -> None:
        """Release what `__init__` opened (a worker thread, a connection)."""


@policy_source
class ReferenceSource(PolicySource):
    """`{reference: expert | random}`: reads nothing, so the camera stays off and its rows are the same in every
    task; built per env (the expert reads the env's paths, random its action spec)."""

    kind = "reference"
    checks_episodes = False

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        if self.spec["reference"] not in ("expert", "random"):
            raise ValueError(f"{self.where}.reference={self.spec['reference']!r}: expected expert or random")

    def env_config(self, task, base):
        return blind_env_config(base)

    def actor(self, env):
        base_env = getattr(env, "base_env", env)
        if self.spec["reference"] == "expert":
            return ExpertPolicy(base_env)
        return RandomPolicy(base_env.action_spec, seed=self.settings.seed)


@policy_source
class CheckpointSource(PolicySource):
    """`{checkpoint: path/last.pt}`: a trained package policy, evaluated in the env it was trained in (its stored
    `env` and `render.image_size`, read from its policy card), with its mean waypoints."""

    kind = "checkpoint"

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        spec, settings = self.spec, self.settings
        trained = trained_policy(spec["checkpoint"], settings.device)  # from the checkpoint's card alone
        self.policy, self.trained_env, self.image_size = trained.policy, trained.env, trained.image_size
        self.reads = tuple(map(str, self.policy.in_keys))
        self.trained_goal_input = trained.goal_input
        self.content = file_sha256(spec["checkpoint"])
        self._actor = PolicyActor(self.policy)

    def shaped_by(self):
        return self.policy

    def actor(self, env):
        return self._actor


@policy_source
class ReleasedSource(PolicySource):
    """`{model: gnm | vint | nomad | mbra | citywalker, weights: <its released file>, ...}`: a released model in its own
    architecture (`policies.released`), the file read without running anything in it; further keys are
    `ReleasedConfig` fields. Evaluated in the benchmark's env shaped to what the model reads."""

    kind = "model"
    extra_keys = RELEASED_KEYS

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.policy, self.content = released_policy(self.spec, self.settings.device)
        self.reads = tuple(map(str, self.policy.in_keys))
        self._actor = PolicyActor(self.policy)

    def shaped_by(self):
        return self.policy

    def actor(self, env):
        return self._actor


class ProtocolSource(PolicySource):
    """A protocol policy (`external.protocol`) stepped through `ExternalActor`: a time limit per call, failures
    counted per episode. Subclasses say where the policy lives (`protocol_policy`); a `served` one is contacted
    only in `ensure`, when one of its evaluations must run."""

    served: ClassVar[bool] = False

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.timeout_s = float(self.spec.get("timeout_s", self.settings.timeout_s))
        self._actor = None
        if self.served:
            self.reads = None
        else:
            self.ensure()

    def protocol_actor(self) -> ExternalActor:
        return ExternalActor(self.protocol_policy(), name=self.name, timeout_s=self.timeout_s,
                             default_image_size=tuple(self.settings.image_size),
                             max_consecutive_failures=self.max_failures())

    def max_failures(self) -> int:
        return int(self.spec.get("max_consecutive_failures", self.settings.max_consecutive_failures))

    def protocol_policy(self):
        raise NotImplementedError

    def ensure(self) -> None:
        if self._actor is None:
            self._actor = self.protocol_actor()
            self.reads = tuple(self._actor.in_keys)

    def shaped_by(self):
        return self._actor

    def actor(self, env):
        self.ensure()
        return self._actor

    def failures(self):
        return self._actor.failures if self._actor is not None else {}

    def transport_error(self):
        return getattr(self._actor, "transport_error", None)

    def close(self):
        if self._actor is not None:
            self._actor.close()


@policy_source
class TargetSource(ProtocolSource):
    """`{target: pkg.mod:Class, kwargs: {...}}`: a protocol policy class imported and built in-process."""

    kind = "target"
    extra_keys = frozenset({"kwargs"})

    def protocol_policy(self):
        return load_target(self.spec["target"], self.spec.get("kwargs"))


@policy_source
class ServedSource(ProtocolSource):
    """`{url: "http://127.0.0.1:8765"}`: a protocol policy served over localhost HTTP (`serve_policy`)."""

    kind = "url"
    served = True

    def protocol_policy(self):
        return RemotePolicy(self.spec["url"], self.timeout_s)


@policy_source
class NavDPSource(ProtocolSource):
    """`{navdp_url: "http://127.0.0.1:8888", navdp_goal: point | image | none, ...}`: a policy server of NavDP's
    HTTP contract (their GNM, ViNT, NoMaD, ... servers unmodified), its trajectories executed by the env."""

    kind = "navdp_url"
    served = True
    extra_keys = frozenset({"navdp_goal", "num_waypoints", "hfov_deg", "stop_threshold", "image_size"})

    def protocol_policy(self):
        spec = self.spec
        return NavDPPolicy(spec["navdp_url"], goal=spec.get("navdp_goal", "point"),
                           num_waypoints=int(spec.get("num_waypoints", 8)), image_size=spec.get("image_size"),
                           hfov_deg=float(spec.get("hfov_deg", 90.0)),
                           stop_threshold=float(spec.get("stop_threshold", -3.0)), timeout_s=self.timeout_s)


def policy_sources(settings) -> list[PolicySource]:
    """The configured policies (`settings.policies`, then one `model` entry per released file found in
    `settings.released_weights`), each built by its adapter (a target imported, a checkpoint or released file
    loaded; a served policy is contacted later, `PolicySource.ensure`)."""
    found = released_weights_policies(settings.released_weights)[0] if settings.released_weights else []
    if not settings.policies and not found:
        raise ValueError("benchmark: no policies; e.g. policies='[{name: expert, reference: expert}]'")
    out, seen = [], set()
    for i, raw in enumerate([*settings.policies, *found]):
        spec = dict(raw)
        name = str(spec.get("name") or "")
        given = [s for s in SOURCES if spec.get(s)]
        if not name or len(given) != 1:
            raise ValueError(f"benchmark policies[{i}]: needs a name and exactly one of {tuple(SOURCES)}, got {spec}")
        known = SOURCES[given[0]].entry_keys()
        unknown = sorted(set(spec) - known)
        if unknown:  # `timeout: 1` for `timeout_s` would run with no limit at all
            near = difflib.get_close_matches(unknown[0], known, n=1)
            raise ValueError(f"benchmark policies[{i}]: unknown key {unknown[0]!r}"
                             + (f" (did you mean {near[0]!r}?)" if near else "") + f"; known: {sorted(known)}")
        if name in seen:
            raise ValueError(f"benchmark policies[{i}]: name {name!r} used twice")
        seen.add(name)
        out.append(SOURCES[given[0]](name, spec, settings, f"benchmark policies[{i}]"))
    return out
