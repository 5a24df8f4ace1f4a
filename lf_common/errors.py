"""The one root of every error the project raises on purpose.

Each room has its own subclass (``MjcfError``, ``MotorError``, ``SensorError``, ``TwinError``, ``TunerError``);
all derive from :class:`LineFollowerError`, so the command line catches one class. A message is one line that
names the input (a file, a flag, a parameter address) and says what is wrong with it.
"""


class LineFollowerError(Exception):
    """Bad input, or an action refused to keep the user's data safe; the message names the input."""


class OutputError(LineFollowerError):
    """An output cannot be written where asked: missing or read-only folder, wrong kind of path, or a file or
    folder there that this program did not write (and so will not replace)."""


class InputTooLarge(LineFollowerError):
    """An input above a documented size limit; the message says the limit and how to get under it."""
