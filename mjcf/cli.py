"""What every command-line entry point shares: one-line errors with exit status 2, logging set-up,
and ``ADDRESS=VALUE`` parsing."""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Callable, Sequence

from lf_common.errors import LineFollowerError
from mjcf.errors import MjcfError

USER_ERRORS: tuple[type[BaseException], ...] = (LineFollowerError,)
EXIT_BAD_INPUT = 2


def run_guarded(
    main: Callable[[argparse.Namespace], int],
    args: argparse.Namespace,
    errors: tuple[type[BaseException], ...] = (),
) -> int:
    """Run a command; bad input becomes ``error: <message>`` on stderr and exit status 2, no traceback."""
    logging.basicConfig(
        level=logging.INFO if getattr(args, "verbose", False) else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return main(args)
    except USER_ERRORS + errors as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def parse_assignments(items: Sequence[str] | None) -> dict[str, float | str]:
    """``["motion.mu=0.6", ...]`` → {"motion.mu": "0.6"}; values are checked by the model space."""
    out: dict[str, float | str] = {}
    for item in items or ():
        address, sep, value = item.partition("=")
        if not sep or not address.strip() or not value.strip():
            raise MjcfError(f"--set {item!r}: expected ADDRESS=VALUE, e.g. motion.mu=0.6")
        out[address.strip()] = value.strip()
    return out
