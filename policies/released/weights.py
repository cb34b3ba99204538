"""Reading the released checkpoint files without running anything in them.

The releases come in three formats:

* a raw state dict (NoMaD `nomad.pth`, MBRA / LogoNav),
* a PyTorch-Lightning `.ckpt`, the weights under `state_dict` with keys prefixed `model.` (CityWalker),
* a dict whose `'model'` entry is the pickled model object itself, beside the optimizer and scheduler
  (GNM `gnm_large.pth`, ViNT `vint.pth`); `torch.load` on those imports and runs the official classes'
  unpickling, and `weights_only=True` refuses them.

`read_checkpoint` reads all three with its own unpickler over torch's zip format: tensors are rebuilt from
the archive's storages by the two tensor constructors torch writes (`_rebuild_tensor_v2`,
`_rebuild_parameter`), `collections.OrderedDict` is the real one, and every other global the pickle names
(the official model classes, torch modules, optimizers, functions, `builtins`) becomes an inert stand-in
that only records its name, arguments and state. Nothing the file names is imported or called.
`module_state_dict` then walks a pickled module's recorded `_parameters` / `_buffers` / `_modules`
into the state dict that `model.state_dict()` would have given.

Errors name the file and what is wrong (`ReleasedWeightsError`); `load_released` checks every key and
shape before anything is copied into the model.
"""

from __future__ import annotations

import collections
import io
import pickle
import zipfile
from pathlib import Path
from typing import Any

import torch
from torch import nn

_DTYPES = {
    "FloatStorage": torch.float32, "DoubleStorage": torch.float64, "HalfStorage": torch.float16,
    "BFloat16Storage": torch.bfloat16, "LongStorage": torch.int64, "IntStorage": torch.int32,
    "ShortStorage": torch.int16, "CharStorage": torch.int8, "ByteStorage": torch.uint8, "BoolStorage": torch.bool,
}


class ReleasedWeightsError(ValueError):
    """A released checkpoint that cannot be read or does not fit the model: names the file and the fault."""


class Inert:
    """Stand-in for any class or function a checkpoint names: records, never runs."""

    qualname = "?"
    args: tuple = ()
    kwargs: dict = {}
    state: Any = None

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs, self.state = args, kwargs, None

    def __setstate__(self, state):
        self.state = state

    def __setitem__(self, key, value):  # pickle's SETITEM on a stand-in dict subclass
        self.__dict__.setdefault("items", {})[key] = value

    def __repr__(self) -> str:
        return f"<inert {self.qualname}>"


_STANDINS: dict[str, type] = {}


def _standin(module: str, name: str) -> type:
    key = f"{module}.{name}"
    if key not in _STANDINS:
        _STANDINS[key] = type(name, (Inert,), {"qualname": key, "__module__": "inert." + module})
    return _STANDINS[key]


class _StorageType:
    def __init__(self, dtype: torch.dtype):
        self.dtype = dtype


def _rebuild_tensor(storage: torch.Tensor, offset: int, size, stride, *_ignored) -> torch.Tensor:
    if not size:
        return storage[offset].clone()
    return storage.as_strided(tuple(size), tuple(stride), offset).clone()


def _rebuild_parameter(data: torch.Tensor, *_ignored) -> torch.Tensor:
    return data


def _rebuild_from_type(func, _new_type, args, _state):
    """`torch._tensor._rebuild_from_type_v2` (a tensor with Python attributes): the plain tensor. `func` came
    through `find_class`, so it is one of the tensor rebuilds here or an inert stand-in."""
    return func(*args)


