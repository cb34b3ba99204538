"""Navigation episodes: the episodes.json schema, and the expert-trajectory generator.

`from wanderland_nav.episodes import Episode, load_episodes, save_episodes` is cheap (numpy only);
`generate_episodes` pulls in the planners and the renderer, so it is imported lazily.
"""

from wanderland_nav.episodes.schema import (
    CORE_FIELDS,
    MIN_INSTRUCTION_WORDS,
    SPLITS,
    Episode,
    EpisodeFile,
    EpisodeFormatError,
    Goal,
    dump_episodes,
    load_episode_file,
    load_episodes,
    parse_episode_file,
    rotation_from_yaw,
    save_episodes,
    yaw_from_rotation,
)

__all__ = [
    "CORE_FIELDS", "MIN_INSTRUCTION_WORDS", "SPLITS", "Episode", "EpisodeFile", "EpisodeFormatError", "Goal",
    "dump_episodes", "load_episode_file", "load_episodes", "parse_episode_file", "rotation_from_yaw",
    "save_episodes", "yaw_from_rotation", "generate_episodes", "GeneratorSettings",
]


def __getattr__(name):  # lazy: the generator imports planners and render
    if name in ("generate_episodes", "GeneratorSettings"):
        from wanderland_nav.episodes import generate

        return getattr(generate, name)
    raise AttributeError(f"module 'wanderland_nav.episodes' has no attribute {name!r}")
