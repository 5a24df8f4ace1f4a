"""The table-driven bad-case tests of outputs, the link and the firmware (``test_bad_outputs.py``,
``test_bad_link.py``, ``test_bad_firmware.py``): a row is a command line, the exit status it must end with, and
the words its one ``error: …`` line must hold. :func:`check_row` runs the row in this process and checks how it
ends: that status, no traceback, and for exit 2 exactly one ``error:`` line, the last one on stderr, rerun's or
anyone's lines included (captured at the file descriptor). Placeholders ``{name}`` are filled from a dict of paths.

Full file systems are small tmpfs mounts (:class:`SmallDisks`: ``{full}``, ``{free16k}``, …), made as root or with
passwordless sudo; rows that need one are skipped otherwise (a failure under CI: conftest.py)."""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shlex
import shutil
import socket
import subprocess
import threading
from typing import Iterable

import pytest

from twin.cli.main import main
from twin.telemetry.wire import Sample, encode

DISK_KB = 64  # [KB] each small file system
_DISK = re.compile(r"\{(full|free(\d+)k)\}")


def fill(text: str, places: dict[str, str]) -> str:
    return re.sub(r"\{([^}]+)\}", lambda m: places[m.group(1)], text)


def _digests(files: Iterable[str]) -> dict[str, str | None]:
    out = {}
    for f in files:
        try:
            with open(f, "rb") as h:
                out[f] = hashlib.sha256(h.read()).hexdigest()
        except OSError:
            out[f] = None
    return out


def check_row(capfd, places: dict[str, str], line: str, status: int, words: Iterable[str],
              owned: Iterable[str] = (), warnings: Iterable[str] = ()) -> str:
    """Run ``line`` (placeholders filled) and check how it ends; the files in ``owned`` (the user's) must be
    unchanged and nothing of theirs copied or moved aside; each of ``warnings`` must be in a ``warning: …`` line on
    stderr, and no warning may reach stdout. Returns stdout."""
    argv = [fill(a, places) for a in shlex.split(line)]
    owned = [fill(f, places) for f in owned]
    before = _digests(owned)
    capfd.readouterr()
    code = main(argv)
    out, err = capfd.readouterr()
    assert code == status, (line, code, err)
    assert "Traceback" not in err and "internal error" not in err, err
    lines = [x for x in err.splitlines() if x.strip()]
    errors = [x for x in lines if x.startswith("error: ")]
    if status == 2:
        assert len(errors) == 1 and lines[-1] == errors[0], f"the error must be the one last line: {lines[-6:]}"
        for w in words:
            assert fill(w, places) in errors[0], (w, errors[0])
    else:
        assert not errors, errors
    for w in warnings:
        assert any(x.startswith("warning: ") and fill(w, places) in x for x in lines), (w, lines[-6:])
    assert "warning:" not in out, f"a warning on stdout: {out[-500:]}"
    assert _digests(owned) == before, "a file the user owns was changed"
    for f in owned:
        folder = os.path.dirname(f)
        assert not [n for n in os.listdir(folder) if ".corrupt-" in n], "a file the user owns was set aside"
    return out


def _as_root() -> list[str] | None:
    """The prefix that runs a command as root: none as root, ``sudo -n`` where it needs no password, else None."""
    if os.geteuid() == 0:
        return []
    if shutil.which("sudo") and subprocess.run(["sudo", "-n", "true"], capture_output=True).returncode == 0:
        return ["sudo", "-n"]
    return None


class SmallDisks:
    """Small tmpfs file systems under ``root``, mounted on first use (as root, or with sudo) and filled to leave a given
    room: ``{full}`` none, ``{free16k}`` 16 KB."""

    def __init__(self, root: str):
        self.root, self.mounted = root, {}
        self.as_root: list[str] | None = None  # the mount command's prefix, found at the first mount (_as_root)

    def places(self, line: str) -> dict[str, str]:
        """The disks ``line`` names, mounted; skips the row where they cannot be."""
        out = {}
        for m in _DISK.finditer(line):
            out[m.group(1)] = self._mount(m.group(1), int(m.group(2) or 0))
        return out

    def _mount(self, name: str, free_kb: int) -> str:
        if name in self.mounted:
            return self.mounted[name]
        if self.as_root is None:
            self.as_root = _as_root()
        if self.as_root is None:
            pytest.skip("a full file system needs root or passwordless sudo (a tmpfs mount)")
        path = os.path.join(self.root, name)
        os.makedirs(path, exist_ok=True)
        r = subprocess.run([*self.as_root, "mount", "-t", "tmpfs", "-o", f"size={DISK_KB}k,mode=1777", "tmpfs", path],
                           capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
        self.mounted[name] = path
        with open(os.path.join(path, ".filler"), "wb") as f:
            with contextlib.suppress(OSError):
                f.write(b"\0" * ((DISK_KB - free_kb) * 1024))
        return path

    def close(self) -> None:
        for path in self.mounted.values():
            subprocess.run([*(self.as_root or []), "umount", "-l", path], capture_output=True)
        self.mounted.clear()


@pytest.fixture(scope="module")
def disks(tmp_path_factory):
    d = SmallDisks(str(tmp_path_factory.mktemp("disks")))
    yield d
    d.close()


@pytest.fixture(scope="module")
def talker():
    """A TCP 'robot' on 127.0.0.1 that sends about 100 KB of wire samples to each connection, then holds it open
    for 30 s; yields its port."""
    lines = b"".join(encode(Sample(0.01 * i, 3500, 1, 40.0, 40.0)).encode() for i in range(3000))
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)

    def serve(conn):
        with conn, contextlib.suppress(OSError):
            conn.sendall(lines)
            conn.recv(1)  # until the reader hangs up (or 30 s)

    def run():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            conn.settimeout(30)
            threading.Thread(target=serve, args=(conn,), daemon=True).start()

    threading.Thread(target=run, daemon=True).start()
    yield server.getsockname()[1]
    server.close()
