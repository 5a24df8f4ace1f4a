"""``python -m tuner``: tune the gains (see :mod:`twin.cli.tune`).

Only the command line is imported here; Ctrl-C while it loads is a clean exit (:func:`twin.cli.guard.startup_failed`).
"""

import sys

from twin.cli.guard import startup_failed

try:
    from twin.cli.tune import main
except (KeyboardInterrupt, ImportError) as e:
    sys.exit(startup_failed(e))

if __name__ == "__main__":
    sys.exit(main())
