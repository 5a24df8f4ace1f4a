"""Both ends of the serial link: the reader that logs every byte a robot sends and never waits forever
(:mod:`twin.link.reader`), the log it keeps, byte for byte, with where each stream ended beside it
(:mod:`twin.link.telemetry_log`), and an emulated robot streaming wire telemetry on a pty or TCP port
(:mod:`twin.link.emulator`)."""

from twin.link.reader import LinkGaveUp, LinkStats, check_port, read_link
from twin.link.telemetry_log import DurableLog, LogWriteError, breaks_path, log_lines, read_breaks

__all__ = ["DurableLog", "LinkGaveUp", "LinkStats", "LogWriteError", "breaks_path", "check_port", "log_lines",
           "read_breaks", "read_link"]
