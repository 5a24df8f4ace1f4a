"""The one exception the `mjcf` room raises for bad input."""


class MjcfError(ValueError):
    """Bad input to the CAD, track or URDF → MJCF models; the message names the input and the fault."""
