"""Seeded stand-in weights for a released model, from its state-dict manifest alone.

What the parity fixtures (`tests/fixtures/released/`) and the random-weight smoke runs use where the real
weights cannot be had. The fill is scaled by fan-in so the signal survives the depth of the network (a
uniform `randn * 0.02` on every tensor drives the activations to zero and leaves only the last layers
tested):

* tensors of 2+ dims named `*weight` (convolutions, linear layers, attention projections):
  `N(0, 1) * sqrt(2 / fan_in)`, fan_in = the product of all dims but the first;
* 1-dim `*weight` (BatchNorm / GroupNorm / LayerNorm scales): `1 + 0.1 N(0, 1)`;
* `*bias`, `*in_proj_bias`, `running_mean`: `0.1 N(0, 1)`;
* `running_var`: `U(0.5, 1.5)`; `num_batches_tracked`: 0;
* `*pos_enc` (the sinusoidal position tables the releases store as buffers): left as the model builds them.

Each tensor draws from its own numpy `Generator(PCG64)` seeded with `(seed, crc32(key))`, so the values do
not depend on the order of the keys, and the rule needs nothing but the key, shape and dtype.
"""

from __future__ import annotations

import math
import zlib

import numpy as np
import torch
import sys
import types

RULE = ("fan-in-scaled normal weights sqrt(2/fan_in), norm scales 1+0.1N, biases/running_mean 0.1N, "
        "running_var U(0.5,1.5), num_batches_tracked 0, pos_enc as built; numpy PCG64 seeded (seed, crc32(key))")


def rng(seed: int, key: str) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64([int(seed), zlib.crc32(key.encode())]))


def fill_value(key: str, shape: tuple[int, ...], dtype: torch.dtype, seed: int) -> torch.Tensor | None:
    """The rule's tensor for `key`, or None where the rule keeps the model's own value (`pos_enc`)."""
    leaf = key.rsplit(".", 1)[-1]
    if leaf == "pos_enc":
        return None
    if leaf == "num_batches_tracked":
        return torch.zeros(shape, dtype=dtype)
    g = rng(seed, key)
    if leaf == "running_var":
        v = g.uniform(0.5, 1.5, size=shape)
    elif leaf.endswith("weight") and len(shape) >= 2:
        fan_in = math.prod(shape[1:])
        v = g.standard_normal(size=shape) * math.sqrt(2.0 / fan_in)
    elif leaf.endswith("weight"):
        v = 1.0 + 0.1 * g.standard_normal(size=shape)
    else:  # biases, in_proj_bias, running_mean and any other buffer
        v = 0.1 * g.standard_normal(size=shape)
    return torch.from_numpy(np.asarray(v, dtype=np.float64)).to(dtype)


def seeded_state_dict(model: torch.nn.Module, seed: int) -> dict[str, torch.Tensor]:
    """`model.state_dict()` with every tensor replaced by the rule's value (seed `seed`)."""
    out = {}
    for k, v in model.state_dict().items():
        new = fill_value(k, tuple(v.shape), v.dtype, seed)
        out[k] = v.clone() if new is None else new
    return out


def manifest(state_dict: dict[str, torch.Tensor]) -> list[list]:
    """`[[key, shape, dtype], ...]` in the state dict's order."""
    return [[k, list(v.shape), str(v.dtype).removeprefix("torch.")] for k, v in state_dict.items()]


#: how each release ships its weights, and (pickled model) the official class the file names
RELEASE_FORMAT = {"gnm": ("pickled_model", "vint_train.models.gnm.gnm", "GNM"),
                  "vint": ("pickled_model", "vint_train.models.vint.vint", "ViNT"),
                  "nomad": ("state_dict",), "logonav": ("state_dict",), "citywalker": ("lightning",)}


def write_release_file(model: str, net: torch.nn.Module, path) -> None:
    """`net`'s weights written as `model`'s release ships them: a raw state dict (NoMaD, LogoNav), a Lightning
    checkpoint with `model.`-prefixed keys (CityWalker), or (GNM, ViNT) the pickled model object under `'model'`
    beside optimizer and scheduler, its class named as the official one (a stand-in module is registered under
    the official name while pickling, then removed). For smoke runs and tests where the real files are absent."""

    fmt = RELEASE_FORMAT[model]
    if fmt[0] == "state_dict":
        torch.save(net.state_dict(), path)
        return
    if fmt[0] == "lightning":
        torch.save({"state_dict": {f"model.{k}": v for k, v in net.state_dict().items()}, "epoch": 0, "global_step": 0,
                    "pytorch-lightning_version": "2.1.0", "hyper_parameters": {"cfg": {"model": {"type": "citywalker_feat"}}},
                    "optimizer_states": [{"state": {}, "param_groups": []}], "lr_schedulers": []}, path)
        return
    _, module, cls = fmt
    parts = module.split(".")
    names = [".".join(parts[:i]) for i in range(1, len(parts) + 1)]
    saved = {k: sys.modules.get(k) for k in names}
    own = type(net)
    official = type(cls, (own,), {"__module__": module})
    try:
        for k in names:
            sys.modules[k] = types.ModuleType(k)
        setattr(sys.modules[module], cls, official)
        net.__class__ = official
        opt = torch.optim.AdamW(net.parameters(), lr=1e-4)
        torch.save({"model": net, "optimizer": opt, "scheduler": torch.optim.lr_scheduler.CosineAnnealingLR(opt, 10),
                    "epoch": 0}, path)
    finally:
        net.__class__ = own
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
