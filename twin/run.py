"""``python -m twin.run``: the front door to every command (see :mod:`twin.cli.main`)."""

import sys

from twin.cli.startup import loading

with loading():  # Ctrl-C while the libraries load: exit 130 at once, no traceback
    from twin.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
