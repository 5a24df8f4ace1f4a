"""``python -m twin.run``: the front door to every command (see :mod:`twin.cli.main`).

Only the command line is imported here; Ctrl-C while it loads is a clean exit (:func:`twin.cli.guard.startup_failed`).
"""

import sys

from twin.cli.guard import startup_failed

try:
    from twin.cli.main import main
except (KeyboardInterrupt, ImportError) as e:
    sys.exit(startup_failed(e))

if __name__ == "__main__":
    sys.exit(main())
