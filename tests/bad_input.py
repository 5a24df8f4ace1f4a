"""What every table of bad inputs shares (one test module per command family: descriptions, tracks, value files,
firmware, outputs, link, …): a folder of bad files made on demand, and the check every bad input must pass.

A row is ``(command line with {name} placeholders, text the error line must contain)``; :func:`check_bad_input`
runs it in this process and asserts: exit status 2, exactly one ``error: …`` line on stderr (warnings aside), no
traceback, the line names the input (one of the row's files, flags or values) and holds the text, all within a time
limit (a command that blocks, e.g. on a FIFO, fails the test instead of hanging it).
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys

from twin.cli.main import main

LIMIT_S = 60.0  # wall time a bad input may take to be refused; a lap never starts on one
_PLACEHOLDER = re.compile(r"\{([^}]+)\}")


class BadFiles:
    """Bad inputs in one folder, by name: ``put`` writes one, ``fifo`` makes a named pipe; ``{dir}`` is the folder
    and ``{missing_dir}`` a folder that does not exist. ``fill`` replaces ``{name}`` placeholders by paths."""

    def __init__(self, folder):
        self.folder = folder
        self.paths = {"dir": str(folder), "missing_dir": str(folder / "no" / "such")}

    def put(self, name: str, data: bytes | str) -> str:
        path = self.folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data if isinstance(data, bytes) else data.encode())
        self.paths[name] = str(path)
        return str(path)

    def fifo(self, name: str) -> str:
        """A named pipe nobody writes to: a reader that opens it blocks for ever."""
        path = self.folder / name
        os.mkfifo(path)
        self.paths[name] = str(path)
        return str(path)

    def __getitem__(self, name: str) -> str:
        return self.paths[name]

    def fill(self, text: str) -> str:
        return _PLACEHOLDER.sub(lambda m: self.paths[m.group(1)], text)


class Hung(BaseException):
    """The command ran past its limit (a BaseException: the CLI's own error handling must not swallow it)."""


@contextlib.contextmanager
def time_limit(seconds: float):
    """Raise :class:`Hung` in the main thread after ``seconds``; a blocking ``open`` or ``read`` is interrupted."""
    def expire(signum, frame):
        raise Hung(f"no answer within {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def check_bad_input(row: str, needle: str, files: BadFiles, capsys, limit_s: float = LIMIT_S) -> str:
    """Run ``python -m twin.run ROW`` in this process and check it as a bad input; returns the error line."""
    args = [files.fill(a) for a in row.split()]
    with time_limit(limit_s):
        code = main(args)
    err = capsys.readouterr().err
    lines = [e for e in err.strip().splitlines() if not e.startswith(("warning: ", "WARNING "))]
    assert code == 2, (code, err)
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err, err
    # the input: a file, a flag, a value or an address in one (control.kp of --set control.kp=nan), or the command
    named = [files[m] for m in _PLACEHOLDER.findall(row)] + args + [p for a in args for p in re.split(r"[=,:]", a) if p]
    assert any(n in lines[0] for n in named), f"the error names none of {named}: {lines[0]}"
    assert files.fill(needle) in lines[0], lines[0]
    return lines[0]


def check_in_fresh_process(args: list[str], limit_s: float = LIMIT_S) -> str:
    """The same in a new ``python -m twin.run`` process (nothing imported or configured beforehand); returns stderr."""
    r = subprocess.run([sys.executable, "-m", "twin.run", *args], capture_output=True, text=True, timeout=limit_s)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: "), r.stderr
    return r.stderr
