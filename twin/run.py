"""``python -m twin.run``: the twin's command line.

  python -m twin.run graph [--json] [--set ADDRESS=VALUE]   models, ports, parameters and relations
"""

from __future__ import annotations

import argparse
import json
import sys

from mjcf.cli import parse_assignments, run_guarded
from twin.errors import TwinError
from twin.models import default_space


def cmd_graph(args: argparse.Namespace) -> int:
    space = default_space()
    space.update(parse_assignments(args.set))
    if args.json:
        print(json.dumps(space.to_dict(), indent=None if args.compact else 2))
    else:
        print(space.describe())
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m twin.run", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    g = sub.add_parser("graph", help="print the common model space: models, ports, parameters, relations")
    g.add_argument("--json", action="store_true", help="export as JSON")
    g.add_argument("--compact", action="store_true", help="with --json: one line")
    g.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="show with a parameter changed, repeatable")
    g.add_argument("-v", "--verbose", action="store_true")
    g.set_defaults(func=cmd_graph)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    return run_guarded(args.func, args, errors=(TwinError,))


if __name__ == "__main__":
    sys.exit(main())
