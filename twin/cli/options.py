"""The flag vocabulary, written once: the same word means the same thing in every command (docs/cli.md's
"Flags" table lists every flag; a test checks it against ``--help``). Old spellings keep working for one
release, hidden from ``--help``, with a deprecation warning on stderr.

Building the parsers and parsing flag text load no library, so ``--help`` and a refused flag take an instant (the
twin the flags describe is built by :mod:`twin.cli.twin_options`).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from typing import Sequence

from twin.cli.guard import fail
from twin.cli.library_values import MOTOR_MODEL, ROBOT_NAMES
from twin.cli.startup import loading
from twin.errors import TwinError

MAX_SEED = 2**64 - 1


class Formatter(argparse.RawDescriptionHelpFormatter):
    """Help that shows each option's default (where it has one) and keeps the descriptions' line breaks."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if default is not None and default is not False and default != argparse.SUPPRESS and action.option_strings:
            text += " (default: %(default)s)"
        return text


def plain_text(text: str) -> str:
    """reST inline markup as a terminal should show it: ``:mod:`x```, ``:func:`~a.x``` → x; double back-quotes
    and ``**`` dropped."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"\1", text)
    return text.replace("``", "").replace("**", "")


class Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (``error: …``, exit 2) and defaults shown in ``--help``."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", Formatter)
        if kwargs.get("description"):  # module docstrings serve as descriptions: a terminal shows no reST
            kwargs["description"] = plain_text(kwargs["description"])
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        sys.exit(fail(f"{self.prog}: {message} (see --help)"))

    def parse_or_exit_code(self, argv: list[str] | None) -> argparse.Namespace | int:
        """Parsed options, or the exit code argparse chose (``--help`` → 0, a usage error → 2) for callers
        that want a return value rather than ``SystemExit``."""
        try:
            return self.parse_args(argv)
        except SystemExit as e:
            return e.code if isinstance(e.code, int) else 2


def deprecated(action: type[argparse.Action], new: str) -> type[argparse.Action]:
    """An action that does what ``action`` does and warns that its spelling gives way to ``new``."""

    class Deprecated(action):
        def __call__(self, parser, namespace, values, option_string=None):
            print(f"warning: {option_string} is deprecated, use {new} (the old spelling works for this release)",
                  file=sys.stderr)
            super().__call__(parser, namespace, values, option_string)

    return Deprecated


# --- value types: each refuses what makes no sense with a one-line usage error --------------------------

def bound(x: float) -> str:  # a range's end: a whole number in full (1048576, not 1.04858e+06), else 12 digits
    return str(int(x)) if math.isfinite(x) and float(x).is_integer() and abs(x) < 1e21 else f"{x:.12g}"


def number(lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False, integer: bool = False):
    """An argparse type: a finite number in [lo, hi] (or (lo, hi] with ``lo_open``)."""

    def parse(text: str):
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'a whole number' if integer else 'a number'}") from None
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
            left = "(" if lo_open else "["
            raise argparse.ArgumentTypeError(f"{text!r} is outside {left}{bound(lo)}, {bound(hi)}]")
        return v

    return parse


seed_type = number(0, MAX_SEED, integer=True)
positive = number(0.0, lo_open=True)
count_type = number(1, 10**9, integer=True)


# --- option groups -------------------------------------------------------------------------------------

def add_world(p: argparse.ArgumentParser, track_default: str | None = "default", robot: bool = True) -> None:
    """--track, --metres-per-pixel, --robot: the robot and the floor it runs on."""
    p.add_argument("--track", default=track_default, metavar="NAME|PNG",
                   help="built-in track (default, oval, circle, chicane; maze: a line maze for a maze-solving 3pi "
                   "program) or an image of a dark closed line")
    p.add_argument("--metres-per-pixel", type=number(0.0, 0.1, lo_open=True), metavar="M",
                   help="scale of an image track without DPI metadata [m]")
    if robot:
        p.add_argument("--robot", metavar="URDF|XACRO|NAME", help="a differential-drive robot description (.urdf, "
                       f".xacro, .urdf.xacro) instead of the generated robot, or a named robot ({', '.join(ROBOT_NAMES)}: "
                       "Pololu's original 3pi)")
        p.add_argument("--motor", metavar="NAME", help="both drive motors from the motor catalogue (default: the "
                       "generated robot's; for a --robot, the catalogue motor that fits its mass and wheels, else one "
                       "sized for it)")
        add_description(p)


def add_description(p: argparse.ArgumentParser) -> None:
    """How to read a robot description and find its parts: wheels, caster, line-sensor mount, packages, xacro."""
    p.add_argument("--xacro-arg", action="append", metavar="NAME=VALUE", help="an argument of a xacro description, repeatable")
    p.add_argument("--package", action="append", metavar="NAME=DIR", help="where package://NAME (and $(find NAME)) "
                   "lives, repeatable (default: ROS_PACKAGE_PATH, AMENT_PREFIX_PATH, then searched around the "
                   "description)")
    p.add_argument("--wheel-joints", metavar="LEFT,RIGHT", help="the drive wheels' joints; fixed hub joints become "
                   "wheels (default: named by a diff-drive plugin, else the two continuous joints across the robot)")
    p.add_argument("--caster", metavar="NAME", help="the caster's link or collision (default: names containing 'caster')")
    p.add_argument("--sensor-link", metavar="LINK", help="the link the line array mounts on, at its origin "
                   "(default: a link named *sensor*)")
    p.add_argument("--sensor-mount", metavar="LINK:X,Y,Z", help="the line array's centre in LINK's frame [m]")


def add_values(p: argparse.ArgumentParser, set_help: str = "a model-space parameter (see 'graph'), repeatable") -> None:
    """--gains, --params, --set: parameter values, applied in that order (--set wins)."""
    p.add_argument("--gains", metavar="FILE.json", help="control gains (control.*), e.g. written by the tuner")
    p.add_argument("--params", metavar="FILE.json", help="a parameter file of any addresses, e.g. written by align")
    p.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help=set_help + "; applied last")


def add_seed(p: argparse.ArgumentParser, default: int, help: str = "sensor-noise seed (same seed, bit-identical laps)") -> None:
    p.add_argument("--seed", type=seed_type, default=default, metavar="N", help=f"{help}; 0 … 2^64−1")


def add_search(p: argparse.ArgumentParser, help: str) -> None:
    """--param ADDRESS (repeatable) and --bounds ADDRESS=LO,HI: what a search varies, and where."""
    p.add_argument("--param", action="append", metavar="ADDRESS", help=help)
    p.add_argument("--parameter", dest="param", action=deprecated(argparse._AppendAction, "--param"), help=argparse.SUPPRESS)
    p.add_argument("--bounds", action="append", metavar="ADDRESS=LO,HI", help="search range of a --param, repeatable")


def add_workers(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--workers", type=number(0, 1024, integer=True), default=0, metavar="N",
                   help=f"{what} in parallel (0: one per core); results do not depend on it")


def add_out(p: argparse.ArgumentParser, what: str, metavar: str, required: bool = False) -> None:
    p.add_argument("-o", "--out", required=required, metavar=metavar, help=f"write {what} here (a new file, or one this "
                   "program wrote)")


def add_out_dir(p: argparse.ArgumentParser, what: str, default: str | None) -> None:
    p.add_argument("--out-dir", default=default, metavar="DIR",
                   help=f"write {what} into this folder (new, empty, or one this program wrote)")


def add_firmware(p: argparse.ArgumentParser, what: str, operator: bool = True) -> None:
    p.add_argument("--firmware", metavar="c|avr|FILE", default="c",
                   help=f"what runs the firmware for {what}: c, the portable C in the twin's callback; avr, the robot's "
                   "ATmega328P program built from twin/csrc/firmware/avr and run cycle by cycle in simavr (processor "
                   "in the loop); or a program file, ELF or Intel HEX, as flashed: that program again, or any 3pi "
                   "program (e.g. built with Pololu's libpololu-avr), run unmodified on the 3pi's board and, without "
                   "--robot, on the 3pi")
    if operator:
        p.add_argument("--operator", metavar="FILE.json", help="button presses for a 3pi program, at times or when the "
                       "LCD shows a text (default: press the button the LCD asks for, else B, when the program has "
                       "polled the buttons for a moment with the motors still)")


def add_controller(p: argparse.ArgumentParser, what: str = "the lap") -> None:
    """--controller-fmu with --map and --controller-param, or --multi-model with --stand-in and --coe: a peer's
    controller FMU drives {what} instead of the firmware (:func:`twin_options.controller_from_args`)."""
    p.add_argument("--controller-fmu", metavar="C.fmu", help=f"a controller FMU (FMI 2 or 3 Co-Simulation) drives "
                   f"{what} instead of the firmware, at its sample time: the line sensors' side in, motor voltages, "
                   "wheel-speed set-points or PWM duties out (the firmware still calibrates)")
    p.add_argument("--map", action="append", metavar="FMU_VARIABLE=[-][SCALE*]TWIN_PORT[+OFFSET]", help="connect a "
                   "variable of the --controller-fmu to a twin port, with sign, scale and offset (FMU_VARIABLE = "
                   "SCALE*TWIN_PORT+OFFSET; e.g. servoRightVal=-1*wheel_duty_right), repeatable (default: by name; "
                   "an input no port maps keeps its start value)")
    p.add_argument("--controller-param", action="append", metavar="NAME=VALUE", help="set a parameter of the "
                   "--controller-fmu before its initialisation, repeatable (default: the FMU's own start values)")
    p.add_argument("--multi-model", metavar="FILE.mm.json", help="an INTO-CPS multi-model: its one FMU instance that "
                   f"the twin does not stand in for drives {what}, with the multi-model's connections and parameters "
                   "(with --stand-in)")
    p.add_argument("--stand-in", metavar="FILE.json", help="the instances of the --multi-model the twin replaces, "
                   "their variables as twin ports and where its sensors are (e.g. examples/intocps-line-follower.json)")
    p.add_argument("--coe", metavar="FILE.coe.json", help="the --multi-model's co-simulation configuration, whose "
                   "fixed step the controller runs at (default: the *coe.json beside the multi-model or in a folder "
                   "right below it, one that names the multi-model first)")


def add_lap_timeout(p: argparse.ArgumentParser) -> None:
    p.add_argument("--lap-timeout", type=number(0.0, 3600.0, lo_open=True), default=60.0, metavar="SIM_S",
                   help="a lap not done after this many simulated seconds ends as 'timeout' (a 3pi program that has "
                   "not driven by then after power-up too)")


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout (everything else on stderr)")


def add_recording(p: argparse.ArgumentParser, what: str, view: bool = True) -> None:
    p.add_argument("--save", metavar="FILE.rrd", help=f"write a rerun recording of {what}")
    if view:
        p.add_argument("--view", action="store_true", help=f"show {what} in the rerun viewer (needs a display)")


DEFAULT_DB_URL = "sqlite:///twin_history.sqlite"  # the history database in the working folder


def add_db(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--db", nargs="?", const=DEFAULT_DB_URL, metavar="URL",
                   help=f"keep {what} in this history database (SQLAlchemy URL, e.g. postgresql+psycopg://host/db for "
                        "a fleet; --db alone: twin_history.sqlite in the working folder); an unreachable one is "
                        "reported in one line and the run goes on")


def keep_history(url: str | None, write, out) -> dict | None:
    """``write(history)`` into the database at ``url`` (None: none asked for); a database that cannot be used is
    one warning line, and the command's result stands."""
    if not url:
        return None
    with loading():
        from tuner.history import History, HistoryError, display

    try:
        history = History(url)
        try:
            return {"db": display(url), "run": write(history)}
        finally:
            history.close()
    except HistoryError as e:
        out.warn(f"{e}; the result stands")
        return {"db": display(url), "error": str(e)}


