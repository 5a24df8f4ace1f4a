"""How every command ends: exit codes, one-line errors on stderr, logging on stderr, clean interrupts.

Exit codes: 0 done; 1 done, but the answer is negative (e.g. no parameter value explains a measurement,
a live link that never opened); 2 bad input or an output that cannot be written (one ``error: …`` line);
130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import sys
from typing import Callable

from lf_common.errors import LineFollowerError

EXIT_OK, EXIT_NEGATIVE, EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 130, 143

log = logging.getLogger("twin.cli")


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that ``finally`` blocks (worker pools, logs) run."""


def _on_sigterm(signum, frame):
    raise Terminated()


def configure_logging(verbose: bool) -> None:
    logging.basicConfig(stream=sys.stderr, level=logging.INFO if verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s", force=True)


def fail(message: str) -> int:
    """Print ``error: message`` as one line on stderr; returns the bad-input exit code."""
    print("error: " + " ".join(str(message).split()), file=sys.stderr, flush=True)
    return EXIT_BAD_INPUT


def _os_message(e: OSError) -> str:
    what = e.filename if e.filename is not None else ""
    return f"{what}: {e.strerror or e}" if what else str(e.strerror or e)


def run_command(command: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a command; every error becomes one ``error: …`` line and an exit code, never a traceback."""
    configure_logging(getattr(args, "verbose", False))
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return command(args)
    except LineFollowerError as e:
        return fail(e)
    except BrokenPipeError:  # the reader of stdout went away (e.g. | head): nothing left to say to it
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except OSError as e:  # a file or device the library did not wrap: name it
        return fail(_os_message(e))
    except UnicodeError as e:
        return fail(f"text that is not valid UTF-8/ASCII ({e})")
    except MemoryError:
        return fail("out of memory: the input is too large for this machine")
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        print("terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except Exception as e:  # a bug, not the input: still one line; -v shows the traceback
        log.info("traceback of the internal error", exc_info=True)
        return fail(f"internal error, please report it ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}); "
                    "-v shows the traceback")
    finally:
        signal.signal(signal.SIGTERM, previous)
