"""``python -m mjcf``: generate the default robot's URDF, or convert any diff-drive URDF (see :mod:`twin.cli.robot`)."""

import sys

from twin.cli.startup import loading

with loading():  # Ctrl-C while the libraries load: exit 130 at once, no traceback
    from twin.cli.robot import main

if __name__ == "__main__":
    sys.exit(main())
