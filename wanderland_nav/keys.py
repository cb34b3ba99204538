"""Every TensorDict key the environment, the policies and the trainer exchange.

Defined once here so that `envs/`, `policies/` and `train.py` never spell a key twice.

Frames
------
* **nav frame**: the scene's native frame rotated so that gravity points along -z (z up),
  metres. Derived from the scene's recorded up axis by `geometry.nav_from_scene_rotation`.
* **body frame**: the agent's own frame on the ground: x forward, y left, z up, origin at
  the agent's feet. This is the frame CityWalker, NoMaD and MBRA predict waypoints in.

Shapes below leave out the batch dimensions `[*B]` (the env's `batch_size`, usually `[B]`).

Key tree of an env step (`td` after `reset`, `td["next"]` after `step`); `?` marks keys that exist
only when the env is built for them (`NavEnvConfig` and the task's episodes)::

    past_positions, goal_vector, goal_pose                    observations: what a policy may read
    rgb?, depth?                                              camera on (depth: camera.depth)
    goal_image?, has_goal_image?                              an episode has a goal view (or the policy reads it)
    instruction_tokens?                                       an episode has an instruction (or observe_instruction)
    pixels?                                                   the newest frame, for video (pixels: true)
    expert_action?                                            the expert's action here, an imitation label
    privileged/?                                              ground truth: experts, BC labels, logs (privileged: true)
        episode_index, step_count, agent_position, agent_yaw,
        distance_to_goal, success, intervention, collision
    action                                                    written by the policy
    reward, done, terminated, truncated                       step outputs (in "next")
    episode/?                                                 step outputs (in "next" only): the running
        success, spl, navigation_error, path_length,          episode's metrics, final at done
        shortest_length, steps, collisions, intervention      (episode_metrics: true)

The policy inputs are `OBSERVATION_KEYS` (and `depth`). `privileged/`, `expert_action` and `pixels` are in the
observation spec too, because they must reach the next step's root (`step_mdp` moves exactly the observation
and done keys there): the expert and BC read the truth at the root, video reads `pixels`; none is a policy
input. `episode/` is in the reward spec: like the reward it exists in `("next", ...)` only, is never returned by
a reset and is never carried to the next step's root (the env's `step_mdp` drops reward keys; in the done
spec TorchRL would OR every leaf into `done`). Name the reward
where TorchRL wants one key: `RewardSum(in_keys=["reward"])`, `env.full_reward_spec["reward"]`.
`wanderland_nav.make_env` builds the policy-facing env: no `privileged/`, metrics on.
"""

# --------------------------------------------------------------------------- observations
RGB = "rgb"
"""uint8 `[T, H, W, 3]`: the last T camera frames, oldest first; index -1 is the current frame."""

DEPTH = "depth"
"""float32 `[T, H, W, 1]`: z-depth (metres along the optical axis) for the frames in `RGB`;
only present when the env is built with depth enabled. 0 where nothing was hit."""

PAST_POSITIONS = "past_positions"
"""float32 `[T, 2]`: the agent's positions at the times of the `RGB` frames, in the current
body frame (x forward, y left), metres; index -1 is always (0, 0)."""

GOAL_VECTOR = "goal_vector"
"""float32 `[2]`: the goal position in the current body frame (x forward, y left), metres."""

GOAL_POSE = "goal_pose"
"""float32 `[4]`: MBRA/LogoNav pose goal `[x, y, cos(dyaw), sin(dyaw)]` in the body frame, where
dyaw is the heading of the expert path's last segment relative to the agent's heading."""

GOAL_IMAGE = "goal_image"
"""uint8 `[H, W, 3]`: the view at the goal (image-goal episodes); zeros when the episode has none."""

HAS_GOAL_IMAGE = "has_goal_image"
"""bool `[1]`: whether `GOAL_IMAGE` holds a real goal view (NoMaD's goal mask is its negation)."""

INSTRUCTION_TOKENS = "instruction_tokens"
"""int64 `[L]`: the episode's instruction as UTF-8 bytes + 1, right-padded with 0 (no tokenizer needed)."""

PIXELS = "pixels"
"""uint8 `[H, W, 3]`: the newest camera frame (`RGB[-1]`), one per agent: TorchRL's `VideoRecorder` key."""

EXPERT_ACTION = "expert_action"
"""float32, shape of `ACTION`: what the path-following expert (`envs.ExpertPolicy`, navmesh shortest path)
would do from here; an imitation label computed from the privileged state, which itself stays out."""

