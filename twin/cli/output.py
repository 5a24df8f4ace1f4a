"""Where a command's words go. With ``--json``: exactly one JSON document on stdout, and every human line,
progress bar and log record on stderr. Without: human lines on stdout."""

from __future__ import annotations

import json
import sys

from lf_common.files import json_safe


class Output:
    def __init__(self, json_mode: bool):
        self.json_mode = bool(json_mode)

    def say(self, text: str) -> None:
        """A human line: stdout, or stderr when stdout carries the JSON document."""
        print(text, file=sys.stderr if self.json_mode else sys.stdout, flush=True)

    def warn(self, text: str) -> None:
        """A warning line (``warning: …``): stderr always, so stdout keeps only the command's answer."""
        print(f"warning: {text}", file=sys.stderr, flush=True)

    def document(self, doc: dict) -> None:
        """The command's JSON document (only with ``--json``): NaN and infinities become null."""
        if self.json_mode:
            print(json.dumps(json_safe(doc), allow_nan=False, default=str), flush=True)
