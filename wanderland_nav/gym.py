"""Gymnasium: `gymnasium.make("WanderlandNav-v0", scene="demo")`, one agent, plain numpy observations.

Why a facade of its own rather than TorchRL's `register_gym`: a Gymnasium user expects arrays without the
env's batch dimension and only what a policy may read; TorchRL's route keeps the leading 1 on every array
and the whole observation spec. The env underneath is `wanderland_nav.make_env` with `batch_size=1` (the
same composition as the apps), so every `make_env` override works here too:
`gymnasium.make("WanderlandNav-v0", scene="demo", env={"camera": {"enabled": False}})`.

Spaces (from the TorchRL specs, batch dimension dropped):
  observation: `Dict` of the policy inputs (`keys.OBSERVATION_KEYS` plus `depth`, those the env carries). Images
      are channels-last `Box`es as Stable-Baselines3's `CnnPolicy` / `MultiInputPolicy` read them: `rgb` uint8
      `[H, W, 3T]` in 0..255, the T history frames stacked along the channels oldest first (frame t is channels
      3t..3t+2, as SB3's `VecFrameStack` stacks), `depth` float32 `[H, W, T]`, `goal_image` uint8 `[H, W, 3]`;
      the rest float32 / int64 `Box`es, bool keys as `MultiBinary`.
  action: `Box` `[K, 2]` body-frame waypoints (metres; `[2]` for a one-waypoint env).
`step` returns `(obs, reward, terminated, truncated, info)`. At the end of an episode `info` holds its metrics
at the top level, beside whatever the wrappers add: `is_success` (SB3's key, which its `EvalCallback` reads),
`spl`, `navigation_error`, `path_length`, `shortest_length`, `steps`, `collisions`, `intervention` (and the
pedestrian metrics when the env has people), so `Monitor(env, info_keywords=("is_success", "spl"))` logs them
and nothing is written under `info["episode"]`, the key Gymnasium's `RecordEpisodeStatistics` and SB3's
`Monitor` own. `render()` (render_mode="rgb_array") returns the newest camera frame `[H, W, 3]` uint8, or None
with the camera off.

Registered by `import wanderland_nav` whenever Gymnasium is installed (Gymnasium 1.x loads no plugin entry
points, so the package registers itself); this module imports Gymnasium and numpy only, torch and the env on
the first `make`. `gymnasium.make("wanderland_nav:WanderlandNav-v0")` imports the package for you. Needs the
`gym` extra: `pip install -e '.[gym]'`.
"""

from __future__ import annotations

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
except ImportError as e:  # an optional extra
    raise ImportError("wanderland_nav.gym needs Gymnasium: pip install -e '.[gym]'") from e

from wanderland_nav import keys as K

ENV_ID = "WanderlandNav-v0"
_OBSERVED = (*K.OBSERVATION_KEYS, K.DEPTH)
_CHANNELS_LAST = (K.RGB, K.DEPTH)  # [T, H, W, C] in the env -> [H, W, T * C] here
_INFO_NAMES = {"success": "is_success"}  # SB3's name; the other metrics keep the env's names


def _space(spec, key=None) -> spaces.Space:
    """One TorchRL leaf spec `[1, ...]` -> the Gymnasium space of one agent's value (channels-last images)."""
    import torch

    shape = tuple(spec.shape[1:])
    if key in _CHANNELS_LAST:
        T, H, W, C = shape
        shape = (H, W, T * C)
    if spec.dtype == torch.bool:
        return spaces.MultiBinary(shape)
    dtype = torch.empty(0, dtype=spec.dtype).numpy().dtype
    if dtype == np.uint8:  # images: the 0..255 bounds SB3's image check asks for
        return spaces.Box(low=0, high=255, shape=shape, dtype=np.uint8)
    if key in _CHANNELS_LAST:  # depth: metres, 0 where nothing was hit
        return spaces.Box(low=0.0, high=np.inf, shape=shape, dtype=dtype)
    low, high = spec.space.low[0].cpu().numpy(), spec.space.high[0].cpu().numpy()
    return spaces.Box(low=low.astype(dtype), high=high.astype(dtype), shape=shape, dtype=dtype)


def _numpy(value, key=None) -> np.ndarray:
    # one agent's value, a copy: the env may write the next step into the same tensor
    out = value[0].detach().cpu().numpy()
    if key in _CHANNELS_LAST:  # [T, H, W, C] -> [H, W, T * C], oldest frame first
        T, H, W, C = out.shape
        return np.ascontiguousarray(out.transpose(1, 2, 0, 3).reshape(H, W, T * C))
    return out.copy()


class WanderlandNavEnv(gymnasium.Env):
    """One `NavEnv` agent behind the Gymnasium API (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(self, scene: str = "demo", *, render_mode: str | None = None, **overrides):
        from wanderland_nav.compose.make_env import make_env

        if overrides.get("batch_size", 1) != 1:
            raise ValueError(f"{ENV_ID}: batch_size={overrides['batch_size']}: the Gymnasium env steps one agent; "
                             "for many agents at once use wanderland_nav.make_env(batch_size=N) (TorchRL)")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"{ENV_ID}: render_mode={render_mode!r}: expected None or 'rgb_array'")
        overrides.pop("batch_size", None)
        self.render_mode = render_mode
        self.env = make_env(scene, batch_size=1, **overrides)
        obs_spec = self.env.observation_spec
        self._keys = [k for k in _OBSERVED if k in obs_spec.keys()]
        self.observation_space = spaces.Dict({k: _space(obs_spec[k], k) for k in self._keys})
        self.action_space = _space(self.env.action_spec)
        rewards = self.env.full_reward_spec
        self._episode_keys = [k for k in rewards.keys(True, True) if isinstance(k, tuple) and k[0] == K.EPISODE]
        self._td = None

    def _observation(self, td) -> dict[str, np.ndarray]:
        return {k: _numpy(td[k], k) for k in self._keys}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.env.set_seed(int(seed))  # the env's episode order and draws, as TorchRL seeds it
        self._td = self.env.reset()
        return self._observation(self._td), {}

    def step(self, action):
        import torch

        if self._td is None:
            raise RuntimeError(f"{ENV_ID}: call reset() before step()")
        a = torch.as_tensor(np.asarray(action, dtype=np.float32)).reshape(self.action_space.shape)
        td = self._td.clone(False).set(K.ACTION, a.unsqueeze(0).to(self.env.device))
        nxt = self.env.step(td)["next"]
        self._td = nxt
        terminated, truncated = bool(nxt[K.TERMINATED].any()), bool(nxt[K.TRUNCATED].any())
        info = {}
        if terminated or truncated:
            info = {_INFO_NAMES.get(k[-1], k[-1]): _numpy(nxt[k]).item() for k in self._episode_keys}
        return self._observation(nxt), float(nxt[K.REWARD].sum()), terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array" or self._td is None or K.PIXELS not in self._td.keys():
            return None
        return _numpy(self._td[K.PIXELS])

    def close(self):
        self.env.close()


def register() -> None:
    """Register `WanderlandNav-v0` with Gymnasium (idempotent; the env class is imported on the first make)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point=f"{__name__}:WanderlandNavEnv")


register()