# --------------------------------------------------------------------------- privileged state
PRIVILEGED = "privileged"
"""Sub-TensorDict of the env's state that no policy may read: the simulator's ground truth, for the
expert, the trainer's statistics, BC labels, metrics and logging (TorchRL's custom envs keep such state
in a nested key, e.g. the pendulum's `("params", ...)`). Every key below is `(PRIVILEGED, name)`."""

EPISODE_INDEX = (PRIVILEGED, "episode_index")
"""int64 `[1]`: index of the running episode in the env's episode list."""

STEP_COUNT = (PRIVILEGED, "step_count")
"""int64 `[1]`: control steps taken in the running episode."""

AGENT_POSITION = (PRIVILEGED, "agent_position")
"""float32 `[3]`: agent position (feet) in the nav frame, metres."""

AGENT_YAW = (PRIVILEGED, "agent_yaw")
"""float32 `[1]`: agent heading in the nav frame, radians, counter-clockwise from +x."""

DISTANCE_TO_GOAL = (PRIVILEGED, "distance_to_goal")
"""float32 `[1]`: geodesic distance from the agent to the goal on the navmesh, metres."""

SUCCESS = (PRIVILEGED, "success")
"""bool `[1]`: the episode ended within the goal radius."""

INTERVENTION = (PRIVILEGED, "intervention")
"""bool `[1]`: the episode ended by intervention (stuck, no progress, left the navigable region)."""

COLLISION = (PRIVILEGED, "collision")
"""bool `[1]`: this step's motion was blocked or deflected by the navmesh boundary."""

# --------------------------------------------------------------------------- episode metrics
EPISODE = "episode"
"""Sub-TensorDict of the running episode's metrics (`NavEnvConfig.episode_metrics`), a step output in the reward
spec: every step's `("next", "episode")` holds them, so at `("next", "done")` the finished episode's final values;
a reset starts them from zero and returns none. What collectors and loggers read (the paper's NE / SR / SPL);
never a policy input."""

EPISODE_SUCCESS = (EPISODE, "success")
"""bool `[1]`: the episode succeeded (so far: False until the step that ends it within the goal radius)."""

EPISODE_SPL = (EPISODE, "spl")
"""float32 `[1]`: success weighted by path length, `success * shortest / max(path, shortest)`."""

EPISODE_NAVIGATION_ERROR = (EPISODE, "navigation_error")
"""float32 `[1]`: Euclidean distance from the agent to the goal (the paper's NE), metres."""

EPISODE_PATH_LENGTH = (EPISODE, "path_length")
"""float32 `[1]`: horizontal distance walked in the episode, metres."""

EPISODE_SHORTEST_LENGTH = (EPISODE, "shortest_length")
"""float32 `[1]`: exact geodesic start -> goal length, metres."""

EPISODE_STEPS = (EPISODE, "steps")
"""int64 `[1]`: control steps taken."""

EPISODE_COLLISIONS = (EPISODE, "collisions")
"""int64 `[1]`: steps whose motion the navmesh boundary blocked or deflected."""

EPISODE_INTERVENTION = (EPISODE, "intervention")
"""bool `[1]`: the episode ended by intervention (stuck, no progress, off the navmesh)."""

EPISODE_KEYS = (EPISODE_SUCCESS, EPISODE_SPL, EPISODE_NAVIGATION_ERROR, EPISODE_PATH_LENGTH, EPISODE_SHORTEST_LENGTH,
                EPISODE_STEPS, EPISODE_COLLISIONS, EPISODE_INTERVENTION)
"""Every `(EPISODE, name)` key the env writes."""

EPISODE_PERSON_COLLISIONS = (EPISODE, "person_collisions")
"""int64 `[1]`: steps in which a pedestrian touched the agent (`env.pedestrians`; `EpisodeMetrics` has the same)."""

EPISODE_INTIMATE_SECONDS = (EPISODE, "intimate_seconds")
"""float32 `[1]`: seconds with the nearest pedestrian in the intimate zone, [0, 0.45) m from the agent's edge."""

EPISODE_PERSONAL_SECONDS = (EPISODE, "personal_seconds")
"""float32 `[1]`: seconds with the nearest pedestrian in the personal zone, [0.45, 1.2) m from the agent's edge."""

