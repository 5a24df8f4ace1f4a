"""The live twin's state file: the aligned value and the alignments, written atomically as ``"generator"`` JSON,
read back after a restart. A file that is unreadable, of the wrong shape or not written by this program is set
aside (renamed ``<state>.corrupt-<time>``, never deleted) and rebuilt from the log.
"""

from __future__ import annotations

import logging
import os
import time

from lf_common.errors import LineFollowerError
from lf_common.files import GENERATOR, check_output_file, parse_json, read_text, write_json
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError

log = logging.getLogger(__name__)

STATE = "live state file"
STATE_LIMIT = 16 * 2**20  # [bytes]; a state of a thousand alignments is under 1 MB


class _Corrupt(Exception):
    """The state file cannot be what this program wrote."""


def read_state(path: str, twin: DigitalTwin) -> dict | None:
    """The state file's values and alignments; None if there is none, or after setting a corrupt one aside
    (renamed, never deleted) with a warning. A folder, link or device there, or a folder that cannot be
    written, is refused at once (:class:`OutputError`): it would fail at the first save."""
    check_output_file(path, lambda _: True, STATE)
    if not os.path.exists(path):
        return None
    try:
        return _parse_state(path, twin)
    except _Corrupt as e:
        aside = _set_aside(path)
        log.warning("%s: %s; set aside as %s, rebuilding the state from the log", path, e, aside)
        return None


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


def _set_aside(path: str) -> str:
    stem = f"{path}.corrupt-{time.strftime('%Y%m%dT%H%M%S')}"
    aside, n = stem, 1
    while os.path.lexists(aside):  # never over an earlier one
        aside, n = f"{stem}.{n}", n + 1
    os.rename(path, aside)
    return aside
