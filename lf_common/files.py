"""Writing outputs without losing anything the user owns, and reading inputs within size limits.

The rules (docs/cli.md's "What is guaranteed" says the same):

* A file is written under a temporary name in its own folder, flushed to disk and renamed over the target,
  so a reader sees the old file or the new one, never half of one. A failure removes the temporary file.
* An existing file is replaced only if this program wrote it: each kind of output recognises its own
  (a ``"generator"`` key in JSON, the application id in a rerun recording, a comment atop an MJCF file).
  A symbolic link is never replaced.
* An output folder is built as a hidden temporary sibling and swapped in whole (``renameat2`` exchange
  where the kernel has it). An existing folder is replaced only when it is empty, or holds exactly the
  files this program wrote there, unchanged: its manifest ``.line-follower-twin.json`` lists them with their
  SHA-256. Anything else is refused before any work starts, and again at the swap.
* Missing parent folders are not created: a typo in a path is an error, not a new folder tree.
* Inputs are read with a size limit and must be regular files (a device or pipe could never end).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import hashlib
import json
import math
import os
import shutil
import stat
import tempfile
from typing import IO, Callable, Iterator

from lf_common.errors import InputTooLarge, LineFollowerError, OutputError

GENERATOR = "line-follower-twin"
MANIFEST = ".line-follower-twin.json"
MJCF_MARKER = f"<!-- written by {GENERATOR} -->"

_UMASK = os.umask(0)
os.umask(_UMASK)


def _why(e: OSError) -> str:
    return e.strerror or str(e)


# --- recognising our own files -------------------------------------------------------------------------

def _generator_of(path: str, first_line_only: bool) -> object:
    """The ``"generator"`` of a JSON document (or of the first line of JSON Lines), None if there is none."""
    try:
        with open(path, "rb") as f:
            doc = json.loads(f.readline(2**16) if first_line_only else f.read(16 * 2**20))
    except (OSError, ValueError, RecursionError):
        return None
    return doc.get("generator") if isinstance(doc, dict) else None


def json_is_ours(path: str) -> bool:
    """A JSON object whose ``"generator"`` is this program."""
    return _generator_of(path, first_line_only=False) == GENERATOR


def jsonl_is_ours(path: str) -> bool:
    """JSON Lines whose first line is an object with this program as ``"generator"``."""
    return _generator_of(path, first_line_only=True) == GENERATOR


def rrd_is_ours(path: str) -> bool:
    """A rerun recording (magic ``RRF2``) that this program's application id opens."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    return head.startswith(b"RRF2") and GENERATOR.encode() in head


def first_line_is_ours(path: str) -> bool:
    """A text file whose first line carries :data:`MJCF_MARKER` (MJCF written by this program)."""
    try:
        with open(path, "rb") as f:
            return MJCF_MARKER.encode() in f.readline(4096)
    except OSError:
        return False


# --- files ---------------------------------------------------------------------------------------------

def check_output_file(path: str, is_ours: Callable[[str], bool] | None, what: str = "output") -> str:
    """Check that ``path`` can be written as a new file or replaces one of ours; returns it absolute.

    Raises:
      OutputError: naming ``path`` as given: missing or read-only folder, a folder or link at ``path``, or a
        file there that this program did not write.
    """
    if not isinstance(path, str) or not path or "\0" in path:
        raise OutputError(f"{path!r}: not a usable {what} path")
    full = os.path.abspath(path)
    parent = os.path.dirname(full)
    if not os.path.isdir(parent):
        raise OutputError(f"{path}: folder {parent} does not exist (create it first)")
    if os.path.islink(full):
        raise OutputError(f"{path}: is a symbolic link; name a new file for the {what}")
    if os.path.isdir(full):
        raise OutputError(f"{path}: is a folder; name a file for the {what}")
    if os.path.exists(full):
        if not os.path.isfile(full):
            raise OutputError(f"{path}: exists and is not a regular file")
        if is_ours is None or not is_ours(full):
            raise OutputError(f"{path}: exists and was not written by {GENERATOR}; choose a new name or move it away")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: folder {parent} is not writable")
    return full


@contextlib.contextmanager
def atomic_path(path: str, is_ours: Callable[[str], bool] | None, what: str = "output") -> Iterator[str]:
    """A temporary path beside ``path`` (same extension) for a writer that wants a file name; renamed over
    ``path`` when the ``with`` block completes, removed if it fails."""
    full = check_output_file(path, is_ours, what)
    parent, name = os.path.split(full)
    ext = os.path.splitext(name)[1]
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=f".tmp{ext}", dir=parent)
        os.close(fd)
    except OSError as e:
        raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)
        check_output_file(path, is_ours, what)  # something else may have appeared meanwhile
        os.replace(tmp, full)
    except OSError as e:
        raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