_ALLOWED = {
    ("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor,
    ("torch._tensor", "_rebuild_from_type_v2"): _rebuild_from_type,
    ("torch._utils", "_rebuild_parameter"): _rebuild_parameter,
    ("torch._utils", "_rebuild_parameter_with_state"): _rebuild_parameter,
    ("collections", "OrderedDict"): collections.OrderedDict,
}


class _Unpickler(pickle.Unpickler):
    def __init__(self, data: bytes, archive: zipfile.ZipFile, prefix: str, path: Path):
        super().__init__(io.BytesIO(data))
        self.archive, self.prefix, self.path = archive, prefix, path
        self.storages: dict[str, torch.Tensor] = {}
        self.standins: set[str] = set()

    def find_class(self, module: str, name: str):
        if (module, name) in _ALLOWED:
            return _ALLOWED[(module, name)]
        if module == "torch" and name in _DTYPES:
            return _StorageType(_DTYPES[name])
        if module == "torch" and name in {str(d).removeprefix("torch.") for d in _DTYPES.values()}:
            return getattr(torch, name)  # a dtype object (plain data)
        self.standins.add(f"{module}.{name}")
        return _standin(module, name)

    def persistent_load(self, pid):
        if not (isinstance(pid, tuple) and len(pid) >= 5 and pid[0] == "storage"):
            raise ReleasedWeightsError(f"{self.path}: unexpected persistent id {pid!r} (not a torch storage)")
        stype, key = pid[1], str(pid[2])
        dtype = stype.dtype if isinstance(stype, _StorageType) else stype if isinstance(stype, torch.dtype) else None
        if dtype is None:
            raise ReleasedWeightsError(f"{self.path}: storage {key} has unknown type {stype!r}")
        if key not in self.storages:
            name = f"{self.prefix}data/{key}"
            try:
                raw = self.archive.read(name)
            except KeyError:
                raise ReleasedWeightsError(f"{self.path}: storage record {name!r} is missing from the archive") from None
            self.storages[key] = torch.frombuffer(bytearray(raw), dtype=dtype) if raw else torch.empty(0, dtype=dtype)
        return self.storages[key]


def read_checkpoint(path: str | Path) -> Any:
    """The object a torch zip checkpoint holds, with tensors as tensors and every other class inert."""
    path = Path(path)
    if not path.is_file():
        raise ReleasedWeightsError(f"{path}: no such checkpoint file")
    if not zipfile.is_zipfile(path):
        raise ReleasedWeightsError(f"{path}: not a torch zip checkpoint (the legacy pre-1.6 format is not read; "
                                   f"re-save it with torch.save)")
    with zipfile.ZipFile(path) as archive:
        pkl = [n for n in archive.namelist() if n.endswith("data.pkl") and n.count("/") == 1]
        if not pkl:
            raise ReleasedWeightsError(f"{path}: archive holds no '<name>/data.pkl' record")
        prefix = pkl[0][: -len("data.pkl")]
        try:
            return _Unpickler(archive.read(pkl[0]), archive, prefix, path).load()
        except ReleasedWeightsError:
            raise
        except Exception as e:  # a malformed pickle: say where
            raise ReleasedWeightsError(f"{path}: cannot read {pkl[0]}: {type(e).__name__}: {e}") from e


def module_state_dict(obj: Any, where: str) -> dict[str, torch.Tensor]:
    """A pickled (inert) `nn.Module` -> its `state_dict()`: parameters, persistent buffers, submodules in order.
    `DataParallel` / `DistributedDataParallel` wrappers are unwrapped (their `module`)."""
    out: dict[str, torch.Tensor] = {}

    def walk(m: Any, prefix: str) -> None:
        state = getattr(m, "state", None)
        if not isinstance(state, dict) or "_modules" not in state:
            raise ReleasedWeightsError(f"{where}: '{prefix.rstrip('.') or 'model'}' is not a pickled torch module "
                                       f"({m!r})")
        for k, v in state.get("_parameters", {}).items():
            if v is not None:
                out[prefix + k] = v
        skip = state.get("_non_persistent_buffers_set", set())
        skip = set(skip.args[0]) if isinstance(skip, Inert) and skip.args else set(skip) if isinstance(skip, set) else set()
        for k, v in state.get("_buffers", {}).items():
            if v is not None and k not in skip:
                out[prefix + k] = v
        for k, sub in state.get("_modules", {}).items():
            if sub is not None:
                walk(sub, prefix + k + ".")

    root = obj
    if getattr(obj, "qualname", "").rsplit(".", 1)[-1] in ("DataParallel", "DistributedDataParallel"):
        root = obj.state["_modules"]["module"]
    walk(root, "")
    return out


def _tensor_dict(obj: Any, where: str) -> dict[str, torch.Tensor]:
    if not isinstance(obj, dict) or not obj:
        raise ReleasedWeightsError(f"{where}: expected a dict of tensors, got {type(obj).__name__}")
    bad = [k for k, v in obj.items() if not isinstance(v, torch.Tensor)]
    if bad:
        raise ReleasedWeightsError(f"{where}: entries {bad[:5]} are not tensors")
    return dict(obj)


def released_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """The model weights of a released file in any of the three formats (module docstring)."""
    path = Path(path)
    obj = read_checkpoint(path)
    if isinstance(obj, dict) and "model" in obj and isinstance(obj["model"], Inert):
        return module_state_dict(obj["model"], f"{path} ['model']")
    if isinstance(obj, dict) and "state_dict" in obj and isinstance(obj["state_dict"], dict):
        sd = _tensor_dict(obj["state_dict"], f"{path} ['state_dict']")
        return {k.removeprefix("model."): v for k, v in sd.items()}
    if isinstance(obj, Inert):
        return module_state_dict(obj, str(path))
    return _tensor_dict(obj, str(path))


def check_state_dict(model: nn.Module, sd: dict[str, torch.Tensor], where: str) -> None:
    """Refuse a state dict that does not fit `model` exactly: missing / unexpected keys, shape mismatches."""
    want = model.state_dict()
    missing = [k for k in want if k not in sd]
    unexpected = [k for k in sd if k not in want]
    shapes = [f"{k}: file {tuple(sd[k].shape)} vs model {tuple(want[k].shape)}"
              for k in want if k in sd and tuple(sd[k].shape) != tuple(want[k].shape)]
    faults = []
    if missing:
        faults.append(f"{len(missing)} missing key(s), e.g. {missing[:4]}")
    if unexpected:
        faults.append(f"{len(unexpected)} unexpected key(s), e.g. {unexpected[:4]}")
    if shapes:
        faults.append(f"{len(shapes)} shape mismatch(es), e.g. {shapes[:3]}")
    if faults:
        raise ReleasedWeightsError(f"{where} does not fit {type(model).__name__}: " + "; ".join(faults))


def load_released(model: nn.Module, path: str | Path) -> nn.Module:
    """Read a released file safely and load it into `model` strictly; returns `model`."""
    sd = released_state_dict(path)
    check_state_dict(model, sd, str(path))
    model.load_state_dict(sd, strict=True)
    return model
