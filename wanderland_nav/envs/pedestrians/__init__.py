"""Pedestrians: people walking the navmesh around the robots, as one component of `NavEnv`.

* `component`: `Pedestrians`, the crowd with its social counters behind the hooks the env calls every reset and
  step (`make_pedestrians` builds it, or `NoPedestrians`, whose hooks change nothing, when `count` is 0): the env's
  body never asks whether there is a crowd;
* `crowd`: `Crowd` (P people per env instance, shortest-path corners, pauses, respawns); the social metrics it feeds are
  `evaluation.social`'s;
* `social_force`: the force model; `bodies`: their Gaussians for the cameras; `config`: `PedestrianConfig`.
"""
