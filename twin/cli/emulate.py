"""``emulate``: a stand-in robot: a twin with hidden parameters driving lap after lap and streaming its wire
telemetry at real-time pace on a pseudo-terminal it creates, or on a 127.0.0.1 TCP port."""

from __future__ import annotations

import argparse
import os

from twin.cli import options as o
from twin.cli.output import Output
from twin.emulator import lap_records, open_pty, serve_tcp, stream

HELP = "a stand-in robot streaming wire telemetry on a pty or a TCP port"


def add_parser(sub) -> None:
    p = sub.add_parser("emulate", help=HELP, description=(
        "A twin with hidden parameters (--set) and its own noise seed drives lap after lap and streams its telemetry "
        "(twin.wire) at real-time pace (or --speed times faster) on a pseudo-terminal it creates (the path is printed) "
        "or on 127.0.0.1:--tcp PORT."))
    o.add_world(p)
    o.add_values(p, "a hidden model-space parameter, repeatable")
    o.add_seed(p, 7, "the robot's noise seed (lap k uses seed + k)")
    p.add_argument("--speed", type=o.number(0.01, 1000.0), default=1.0, metavar="X", help="faster than real time by this factor")
    p.add_argument("--every", type=o.number(1, 1000, integer=True), default=2, metavar="N", help="one sample line every N control ticks")
    p.add_argument("--laps", type=o.count_type, metavar="N", help="stop after this many laps (default: run until stopped)")
    p.add_argument("--tcp", type=o.number(0, 65535, integer=True), metavar="PORT",
                   help="serve on 127.0.0.1:PORT instead of a pty (0: any free port)")
    p.add_argument("--link", metavar="PATH", help="also make PATH a symlink to the pty, stable across restarts")
    p.add_argument("--echo", metavar="FILE", help="append every line sent to FILE")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    twin = o.twin_from_args(args)
    twin.model()
    echo_file = open(args.echo, "a", buffering=1) if args.echo else None
    echo = echo_file.write if echo_file else None
    lines = lap_records(twin, args.seed, args.every, args.laps)
    try:
        if args.tcp is not None:
            server = serve_tcp(args.tcp)
            url = f"socket://127.0.0.1:{server.getsockname()[1]}"
            out.document({"link": url})
            out.say(f"robot emulator on {url}")
            while True:
                conn, _ = server.accept()
                try:
                    stream(lines, conn.sendall, args.speed, echo)
                    return 0
                except OSError:
                    continue  # the reader went away: wait for the next one, carry on with the laps
                finally:
                    conn.close()
        master, slave, path = open_pty(args.link)
        out.document({"link": path})
        out.say(f"robot emulator on {path}")
        stream(lines, lambda b: os.write(master, b), args.speed, echo)
        return 0
    finally:
        if echo_file:
            echo_file.close()