@contextlib.contextmanager
def atomic_file(path: str, is_ours: Callable[[str], bool] | None, what: str = "output", binary: bool = False) -> Iterator[IO]:
    """An open file (text UTF-8, or ``binary``) whose content replaces ``path`` atomically on success."""
    with atomic_path(path, is_ours, what) as tmp:
        try:
            f = open(tmp, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8", "newline": "\n"}))
        except OSError as e:
            raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
        with f:
            yield f


def json_safe(obj):
    """A copy of nested dicts, lists and tuples with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def write_json(path: str, doc: dict, what: str = "JSON output", is_ours: Callable[[str], bool] = json_is_ours) -> str:
    """``doc`` with ``"generator"`` first, written atomically; replaces only a file ``is_ours`` recognises (by
    default a JSON file of ours)."""
    text = json.dumps(json_safe({"generator": GENERATOR, **doc}), indent=2, allow_nan=False, default=str) + "\n"
    with atomic_file(path, is_ours, what) as f:
        f.write(text)
    return os.path.abspath(path)


# --- folders -------------------------------------------------------------------------------------------

def _tree(root: str) -> tuple[set[str], set[str]]:
    """(files, folders) under ``root`` as relative paths; links count as files."""
    files, dirs = set(), set()
    for here, subdirs, names in os.walk(root, followlinks=False):
        rel = os.path.relpath(here, root)
        for d in subdirs:
            p = os.path.normpath(os.path.join(rel, d))
            (files if os.path.islink(os.path.join(here, d)) else dirs).add(p)
        for n in names:
            files.add(os.path.normpath(os.path.join(rel, n)))
    return files, dirs


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def files_digest(paths, top: str) -> str:
    """One SHA-256 over the files ``paths`` (each named by its path relative to ``top``, then its bytes), in sorted
    order: what a cache key holds for the code or data it was made with."""
    h = hashlib.sha256()
    for path in sorted(set(paths)):
        h.update(os.path.relpath(path, top).encode() + b"\0")
        with open(path, "rb") as f:
            h.update(f.read())
    return h.hexdigest()


def write_manifest(folder: str) -> dict[str, str]:
    """List every file under ``folder`` with its SHA-256 in ``folder/MANIFEST``; returns {file: hash}."""
    files, dirs = _tree(folder)
    files.discard(MANIFEST)
    hashes = {f: _sha256(os.path.join(folder, f)) for f in sorted(files)}
    with open(os.path.join(folder, MANIFEST), "w", encoding="utf-8") as f:
        json.dump({"generator": GENERATOR, "files": hashes, "folders": sorted(dirs)}, f, indent=1)
    return hashes


def foreign_entries(folder: str) -> list[str]:
    """What in ``folder`` this program did not write, or changed since (empty: the folder is ours or empty)."""
    files, dirs = _tree(folder)
    if not files and not dirs:
        return []
    try:
        with open(os.path.join(folder, MANIFEST), encoding="utf-8") as f:
            manifest = json.load(f)
        listed, listed_dirs = dict(manifest["files"]), set(manifest.get("folders", []))
        if manifest.get("generator") != GENERATOR:
            raise ValueError
    except (OSError, ValueError, KeyError, TypeError):
        return sorted(files | dirs)
    files.discard(MANIFEST)
    foreign = sorted((files - set(listed)) | (dirs - listed_dirs))
    for f in sorted(files & set(listed)):
        try:
            if _sha256(os.path.join(folder, f)) != listed[f]:
                foreign.append(f"{f} (changed)")
        except OSError:
            foreign.append(f)
    return foreign


def check_output_dir(path: str, what: str = "output folder") -> str:
    """Check that ``path`` can become a folder of ours (new, empty, or ours unchanged); returns it absolute."""
    if not isinstance(path, str) or not path or "\0" in path:
        raise OutputError(f"{path!r}: not a usable {what} path")
    full = os.path.abspath(path)
    parent = os.path.dirname(full)
    here = os.path.abspath(os.getcwd())
    if full == parent or here == full or here.startswith(full + os.sep):
        raise OutputError(f"{path}: is the current folder or one above it; name a new folder for the {what}")
    if not os.path.isdir(parent):
        raise OutputError(f"{path}: folder {parent} does not exist (create it first)")
    if os.path.islink(full):
        raise OutputError(f"{path}: is a symbolic link; name a new folder for the {what}")
    if os.path.exists(full):
        if not os.path.isdir(full):
            raise OutputError(f"{path}: is a file; name a folder for the {what}")
        foreign = foreign_entries(full)
        if foreign:
            shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise OutputError(f"{path}: holds files {GENERATOR} did not write ({shown}); choose a new folder or "
                              "move them away")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: folder {parent} is not writable")
    return full


_RENAME_EXCHANGE = 2


def _exchange(a: str, b: str) -> bool:
    """Swap two paths in one step (Linux renameat2); False where the kernel or libc cannot."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    rc = renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), b)


def _publish_dir(tmp: str, full: str, path: str, what: str) -> None:
    """Put the finished folder ``tmp`` at ``full``: a rename when nothing is there, else a swap with a folder
    that is (still) ours; the old content is then removed."""
    try:
        os.rename(tmp, full)  # replaces nothing but an empty folder
        return
    except OSError as e:
        if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
    check_output_dir(path, what)
    try:
        if not _exchange(tmp, full):
            old = tempfile.mkdtemp(prefix=f".{os.path.basename(full)}.", suffix=".old", dir=os.path.dirname(full))
            os.rename(full, os.path.join(old, "d"))
            os.rename(tmp, full)
            shutil.rmtree(old, ignore_errors=True)
            return
    except OSError as e:
        raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
    shutil.rmtree(tmp, ignore_errors=True)  # tmp now holds the old content, which was ours


@contextlib.contextmanager
def output_dir(path: str, what: str = "output folder") -> Iterator[str]:
    """A temporary folder to fill; on success it gets a manifest and replaces ``path`` (new, empty, or ours).
    On failure nothing at ``path`` changes and the temporary folder is removed."""
    full = check_output_dir(path, what)
    try:
        tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(full)}.", suffix=".tmp", dir=os.path.dirname(full))
    except OSError as e:
        raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
    try:
        yield tmp
        write_manifest(tmp)
        os.chmod(tmp, 0o777 & ~_UMASK)
        _publish_dir(tmp, full, path, what)
    except OSError as e:
        raise OutputError(f"{path}: cannot write the {what} ({_why(e)})") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def publish_once(tmp: str, target: str) -> bool:
    """Rename a finished folder into place unless another process already did (a cache race). Returns True
    if ``tmp`` became ``target``; otherwise ``tmp`` is removed and the winner's ``target`` stays."""
    try:
        os.rename(tmp, target)
        return True
    except OSError as e:
        if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    shutil.rmtree(tmp, ignore_errors=True)
    return False


