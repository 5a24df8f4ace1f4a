"""The command line: the one layer that imports the libraries (``mjcf``, ``twin``, ``tuner``), never the reverse.

* :mod:`twin.cli.guard`: how every command ends (exit codes, one-line errors, interrupts).
* :mod:`twin.cli.output`: human text, or one JSON document on stdout.
* :mod:`twin.cli.options`: the flag vocabulary, written once; :mod:`twin.cli.library_values`: the libraries' values
  its help and choices quote, copied so that building the parsers loads no library.
* :mod:`twin.cli.twin_options`: the one way to build a twin (and the program it runs) from flags.
* :mod:`twin.cli.startup`: Ctrl-C while modules load; a command loads the libraries in its ``with loading():``
  blocks as it starts its work, so ``--help`` and a refused flag take an instant.
* one module per command (``lap``, ``tune``, ``align``, …), each with ``add_parser`` and ``run``.
* :mod:`twin.cli.main`: ``python -m twin.run``'s parser; ``tune`` and ``robot`` also serve
  ``python -m tuner`` and ``python -m mjcf``.
"""
