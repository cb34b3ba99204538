"""Scene preparation: what `prepare` (and the first `train` / `evaluate` on a scene) builds beside a scene.

* `scene`: one scene's collision mesh and navmesh, cached by the digest of their inputs, with the
  navmesh-vs-scene up-axis check (`prepare_scene`);
* `scene_set`: a scene set prepared in parallel (process pool or Ray tasks), resumably, its failures listed.
"""
