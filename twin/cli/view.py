"""``view``: open saved rerun recordings in the viewer."""

from __future__ import annotations

import argparse
import os

from twin.cli import options as o
from twin.cli.output import Output
from twin.cli.startup import loading

HELP = "open saved rerun recordings (.rrd) in the rerun viewer"


def add_parser(sub) -> None:
    p = sub.add_parser("view", help=HELP, description=HELP + ". Needs a display; without one, serve a recording "
                       "to a browser with: rerun --serve-web FILE.rrd")
    p.add_argument("recordings", nargs="+", metavar="FILE.rrd")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    with loading():
        from twin.viz import viewer

    out = Output(args.json)
    exe = viewer.open_files(args.recordings)
    out.document({"opened": [os.path.abspath(p) for p in args.recordings], "viewer": exe})
    out.say(f"opened {len(args.recordings)} recording(s) in {exe}")
    return 0
