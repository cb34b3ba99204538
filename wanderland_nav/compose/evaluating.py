"""`evaluate`'s composition: the reference policies as objects."""

from __future__ import annotations

from functools import partial

from wanderland_nav.compose.schema import EvaluateConfig
from wanderland_nav.envs.experts import ExpertPolicy, RandomPolicy


def reference_policy(c: EvaluateConfig, env):
    """The built-in references: the privileged navmesh expert (upper bound) or uniform random actions."""
    if c.reference == "expert":
        return ExpertPolicy(env, source=c.expert_path_source)
    if c.reference == "random":
        return RandomPolicy(env.action_spec, seed=c.seed)
    raise ValueError(f"reference={c.reference!r}: expected expert or random (trained policies: checkpoints=[...])")


def reference(c: EvaluateConfig):
    """`reference_policy` as a per-env policy for `Evaluator`: the references read their env (expert paths, action
    spec), so each env gets its own."""
    policy = partial(reference_policy, c)
    policy.per_env = True
    return policy
