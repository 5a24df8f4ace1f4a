"""Cache entries that are checked, not trusted: each is a folder built in private and published by one rename,
with a manifest of its files' SHA-256 that is verified every time the entry is used.

* A process that finds the entry being built by another waits for it (a lock beside the entry, up to
  ``BUILD_WAIT_S``) instead of building it again (a race of the twin is minutes of CPU); past that wait, or where
  the lock cannot be had, both build, the first rename wins and the other uses the winner's entry. A caller that
  must answer sooner asks for a shorter wait and hears :class:`StillBuilding` past it.
* An entry whose files are missing, changed, truncated or joined by strangers is set aside and rebuilt, with
  a warning naming it; nothing outside the cache folder is touched.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import tempfile
import time
from typing import Callable, Iterator

try:
    import fcntl
except ImportError:  # (not POSIX: no lock; two builders of one entry both build, as the rename allows)
    fcntl = None

from lf_common.errors import LineFollowerError
from lf_common.files import MANIFEST, foreign_entries, publish_once, write_manifest

log = logging.getLogger(__name__)
BUILD_WAIT_S = 900.0  # [s] at most, waiting for another process's build of the same entry; then build it too
POLL_S = 0.1


class StillBuilding(LineFollowerError):
    """Another process is building the entry, and did not finish within the wait the caller asked for."""


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


def cached_folder(target: str, build: Callable[[str], None], what: str, wait_s: float | None = None,
                  build_here: bool = True) -> str:
    """The verified cache folder ``target``, built by ``build(tmp)`` into an empty private folder if needed.
    ``wait_s``: how long to wait for another process building it (None: ``BUILD_WAIT_S``, then build it here too).
    ``build_here`` False: never build it here (it is to come from another process).

    Raises:
      StillBuilding: another process is still building it after ``wait_s``, or (``build_here`` False) it is not
        built yet (nothing here was built or removed).
      LineFollowerError: the cache folder cannot be written (the message names it).
    """
    problems = entry_problems(target)
    if not problems:
        return target
    parent = os.path.dirname(target)
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as e:
        raise LineFollowerError(f"cache {parent}: cannot write ({e.strerror or e}); set TWIN_CACHE_DIR to a writable folder") from None
    with _one_builder(target, what, wait_s):
        problems = entry_problems(target)
        if problems and not build_here:
            raise StillBuilding(f"cache: {what} {target} is not built yet")
        if problems:  # else built by the process we waited for
            _build(target, build, what, problems)
    return target


def lock_path(target: str) -> str:
    """The lock a process building the entry ``target`` holds (a hidden file beside it)."""
    return os.path.join(os.path.dirname(target), f".{os.path.basename(target)}.lock")


@contextlib.contextmanager
def _one_builder(target: str, what: str, wait_s: float | None = None) -> Iterator[None]:
    """Held while ``target`` is built, so that another process asking for it waits instead of building it too. The
    lock is a file beside the entry (hidden), removed by whoever held it when done (built, found built, or failed):
    a process still waiting on it, or one that opens a new one, finds the entry when it gets the lock (or, after a
    failed build, builds it). Past ``wait_s`` (not None), :class:`StillBuilding`, the lock left to its holder."""
    path = lock_path(target)
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644) if fcntl else None
    except OSError:
        fd = None
    if fd is None:
        yield
        return
    gave_up = False
    try:
        deadline = time.monotonic() + (BUILD_WAIT_S if wait_s is None else min(wait_s, BUILD_WAIT_S))
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    if wait_s is not None:
                        gave_up = True
                        raise StillBuilding(f"cache: {what} {target} is still being built by another process after "
                                            f"{wait_s:g} s") from None
                    log.warning("cache: %s %s is still being built by another process after %.0f s; building it "
                                "here too", what, target, BUILD_WAIT_S)
                    break
                time.sleep(POLL_S)
        yield
    finally:
        with contextlib.suppress(OSError):
            if not gave_up and os.stat(path).st_ino == os.fstat(fd).st_ino:  # ours, not a newer one's
                os.unlink(path)
        os.close(fd)


def _build(target: str, build: Callable[[str], None], what: str, problems: list[str]) -> None:
    parent = os.path.dirname(target)
    try:
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
