"""wanderland_nav: embodied navigation in geometrically grounded simulation.

scene folder -> Scene -> collision mesh -> NavMesh -> episodes.json -> NavEnv -> PPO / evaluate,
with Gaussians -> render() as the camera and rerun as the eyes. See ARCHITECTURE.md.

`wanderland_nav.make_env(scene="demo")` is the one-call TorchRL environment (`compose/make_env.py`);
it is imported on first use, so `import wanderland_nav` stays free of torch, Hydra and TorchRL, and importing the
package changes nothing in the process (the entry points ready it: `wanderland_nav/app.py`) but Gymnasium's
registry: where Gymnasium is installed (the `gym` extra), `import wanderland_nav` registers `WanderlandNav-v0`
(`wanderland_nav/gym.py`: Gymnasium and numpy only; the env is built on the first `gymnasium.make`).
"""

import importlib.util

__version__ = "0.1.0"

if importlib.util.find_spec("gymnasium") is not None:  # Gymnasium 1.x reads no plugin entry points
    from wanderland_nav import gym as _gym  # noqa: E402,F401  registers WanderlandNav-v0


def __getattr__(name):
    if name == "make_env":
        from wanderland_nav.compose.make_env import make_env

        return make_env
    raise AttributeError(f"module 'wanderland_nav' has no attribute {name!r}")
