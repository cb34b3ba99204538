"""Whose an episodes file is: the project's only when its bytes are those it wrote (the sha256 recorded in its
`generator` block when written), else the user's, never regenerated in place (`episodes_target` then writes beside)."""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

from wanderland_nav.episodes.schema import EpisodeFormatError, load_episode_file, read_episode_bytes

log = logging.getLogger("wanderland_nav.episodes.generate")


GENERATOR_NAME = "wanderland_nav.make_episodes"  # the `generator.name` this project writes into its episode files
# names earlier versions wrote (the entry point was `wanderland_nav.expert`): their files are still ours
OUR_GENERATOR_NAMES = (GENERATOR_NAME, "wanderland_nav.expert")


#: the `generator` field holding the sha256 of the file's own (uncompressed) bytes as written, computed with
#: this field set to `_UNSTAMPED`: any later change to the bytes (a hand edit, a reformat) shows as a mismatch
WRITTEN_DIGEST = "written_sha256"
_UNSTAMPED = "0" * 64


def _stamp(digest: str) -> bytes:
    return f'"{WRITTEN_DIGEST}": "{digest}"'.encode()


def _stamped(data: bytes) -> bytes:
    """`data` (written with `WRITTEN_DIGEST` = `_UNSTAMPED`) with the sha256 of those bytes in its place."""
    return data.replace(_stamp(_UNSTAMPED), _stamp(hashlib.sha256(data).hexdigest()), 1)


def not_ours_because(path: Path) -> str | None:
    """Why `path` is not an episodes file this project wrote byte for byte (None: it is).

    Ours means: a valid episodes file, our `generator` block, and bytes whose sha256 (with the recorded
    digest blanked) is the digest recorded when it was written. A file whose block survived a hand edit is
    the user's: it is never regenerated in place."""
    try:
        f = load_episode_file(path)
    except (EpisodeFormatError, OSError) as e:
        return f"not an episodes file of this project ({e})"
    gen = f.extras.get("generator")
    if not (isinstance(gen, dict) and gen.get("name") in OUR_GENERATOR_NAMES):
        return "it has no generator block of this project"
    recorded = gen.get(WRITTEN_DIGEST)
    if not isinstance(recorded, str) or len(recorded) != 64:
        return f"its generator block records no digest of the bytes written (generator.{WRITTEN_DIGEST})"
    raw = read_episode_bytes(path)
    if raw.count(_stamp(recorded)) != 1 or \
            hashlib.sha256(raw.replace(_stamp(recorded), _stamp(_UNSTAMPED))).hexdigest() != recorded:
        return (f"its bytes are not those written (their sha256 differs from generator.{WRITTEN_DIGEST}): "
                "edited after it was written, so it is the user's")
    return None


def written_by_us(path: Path) -> bool:
    """Whether `path` is an episodes file this project wrote, unchanged since (`not_ours_because`)."""
    return not_ours_because(path) is None


def generated_sibling(path: Path) -> Path:
    """`episodes.json` -> `episodes.generated.json` (`x.json.gz` -> `x.generated.json.gz`)."""
    stem, _, suffixes = path.name.partition(".")
    return path.with_name(f"{stem}.generated.{suffixes}" if suffixes else f"{stem}.generated")


def episodes_target(out: Path, *, force: bool) -> Path:
    """Where to write: `out`, unless `out` exists and this project did not write it (released data, a
    hand-edited or foreign file): then its `generated_sibling`, so released data is never overwritten.
    `force=True` overwrites whatever is at `out`."""
    why = None if force or not out.exists() else not_ours_because(out)
    if why is None:
        return out
    target = generated_sibling(out)
    log.warning("%s was not written by %s (%s): left untouched; generated episodes go to %s "
                "(force=true overwrites it)", out, GENERATOR_NAME, why, target)
    return target
