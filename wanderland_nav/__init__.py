"""wanderland_nav: embodied navigation in geometrically grounded simulation.

scene folder -> Scene -> collision mesh -> NavMesh -> episodes.json -> NavEnv -> PPO / evaluate,
with Gaussians -> render() as the camera and rerun as the eyes. See ARCHITECTURE.md.
"""

__version__ = "0.1.0"
