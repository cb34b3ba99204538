"""A library policy as TorchRL's PPO pieces expect it: a `ProbabilisticActor` and a value operator.

Why an adapter, not the policy itself: a `NavPolicy.forward` writes waypoints, `loc`, `scale` AND
`state_value` in one call (the project's own PPO wants that), but TorchRL's objectives need the actor
and the critic as separate modules whose output keys do not overlap (`GAE(value_network=...)` refuses
a value network whose keys the actor also writes). Both modules here call the one policy, so its
weights are shared and its contract (`policies.base`) is unchanged:

* `policy_actor(policy, env)`: `ProbabilisticActor` over `[loc, scale]` with `WaypointNormal`, an
  independent Normal over the LAST TWO dims of the `[K, 2]` waypoint action, so the log-prob is one
  number per sample (TorchRL's `TanhNormal` / `IndependentNormal` default to one event dim and would
  give K log-probs per sample, which PPO's ratio then silently averages).
* `PolicyValue(policy)`: writes `state_value` only; the trunk runs without gradients and only the
  value head trains (`NavPolicy.value`, as the project's PPO).

vmap: TorchRL's GAE evaluates the value network on the stacked `(td, td["next"])` under `torch.vmap`.
GroupNorm has no batching rule for inputs whose vmapped dimension is not the batch one, so the value
module runs the policy once on the vmapped dimension folded into the batch (`_unvmapped`), which is
the same arithmetic and needs no `deactivate_vmap=True` from the user.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.modules import ProbabilisticActor

from policies import WaypointNormal
from wanderland_nav import keys as K
from torch._C import _functorch as ft


class _LocScale(TensorDictModuleBase):
    """The policy's Gaussian parameters: reads its observation keys, writes `loc`, `scale` and nothing else."""

    def __init__(self, policy):
        super().__init__()
        self.policy = policy
        self.in_keys = list(policy.in_keys)
        self.out_keys = [K.LOC, K.SCALE]

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        out = self.policy(td.select(*self.in_keys).copy())
        td.set(K.LOC, out.get(K.LOC))
        return td.set(K.SCALE, out.get(K.SCALE))


class PolicyValue(TensorDictModuleBase):
    """The policy's value head as a TorchRL value operator: writes `state_value` only."""

    def __init__(self, policy):
        super().__init__()
        self.policy = policy
        self.in_keys = list(policy.in_keys)
        self.out_keys = [K.STATE_VALUE]

    def forward(self, td: TensorDictBase) -> TensorDictBase:
        value = _unvmapped(lambda sub: self.policy.value(sub).get(K.STATE_VALUE), td.select(*self.in_keys))
        return td.set(K.STATE_VALUE, value)


def _unvmapped(fn, td: TensorDictBase) -> torch.Tensor:
    """`fn(td) -> [*B, D]` run on plain tensors: each `torch.vmap` level over `td` is unwrapped into a real
    leading dimension (`[V, *B]`; the policy takes any leading batch dims), and the result wrapped back.
    Same arithmetic as vmap's, one batched call, and GroupNorm never sees a batched tensor."""

    leaves = list(td.values(True, True))
    if not leaves or not ft.is_batchedtensor(leaves[0]):
        return fn(td)
    level = ft.maybe_get_level(leaves[0])

    def unwrap(x: torch.Tensor) -> torch.Tensor:
        tensor, bdim = ft._unwrap_batched(x, level)
        return tensor.movedim(bdim, 0)

    plain = {key: unwrap(x) for key, x in td.items(True, True)}
    V = next(iter(plain.values())).shape[0]
    out = _unvmapped(fn, TensorDict(plain, batch_size=[V, *td.batch_size]))  # deeper vmap levels, if any
    return ft._add_batch_dim(out, 0, level)


def policy_actor(policy, env=None, *, return_log_prob: bool = True) -> ProbabilisticActor:
    """`ProbabilisticActor` sampling `action [*B, K, 2]` from the policy's `WaypointNormal(loc, scale)`;
    `env`: its action spec bounds the samples' spec (the env clamps nothing: waypoints far out are walked
    towards). `ExplorationType.DETERMINISTIC` gives the mean waypoints."""
    return ProbabilisticActor(
        _LocScale(policy),
        in_keys=[K.LOC, K.SCALE],
        out_keys=[K.ACTION],
        spec=env.action_spec_unbatched if env is not None else None,
        distribution_class=WaypointNormal,
        return_log_prob=return_log_prob,
        log_prob_key=K.ACTION_LOG_PROB,
    )


def policy_modules(policy, env=None) -> tuple[ProbabilisticActor, PolicyValue]:
    """(actor, value): what `ClipPPOLoss(actor, value)` and `GAE(value_network=value)` take."""
    return policy_actor(policy, env), PolicyValue(policy)
