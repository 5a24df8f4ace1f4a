"""Cache entries that are checked, not trusted: each is a folder built in private and published by one rename,
with a manifest of its files' SHA-256 that is verified every time the entry is used.

* Two processes building the same entry at once both build; the first rename wins and the other uses the
  winner's entry (its own copy is discarded).
* An entry whose files are missing, changed, truncated or joined by strangers is set aside and rebuilt, with
  a warning naming it; nothing outside the cache folder is touched.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from typing import Callable

from lf_common.errors import LineFollowerError
from lf_common.files import MANIFEST, foreign_entries, publish_once, write_manifest

log = logging.getLogger(__name__)


def cache_dir() -> str:
    """Where generated robots, track textures and converted meshes are kept: ``$TWIN_CACHE_DIR`` or
    ~/.cache/line-follower-twin."""
    return os.environ.get("TWIN_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "line-follower-twin")


def entry_problems(folder: str) -> list[str]:
    """Why a cache entry cannot be used (empty list: it is complete and unchanged)."""
    if not os.path.isdir(folder):
        return ["missing"]
    if not os.path.isfile(os.path.join(folder, MANIFEST)):
        return ["no manifest"]
    return foreign_entries(folder)


def cached_folder(target: str, build: Callable[[str], None], what: str) -> str:
    """The verified cache folder ``target``, built by ``build(tmp)`` into an empty private folder if needed.

    Raises:
      LineFollowerError: the cache folder cannot be written (the message names it).
    """
    problems = entry_problems(target)
    if not problems:
        return target
    parent = os.path.dirname(target)
    try:
        os.makedirs(parent, exist_ok=True)
        if problems != ["missing"]:
            log.warning("cache: %s %s is damaged (%s); rebuilding it", what, target, ", ".join(problems[:3]))
            aside = tempfile.mkdtemp(prefix=f".{os.path.basename(target)}.", suffix=".bad", dir=parent)
            try:
                os.rename(target, os.path.join(aside, "entry"))
            except FileNotFoundError:
                pass  # another process set it aside first
            shutil.rmtree(aside, ignore_errors=True)
        tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(target)}.", suffix=".tmp", dir=parent)
    except OSError as e:
        raise LineFollowerError(f"cache {parent}: cannot write ({e.strerror or e}); set TWIN_CACHE_DIR to a writable folder") from None
    try:
        build(tmp)
        write_manifest(tmp)
        publish_once(tmp, target)
    except OSError as e:
        raise LineFollowerError(f"cache {target}: cannot write ({e.strerror or e})") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    problems = entry_problems(target)
    if problems:  # the winner of a race left a bad entry: not ours to fix twice
        raise LineFollowerError(f"cache {target}: {what} is damaged right after it was built ({', '.join(problems[:3])})")
    return target
