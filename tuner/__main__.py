"""``python -m tuner``: tune the gains (see :mod:`twin.cli.tune`)."""

import sys

from twin.cli.startup import loading

with loading():  # Ctrl-C while the libraries load: exit 130 at once, no traceback
    from twin.cli.tune import main

if __name__ == "__main__":
    sys.exit(main())
