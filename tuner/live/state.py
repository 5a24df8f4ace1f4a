"""The live twin's state file: the aligned value and the alignments, written atomically as JSON that opens with
this program's state header, read back after a restart.

Only a state file is ever touched. A file there that does not carry the state header (a user's file, anything
unreadable) is refused, left as it is (:class:`OutputError`, one line). A file that carries the header but is
damaged (truncated, wrong shape, values out of range) is copied aside as ``<state>.corrupt-<time>``, never moved
or deleted, and the state is rebuilt from the log; the next save replaces it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import time

from lf_common.errors import LineFollowerError, OutputError
from lf_common.files import GENERATOR, check_output_file, parse_json, read_text, write_json
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError

log = logging.getLogger(__name__)

STATE = "live state file"
STATE_KIND = "live state"
STATE_LIMIT = 16 * 2**20  # [bytes]; a state of a thousand alignments is under 1 MB
# how every state file this program writes begins (write_json: "generator" first, then "kind"); found even in a
# file cut short after it
_HEADER = f'{{\n  "generator": "{GENERATOR}",\n  "kind": "{STATE_KIND}"'.encode()


class _Corrupt(Exception):
    """A state file of ours that cannot be used."""


def state_is_ours(path: str) -> bool:
    """The file carries the state header: one this program wrote as a live state (whole or damaged), or a whole
    state written before the header had its ``kind`` (generator, values and alignments)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(_HEADER))
            if head == _HEADER:
                return True
            doc = parse_json((head + f.read(STATE_LIMIT)).decode("utf-8"), path)
    except (OSError, UnicodeDecodeError, LineFollowerError):
        return False
    return isinstance(doc, dict) and doc.get("generator") == GENERATOR and {"values", "alignments"} <= doc.keys()


def check_state(path: str) -> str:
    """The state file can be read and replaced: none yet, or one of ours. Anything else is refused untouched."""
    if os.path.isfile(path) and not os.access(path, os.R_OK):
        raise OutputError(f"{path}: cannot read the {STATE} (permission denied); it is left as it is")
    if os.path.isfile(path) and not os.path.islink(path) and not state_is_ours(path):
        raise OutputError(f"{path}: exists and is not a {STATE} (it was not written by {GENERATOR} as one); it is "
                          "left as it is: choose another --state or move it away")
    return check_output_file(path, state_is_ours, STATE)


def read_state(path: str, twin: DigitalTwin) -> dict | None:
    """The state file's values and alignments; None if there is none, or after copying a damaged one of ours
    aside with a warning. A file that is not ours is refused (:class:`OutputError`) and left untouched."""
    check_state(path)
    if not os.path.exists(path):
        return None
    try:
        return _parse_state(path, twin)
    except _Corrupt as e:
        aside = _copy_aside(path)
        log.warning("%s: %s; a copy is set aside as %s, rebuilding the state from the log", path, e, aside)
        return None


def write_state(path: str, values: dict, alignments: list) -> str:
    """The state, atomically; replaces only a state file of ours (a damaged one included)."""
    return write_json(path, {"kind": STATE_KIND, "values": values, "alignments": alignments}, STATE, state_is_ours)


def _parse_state(path: str, twin: DigitalTwin) -> dict:
    try:
        state = parse_json(read_text(path, STATE_LIMIT, STATE), path)
    except LineFollowerError as e:
        raise _Corrupt(str(e).removeprefix(f"{path}: ")) from None
    if not isinstance(state, dict) or state.get("generator") != GENERATOR:
        raise _Corrupt(f"not a state file written by {GENERATOR}")
    values, alignments = state.get("values"), state.get("alignments")
    if not (isinstance(values, dict) and isinstance(alignments, list) and all(isinstance(a, dict) for a in alignments)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values.values())):
        raise _Corrupt('wrong shape (expected "values": {address: number}, "alignments": [{…}])')
    try:
        twin.checked_values(values)  # known addresses, finite, within range
    except TwinError as e:
        raise _Corrupt(str(e)) from None
    return {"values": values, "alignments": alignments}


def _copy_aside(path: str) -> str:
    """A copy of the damaged state under a new name (never over an earlier one); the original stays."""
    stem = f"{path}.corrupt-{time.strftime('%Y%m%dT%H%M%S')}"
    aside, n = stem, 1
    while True:
        try:
            with open(path, "rb") as src, open(aside, "xb") as dst:
                shutil.copyfileobj(src, dst)
                os.fsync(dst.fileno())
            return aside
        except FileExistsError:
            aside, n = f"{stem}.{n}", n + 1
        except OSError as e:
            with contextlib.suppress(OSError):
                os.unlink(aside)  # the partial copy (this name was free: nothing else was there)
            raise OutputError(f"{aside}: cannot copy the damaged {STATE} aside ({e.strerror or e}); {path} is left "
                              "as it is") from None
