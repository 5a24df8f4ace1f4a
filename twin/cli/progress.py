"""Progress of a command's long phases: one tqdm bar on stderr, silent under ``-q`` and ``--json`` (stdout then
carries one JSON document and stderr only what went wrong), off when stderr is not a terminal (tqdm's own rule).

A bar counts what its phase knows it will do, and when the phase ends sooner (a search that converged before its
iteration cap) :func:`finish` sets its total to what was done, so it ends full: at its real end.
"""

from __future__ import annotations

import argparse
import sys

from twin.cli.startup import loading


def silent(args: argparse.Namespace) -> bool:
    """-q or --json: no bar."""
    return bool(getattr(args, "quiet", False) or getattr(args, "json", False))


def bar(args: argparse.Namespace, total: int | None, desc: str, unit: str):
    """A tqdm bar on stderr for the phase, or a disabled one (every call a no-op) under -q and --json."""
    with loading():
        from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, disable=True if silent(args) else None)


def finish(b) -> None:
    """The phase has ended: its bar ends full at what was done, then closes."""
    if not b.disable and b.total != b.n:
        b.total = b.n
        b.refresh()
    b.close()


def planned_steps(b, steps: int) -> None:
    """``steps`` more the phase now knows it will do."""
    if not b.disable:
        b.total = (b.total or 0) + steps
        b.refresh()


class Phases:
    """``(done, planned)`` callbacks of a phase that runs now and then (each re-tune of ``live --act``) as one bar
    per run: opened at its first step, closed full when done reaches planned."""

    def __init__(self, args: argparse.Namespace, desc: str, unit: str):
        self.args, self.desc, self.unit, self.bar = args, desc, unit, None

    def __call__(self, done: int, planned: int) -> None:
        if self.bar is None:
            self.bar = bar(self.args, planned, self.desc, self.unit)
        self.bar.total = planned
        self.bar.update(done - self.bar.n)
        if done >= planned:
            finish(self.bar)
            self.bar = None
