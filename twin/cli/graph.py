"""``graph``: the common model space: models, ports, parameters (value, unit, change cost) and relations."""

from __future__ import annotations

import argparse

from twin.cli import options as o
from twin.cli.output import Output
from twin.model.partial_models import default_space

HELP = "print the common model space: models, ports, parameters and relations"


def add_parser(sub) -> None:
    p = sub.add_parser("graph", help=HELP, description=HELP + " (paper §2, §3.8).")
    p.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="show with a parameter changed, repeatable")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    space = default_space()
    space.update(o.parse_assignments(args.set))
    out.document(space.to_dict())
    if not args.json:
        out.say(space.describe())
    return 0
