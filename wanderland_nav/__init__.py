"""wanderland_nav: embodied navigation in geometrically grounded simulation.

scene folder -> Scene -> collision mesh -> NavMesh -> episodes.json -> NavEnv -> PPO / evaluate,
with Gaussians -> render() as the camera and rerun as the eyes. See ARCHITECTURE.md.

`wanderland_nav.make_env(scene="demo")` is the one-call TorchRL environment (`compose/make_env.py`);
it is imported on first use, so `import wanderland_nav` stays free of Hydra and TorchRL, and importing the
package changes nothing in the process (the entry points ready it: `wanderland_nav/app.py`).
"""

__version__ = "0.1.0"


def __getattr__(name):
    if name == "make_env":
        from wanderland_nav.compose.make_env import make_env

        return make_env
    raise AttributeError(f"module 'wanderland_nav' has no attribute {name!r}")