def check_db(url: str | None) -> None:
    """Bad input refused before the work: see :func:`tuner.history.check_db`."""
    if url:
        with loading():
            from tuner.history import check_db as check

        check(url)


def add_verbose(p: argparse.ArgumentParser, quiet: bool = False) -> None:
    p.add_argument("-v", "--verbose", action="store_true", help="log what happens (stderr)")
    if quiet:
        p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


# --- parsing flag text ---------------------------------------------------------------------------------

ASSIGNMENT_FORMS = {  # flag → the form its NAME=VALUE items take, as its metavar and README say
    "--set": "ADDRESS=VALUE, e.g. motion.mu=0.6",
    "--bounds": "ADDRESS=LOWER,UPPER, e.g. control.kp=1,60",
    "--grid": "ADDRESS=V1,V2,…, e.g. cad.L=0.035,0.045",
    "--scenario": "ADDRESS=V1,V2,…, e.g. motion.mu=0.6,0.9",
    "--xacro-arg": "NAME=VALUE, e.g. use_sim=false",
}


def parse_assignments(items: Sequence[str] | None, flag: str = "--set") -> dict[str, str]:
    """``["motion.mu=0.6", ...]`` → {"motion.mu": "0.6"}; the values are checked where they are used (the model
    space, xacro). ``flag`` names the items' flag, and its form (:data:`ASSIGNMENT_FORMS`) in the error."""
    out: dict[str, str] = {}
    for item in items or ():
        address, sep, value = item.partition("=")
        if not sep or not address.strip() or not value.strip():
            raise TwinError(f"{flag} {item!r}: expected {ASSIGNMENT_FORMS[flag]}")
        out[address.strip()] = value.strip()
    return out