# --- reading with limits -------------------------------------------------------------------------------

_KINDS = ((stat.S_ISDIR, "folder"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISCHR, "character device"),
          (stat.S_ISBLK, "block device"), (stat.S_ISSOCK, "socket"))


def input_file(path: str, what: str) -> os.stat_result:
    """Check that ``path`` is a regular file: the one check of every input file a flag names (a FIFO or device
    would block a reader or never end). Returns its ``stat``.

    Raises:
      LineFollowerError: ``PATH: no such WHAT``, ``PATH: is a FIFO, not a regular file`` (a folder, a device, a
        socket alike), or ``PATH: cannot read the WHAT (why)``.
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise LineFollowerError(f"{path}: no such {what}") from None
    except (OSError, ValueError) as e:
        raise LineFollowerError(f"{path}: cannot read the {what} ({getattr(e, 'strerror', None) or e})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _KINDS if test(st.st_mode)), "special file")
        raise LineFollowerError(f"{path}: is a {kind}, not a regular file")
    return st


def read_bytes(path: str, limit: int, what: str) -> bytes:
    """The whole of a regular file (:func:`input_file`) of at most ``limit`` bytes.

    Raises:
      LineFollowerError: missing, not a regular file, unreadable; InputTooLarge above ``limit``.
    """
    st = input_file(path, what)
    if st.st_size > limit:
        raise InputTooLarge(f"{path}: the {what} is {st.st_size / 1e6:.1f} MB, more than the {limit / 1e6:g} MB limit")
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as e:
        raise LineFollowerError(f"{path}: cannot read the {what} ({_why(e)})") from None
    if len(data) > limit:
        raise InputTooLarge(f"{path}: the {what} is more than the {limit / 1e6:g} MB limit")
    return data


def read_text(path: str, limit: int, what: str) -> str:
    """A UTF-8 text file of at most ``limit`` bytes."""
    data = read_bytes(path, limit, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise LineFollowerError(f"{path}:{line}: the {what} is not UTF-8 text (byte 0x{data[e.start]:02x})") from None


MAX_INT_DIGITS = 40  # a seed, the longest whole number the twin reads, has 20 digits


class _DuplicateKey(Exception):
    pass


class _LongInteger(Exception):
    pass


def _unique_keys(pairs: list) -> dict:
    out = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _integer(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:  # before int(): Python refuses 4300+ digits with its own advice
        raise _LongInteger(text)
    return int(text)


def parse_json(text: str, where: str):
    """JSON from text; errors name ``where`` (a path, or path:line) and stay one line. A key given twice in one
    object (``json`` would keep the last silently) and a whole number longer than ``MAX_INT_DIGITS`` are refused."""
    try:
        return json.loads(text, object_pairs_hook=_unique_keys, parse_int=_integer)
    except json.JSONDecodeError as e:
        at = f"line {e.lineno}, column {e.colno}" if "\n" in text.strip() else f"column {e.colno}"
        raise LineFollowerError(f"{where}: not JSON ({at}: {e.msg})") from None
    except RecursionError:
        raise LineFollowerError(f"{where}: JSON nested too deeply") from None
    except _DuplicateKey as e:
        raise LineFollowerError(f"{where}: key {str(e.args[0])[:80]!r} is given twice in one object") from None
    except _LongInteger as e:
        raise LineFollowerError(f"{where}: a whole number of {len(e.args[0].lstrip('-'))} digits; no value here has "
                                f"more than {MAX_INT_DIGITS}") from None


def read_json(path: str, limit: int, what: str):
    """A JSON document from a file of at most ``limit`` bytes."""
    return parse_json(read_text(path, limit, what), path)
