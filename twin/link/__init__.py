"""Both ends of the serial link: the reader that logs every byte a robot sends and never waits forever
(:mod:`twin.link.reader`), the log it keeps, byte for byte, with where each stream ended beside it
(:mod:`twin.link.telemetry_log`), the commands queued for the robot (:class:`Outbox`), and an emulated robot
streaming wire telemetry on a pty or TCP port (:mod:`twin.link.emulator`) and answering commands at its end
(:mod:`twin.link.robot_end`)."""

from twin.link.reader import LinkGaveUp, LinkStats, Outbox, check_port, read_link
from twin.link.telemetry_log import (DurableLog, LogWriteError, breaks_path, check_log, log_is_ours, log_lines,
                                     read_breaks, unlocked_for_reading)

__all__ = ["DurableLog", "LinkGaveUp", "LinkStats", "LogWriteError", "Outbox", "breaks_path", "check_log", "check_port",
           "log_is_ours", "log_lines", "read_breaks", "read_link", "unlocked_for_reading"]
