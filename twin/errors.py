"""The exception the `twin` room raises for bad input."""


class TwinError(ValueError):
    """Bad input to the model space or the twin; the message names the input and the fault."""
