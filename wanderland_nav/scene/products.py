"""Where a scene's generated files go: beside the scene, or in a cache folder when the scene is read-only.

Released data often sits on a read-only share. Collision mesh, navmesh, episodes and goal views are then
written to `$WANDERLAND_NAV_CACHE/scenes/<scene folder name>-<hash of its absolute path>` (default cache:
`$XDG_CACHE_HOME/wanderland_nav`, else `~/.cache/wanderland_nav`), decided when the scene is loaded, before
any computation, and logged. Files already beside the scene (a released `episodes.json`) are still read.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

from wanderland_nav.cache import CACHE_ENV, cache_root, writable  # the one user cache folder of the project

log = logging.getLogger(__name__)

def products_dir(root: Path) -> Path | None:
    """None when `root` takes generated files itself; else the cache folder that stands in for it (created)."""
    root = Path(root)
    if writable(root):
        return None
    key = hashlib.sha256(str(root.resolve()).encode()).hexdigest()[:8]
    out = cache_root() / "scenes" / f"{root.name}-{key}"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OSError(e.errno, f"{root} is read-only and its cache folder {out} cannot be made ({e.strerror}); "
                               f"set {CACHE_ENV} to a writable folder", str(out)) from None
    if not writable(out):
        raise PermissionError(f"{root} is read-only and its cache folder {out} is not writable either; "
                              f"set {CACHE_ENV} to a writable folder")
    log.warning("%s is read-only: generated files (collision mesh, navmesh, episodes, goal views) go to %s "
                "(set %s to move it)", root, out, CACHE_ENV)
    return out
