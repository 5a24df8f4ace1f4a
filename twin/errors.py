"""The exception the `twin` room raises for bad input."""

from lf_common.errors import LineFollowerError


class TwinError(LineFollowerError, ValueError):
    """Bad input to the model space or the twin; the message names the input and the fault."""
