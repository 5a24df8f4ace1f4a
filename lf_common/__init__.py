"""What every room shares and nothing else provides: the one error root (:mod:`lf_common.errors`) and the
rules for writing outputs without losing the user's files and reading inputs within limits
(:mod:`lf_common.files`). It imports nothing of the project, so the lowest rooms (``motors``,
``line_sensor``) can use it too."""

from lf_common.errors import InputTooLarge, LineFollowerError, OutputError

VERSION = "0.1.0"  # the package's version (pyproject.toml reads it from here)

__all__ = ["InputTooLarge", "LineFollowerError", "OutputError", "VERSION"]
