"""Files that are appended to as things happen (the telemetry log's break index, the live twin's journal): each is
created whole, its header in one step, and a line torn by a crash or a full disk is found before the next is
added. (Written outputs are :mod:`lf_common.files`'s: replaced whole, atomically.)"""

from __future__ import annotations

import contextlib
import os
import uuid


def create_whole(path: str, head: bytes) -> bool:
    """Create ``path`` holding ``head`` in one step, unless something is already there (left as it is): written
    under a temporary name in its folder, fsynced and hard-linked into place, so a full disk or a crash leaves no
    file or the whole of ``head``, never an empty file that the next run would take for a stranger's. True if this
    call created it.

    Raises:
      OSError: the temporary file cannot be written (a full disk); nothing is left behind.
    """
    folder, name = os.path.split(os.path.abspath(path))
    tmp = os.path.join(folder, f".{name}.{uuid.uuid4().hex}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # (the umask applies, as to any new file)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(head)
            f.flush()
            os.fsync(f.fileno())
        try:
            os.link(tmp, path)  # fails on an existing file: nothing is ever replaced
        except FileExistsError:
            return False
        return True
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def ends_with_newline(path: str) -> bool:
    """Whether the file is empty or its last byte is a newline (an appended log or journal was not torn)."""
    with open(path, "rb") as f:
        if f.seek(0, os.SEEK_END) == 0:
            return True
        f.seek(-1, os.SEEK_END)
        return f.read(1) == b"\n"