EPISODE_SOCIAL_SECONDS = (EPISODE, "social_seconds")
"""float32 `[1]`: seconds with the nearest pedestrian in the social zone, [1.2, 3.6) m from the agent's edge."""

EPISODE_MIN_PERSON_DISTANCE = (EPISODE, "min_person_distance")
"""float32 `[1]`: the closest centre distance to any pedestrian so far, metres (inf before the first step)."""

EPISODE_MIN_TIME_TO_COLLISION = (EPISODE, "min_time_to_collision")
"""float32 `[1]`: the smallest constant-velocity time-to-collision with any pedestrian so far, seconds (capped at
`evaluation.social.TTC_HORIZON`)."""

EPISODE_STALLED_SECONDS = (EPISODE, "stalled_seconds")
"""float32 `[1]`: seconds in which the agent neither moved nor turned."""

EPISODE_PATH_IRREGULARITY = (EPISODE, "path_irregularity")
"""float32 `[1]`: total absolute heading change per metre of max(path, shortest) length, rad/m."""

EPISODE_JERK = (EPISODE, "jerk")
"""float32 `[1]`: mean magnitude of the agent's horizontal jerk per step, m/s^3."""

EPISODE_SOCIAL_KEYS = (EPISODE_PERSON_COLLISIONS, EPISODE_INTIMATE_SECONDS, EPISODE_PERSONAL_SECONDS,
                       EPISODE_SOCIAL_SECONDS, EPISODE_MIN_PERSON_DISTANCE, EPISODE_MIN_TIME_TO_COLLISION,
                       EPISODE_STALLED_SECONDS, EPISODE_PATH_IRREGULARITY, EPISODE_JERK)
"""The `(EPISODE, name)` keys the env adds with pedestrians on (`env.pedestrians.count > 0`)."""

# --------------------------------------------------------------------------- actions
ACTION = "action"
"""float32: `[K, 2]` body-frame waypoints (x forward, y left, metres) in waypoint mode, or `[2]`
`(v [m/s], omega [rad/s])` in velocity mode."""

WAYPOINTS = "waypoints"
"""float32 `[K, 2]`: a policy's deterministic (mean) waypoint prediction in the body frame."""

ARRIVAL_LOGIT = "arrival_logit"
"""float32 `[1]`: CityWalker-style logit that the agent has arrived."""

# --------------------------------------------------------------------------- PPO
LOC = "loc"
"""float32, shape of `ACTION`: mean of the Gaussian action distribution."""

SCALE = "scale"
"""float32, shape of `ACTION`: standard deviation of the Gaussian action distribution."""

ACTION_LOG_PROB = "action_log_prob"
"""float32 `[]`: log-probability of `ACTION` under the behaviour policy (summed over action dims)."""

STATE_VALUE = "state_value"
"""float32 `[1]`: the value head's estimate."""

# --------------------------------------------------------------------------- step outputs
REWARD = "reward"
"""float32 `[1]`: +R_succ on success, -R_fail on intervention, else -alpha + beta * (d_{t-1} - d_t)."""

DONE = "done"
TERMINATED = "terminated"
TRUNCATED = "truncated"
"""bool `[1]` each, TorchRL's convention: done = terminated | truncated; truncated = timeout."""

RESET = "_reset"
"""bool `[1]`: TorchRL's partial-reset mask."""

OBSERVATION_KEYS = (
    RGB,
    PAST_POSITIONS,
    GOAL_VECTOR,
    GOAL_POSE,
    GOAL_IMAGE,
    HAS_GOAL_IMAGE,
    INSTRUCTION_TOKENS,
)
"""Keys a policy may read (plus `DEPTH` when enabled), each present only when the env carries it: no
`RGB` / `DEPTH` with the camera off, no `GOAL_IMAGE` / `HAS_GOAL_IMAGE` unless an episode has a goal view
(or `NavEnvConfig.observe_goal_image`), no `INSTRUCTION_TOKENS` unless an episode has an instruction (or
`observe_instruction`). The rest of the observation spec is `PIXELS`, `EXPERT_ACTION` and `PRIVILEGED`, each
when the env is built for it; `EPISODE` is in the reward spec (see the key tree above)."""

PRIVILEGED_KEYS = (EPISODE_INDEX, STEP_COUNT, AGENT_POSITION, AGENT_YAW, DISTANCE_TO_GOAL, SUCCESS, INTERVENTION,
                   COLLISION)
"""Every `(PRIVILEGED, name)` key the env writes."""
