"""Both ends of the serial link: the reader that logs every byte a robot sends and never waits forever
(:mod:`twin.link.reader`), and an emulated robot streaming wire telemetry on a pty or TCP port
(:mod:`twin.link.emulator`)."""

from twin.link.reader import DurableLog, LinkGaveUp, LinkStats, check_port, read_link

__all__ = ["DurableLog", "LinkGaveUp", "LinkStats", "check_port", "read_link"]
