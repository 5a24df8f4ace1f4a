"""The command line: the one layer that imports the libraries (``mjcf``, ``twin``, ``tuner``), never the reverse.

* :mod:`twin.cli.guard`: how every command ends (exit codes, one-line errors, interrupts).
* :mod:`twin.cli.output`: human text, or one JSON document on stdout.
* :mod:`twin.cli.options`: the flag vocabulary, written once, and the one way to build a twin from flags.
* one module per command (``lap``, ``tune``, ``align``, …), each with ``add_parser`` and ``run``.
* :mod:`twin.cli.main`: ``python -m twin.run``'s parser; ``tune`` and ``robot`` also serve
  ``python -m tuner`` and ``python -m mjcf``.
"""
