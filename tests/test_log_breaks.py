"""The telemetry log holds the bytes received and no others: a drop in the middle of a line, a stop, a crash add
nothing to it (they added a newline that never came); where each stream ended is kept beside it, in the break
index, and reading the log back (replay, resume) ends a cut line there instead of gluing it to the next."""

from __future__ import annotations

import contextlib
import json
import socket
import threading

import pytest

from twin.cli.main import main
from twin.link import DurableLog, breaks_path, log_lines, read_breaks
from twin.telemetry.wire import Header, Sample, encode

GOOD = [encode(Sample(0.01 * i, 3500, 1, 40.0, 40.0)).encode() for i in range(3)]
HEADER = encode(Header(8, 0.005, 2)).encode()


def robot(connections: list[bytes], hold_s: float = 30.0) -> int:
    """A TCP robot: each connection in turn gets its bytes, then is hung up (the last one held ``hold_s``)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    server.settimeout(30)

    def run():
        with server:
            for i, data in enumerate(connections):
                conn, _ = server.accept()
                with conn:
                    conn.sendall(data)
                    if i == len(connections) - 1:
                        conn.settimeout(hold_s)
                        with contextlib.suppress(OSError):
                            conn.recv(1)  # until live hangs up, or hold_s

    threading.Thread(target=run, daemon=True).start()
    return server.getsockname()[1]


def test_the_log_is_the_bytes_received_across_a_drop_and_a_stop(tmp_path, capsys):
    first = GOOD[0] + GOOD[1][:12]  # dropped in the middle of a line
    second = HEADER + GOOD[2] + GOOD[0][:9]  # stopped in the middle of a line
    port = robot([first, second])
    log = tmp_path / "live.log"
    capsys.readouterr()
    assert main(["live", "--track", "oval", "--port", f"socket://127.0.0.1:{port}", "--log", str(log),
                 "--duration", "2", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert log.read_bytes() == first + second  # those bytes and no others
    assert read_breaks(str(log)) == [len(first), len(first + second)]
    assert summary["lines"] == 5 and summary["corrupted"] == 2 and summary["reconnects"] >= 1
    # read back: the cut line is not glued to the header that followed it
    assert list(log_lines(str(log))) == [GOOD[0], None, HEADER, GOOD[2], None]
    assert main(["live", "--track", "oval", "--replay", str(log), "--json"]) == 0
    replayed = json.loads(capsys.readouterr().out)
    assert (replayed["lines"], replayed["corrupted"]) == (5, 2)


def test_a_crash_in_the_middle_of_a_line_is_marked_not_mended(tmp_path):
    log = tmp_path / "live.log"
    log.write_bytes(GOOD[0] + b"$LFS,12,35")  # the process died mid-line, before it could mark the end
    held = DurableLog(str(log))
    try:
        assert log.read_bytes() == GOOD[0] + b"$LFS,12,35"  # nothing added to the log
        assert read_breaks(str(log)) == [len(GOOD[0]) + 10]
        held.write(GOOD[1])  # the next run's first line
    finally:
        held.close()
    assert list(log_lines(str(log))) == [GOOD[0], None, GOOD[1]]
    again = DurableLog(str(log))  # a restart after a clean end adds no mark
    again.close()
    assert read_breaks(str(log)) == [len(GOOD[0]) + 10]


def test_log_lines_cut_at_every_mark_however_the_log_is_read(tmp_path):
    log = tmp_path / "l.log"
    junk = b"x" * 200_000  # longer than any wire line, across chunks, cut by a drop
    parts = [GOOD[0] + GOOD[1][:5], junk, GOOD[2] + GOOD[0], b"$LF"]
    held = DurableLog(str(log))
    for p in parts:
        held.write(p)
        held.end_stream("dropped: test")
    held.end_stream("stopped")  # nothing new: no second mark at the same place
    held.close()
    assert read_breaks(str(log)) == [sum(map(len, parts[:i + 1])) for i in range(len(parts))]
    assert list(log_lines(str(log))) == [GOOD[0], None, None, GOOD[2], GOOD[0], None]


def test_a_break_index_the_user_owns_is_refused_untouched(tmp_path):
    log = tmp_path / "live.log"
    index = tmp_path / "live.log.breaks"
    index.write_text("my notes\n")
    with pytest.raises(Exception, match="was not written by") as e:
        DurableLog(str(log))
    assert str(index) in str(e.value) and index.read_text() == "my notes\n" and breaks_path(str(log)) == str(index)
