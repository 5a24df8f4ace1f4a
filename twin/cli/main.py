"""``python -m twin.run``: the front door to every command of the twin. ``python -m twin.run COMMAND --help``
shows each command's options and their defaults; docs/cli.md's "Flags" table says what each flag means."""

from __future__ import annotations

from twin.cli import (align, build, design, diagnose, emulate, firmware, fmu, graph, history, lap, live, record, robot, sweep,
                      tune, view)
from twin.cli import options as o
from twin.cli.guard import run_command
from twin.cli.startup import loading


def parser() -> o.Parser:
    p = o.Parser(prog="python -m twin.run", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in (lap, tune, align, diagnose, sweep, design, record, emulate, live, history, view, build, firmware, fmu,
                    graph):
        command.add_parser(sub)
    robot.add_generate(sub)
    robot.add_convert(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    with loading():  # Ctrl-C while the parsers are built or the flags checked: exit 130 at once, no traceback
        args = parser().parse_or_exit_code(argv)
    if isinstance(args, int):
        return args
    return run_command(args.run, args)
