"""The one home of reference gains: what ``tune`` answers today, tuned when asked (``tuned_gains``), never a copy.

The tests' session fixtures ``plain_gains`` and ``robust_gains`` (conftest.py) and the benchmarks that need tuned or
robust gains (``sys.path`` to this folder, as ``bench_fmu.py`` does for fmu_helpers) all call it, so no gain set held
in a file can drift away from the tuner's current answer. Not a test module."""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile

from twin.cli.main import main


def tuned_gains(*flags: str) -> dict[str, float]:
    """The gains ``python -m tuner -q FLAGS`` writes (default robot and track unless ``flags`` say otherwise; e.g.
    ``"--robust"``, ``"--track", "oval"``, ``"--max-iter", "1"``), by address."""
    with tempfile.TemporaryDirectory(prefix="tuned-") as folder:
        path = os.path.join(folder, "gains.json")
        with contextlib.redirect_stdout(sys.stderr):  # its summary: a caller's stdout may be one JSON document
            status = main(["tune", "-q", "-o", path, *flags])
        if status != 0:
            raise RuntimeError(f"tune {' '.join(flags)} exited {status}")
        with open(path) as f:
            return json.load(f)["gains"]


def set_flags(gains: dict[str, float]) -> list[str]:
    """``gains`` as the ``--set ADDRESS=VALUE`` flags of a command, at full precision."""
    return [w for a, v in gains.items() for w in ("--set", f"{a}={v!r}")]