def parse_bounds(items: Sequence[str] | None, addresses: Sequence[str] | None = None) -> dict[str, tuple[float, float]]:
    """``["control.kp=1,60", ...]`` → {"control.kp": (1.0, 60.0)}; each address must be among ``addresses``
    when given. The bounds themselves are checked where they are used (the search space, the aligners)."""
    out = {}
    for address, text in parse_assignments(items, "--bounds").items():
        if addresses is not None and address not in addresses:
            raise TwinError(f"--bounds {address}: not a searched parameter ({', '.join(addresses)})")
        try:
            lo, hi = (float(p) for p in str(text).split(","))
        except ValueError:
            raise TwinError(f"--bounds {address}={text}: expected LOWER,UPPER, e.g. control.kp=1,60") from None
        out[address] = (lo, hi)
    return out


def _example(address: str) -> str:
    """Two values inside ``address``'s range, for a message's example (0.6,0.9 for an unknown address)."""
    with loading():
        from twin.model.partial_models import default_space

    try:
        p = default_space().parameter(address)
    except TwinError:
        return "0.6,0.9"
    return ",".join(f"{p.lower + (p.upper - p.lower) * f:.3g}" for f in (1 / 3, 2 / 3))


def parse_grid(items: Sequence[str] | None, flag: str = "--grid") -> dict[str, tuple]:
    """``["cad.L=0.035,0.045"]`` → {"cad.L": (0.035, 0.045)}; a categorical address (``motor.model``) takes names."""
    out: dict[str, tuple] = {}
    for address, text in parse_assignments(items, flag).items():
        if address in CATEGORICAL:
            names = tuple(v.strip() for v in str(text).split(","))
            for name in names:
                CATEGORICAL[address](name)  # an unknown name: one line that lists the choices
            if len(set(names)) != len(names):
                raise TwinError(f"{flag} {address}={text}: a value is given twice")
            out[address] = names
            continue
        try:
            values = tuple(float(v) for v in str(text).split(","))
        except ValueError:
            raise TwinError(f"{flag} {address}={text}: expected comma-separated numbers, e.g. {address}={_example(address)}") from None
        if not all(math.isfinite(v) for v in values):
            raise TwinError(f"{flag} {address}={text}: values must be finite")
        if len(set(values)) != len(values):
            raise TwinError(f"{flag} {address}={text}: a value is given twice")
        out[address] = values
    return out


def _catalogue_motor(name: str):
    with loading():
        from twin.model.motor_setup import catalogue_motor

    return catalogue_motor(name)


CATEGORICAL = {MOTOR_MODEL: _catalogue_motor}  # address → its check, which names the choices
