"""The flag vocabulary, written once: the same word means the same thing in every command (docs/cli.md's
"Flags" table lists every flag; a test checks it against ``--help``). Old spellings keep working for one
release, hidden from ``--help``, with a deprecation warning on stderr.

Also the one public way to build a twin from command-line options: :func:`twin_from_args`.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import sys
from typing import Sequence

from mjcf.robot_config import RobotConfig
from twin.cli.guard import fail
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.model.motor_setup import MOTOR_MODEL, catalogue_motor, motor_for_robot, use_motor
from twin.core.identity import mismatch
from twin.model.parameter_files import load_gains, load_values, tuned_for_record
from twin.model.partial_models import default_space
from twin.model.robots import ROBOTS, named_robot, use_robot

MAX_SEED = 2**64 - 1
log = logging.getLogger(__name__)


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
                       f".xacro, .urdf.xacro) instead of the generated robot, or a named robot ({', '.join(ROBOTS)}: "
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


def add_lap_timeout(p: argparse.ArgumentParser) -> None:
    p.add_argument("--lap-timeout", type=number(0.0, 3600.0, lo_open=True), default=60.0, metavar="SIM_S",
                   help="a lap not done after this many simulated seconds ends as 'timeout' (a 3pi program that has "
                   "not driven by then after power-up too)")


def check_program_runs(twin: DigitalTwin, program) -> None:
    """The program ``--firmware`` names (None: the twin's own, built here) checked against ``twin`` before any lap:
    one line (a missing simavr included) otherwise."""
    from twin.pil import runnable_firmware
    from twin.pil.board import runnable_program

    if program is None:
        runnable_firmware(twin)
    else:
        runnable_program(twin, program.path)


def program_from_args(args: argparse.Namespace):
    """The program ``--firmware FILE`` names, loaded and checked for the MCU (None for c and avr); the ``--operator``
    script if one is given. A one-line TwinError on a bad file."""
    from twin.pil.board import load_script
    from twin.pil.program import load_program

    firmware = getattr(args, "firmware", "c")
    program = None if firmware in ("c", "avr") else load_program(firmware)
    script = getattr(args, "operator", None)
    if script and (program is None or program.traced):
        raise TwinError("--operator: presses buttons for a 3pi program run on the board (--firmware FILE of a program "
                        "other than the twin's own firmware)")
    return program, load_script(script) if script else None


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


def parse_sensor_mount(text: str | None) -> tuple[str, tuple[float, float, float]] | None:
    """``"base_link:0.1,0,-0.03"`` → ("base_link", (0.1, 0.0, -0.03))."""
    if not text:
        return None
    link, sep, xyz = text.rpartition(":")
    try:
        values = tuple(float(v) for v in xyz.split(","))
    except ValueError:
        values = ()
    if not sep or not link or len(values) != 3 or not all(math.isfinite(v) and abs(v) < 10 for v in values):
        raise TwinError(f"--sensor-mount {text!r}: expected LINK:X,Y,Z in metres, e.g. base_link:0.1,0,-0.03")
    return link, values  # type: ignore[return-value]


def robot_config(args: argparse.Namespace) -> RobotConfig:
    """Which parts of the robot description are the wheels, caster and sensor mount, and how to read it."""
    wheels = None
    if getattr(args, "wheel_joints", None):
        parts = args.wheel_joints.split(",")
        if len(parts) != 2 or not all(p.strip() for p in parts):
            raise TwinError(f"--wheel-joints {args.wheel_joints!r}: expected LEFT,RIGHT")
        wheels = (parts[0].strip(), parts[1].strip())
    packages = []
    for item in getattr(args, "package", None) or ():
        name, sep, path = item.partition("=")
        if not sep or not name.strip() or not path.strip():
            raise TwinError(f"--package {item!r}: expected NAME=DIR")
        if not os.path.isdir(path):
            raise TwinError(f"--package {item}: {path} is not a folder")
        packages.append((name.strip(), path))
    xacro_args = tuple(parse_assignments(getattr(args, "xacro_arg", None), "--xacro-arg").items())
    description = getattr(args, "robot", None) or getattr(args, "urdf", None)
    given = [f for f, v in (("--wheel-joints", wheels), ("--caster", getattr(args, "caster", None)),
                            ("--sensor-link", getattr(args, "sensor_link", None)),
                            ("--sensor-mount", getattr(args, "sensor_mount", None)), ("--package", packages),
                            ("--xacro-arg", xacro_args)) if v]
    if given and not description:
        raise TwinError(f"{given[0]}: describes a robot description; give one with --robot")
    return RobotConfig(wheel_joints=wheels, caster=getattr(args, "caster", None),
                       sensor_link=getattr(args, "sensor_link", None),
                       sensor_mount=parse_sensor_mount(getattr(args, "sensor_mount", None)),
                       package_dirs=tuple(packages), xacro_args=xacro_args)


# --- the twin the flags describe -----------------------------------------------------------------------

def twin_from_args(args: argparse.Namespace, track: str | None = None, robot: str | None = None) -> DigitalTwin:
    """The twin the command line describes: world options (a named robot's values: ``--robot 3pi``), then --gains,
    --params, then --set (which wins).

    Args:
      args: parsed options of :func:`add_world` and :func:`add_values` (missing ones are skipped).
      track: overrides ``args.track`` (e.g. the track a telemetry file names).
      robot: the named robot when ``--robot`` names none (a 3pi program runs on the 3pi).
    """
    given = getattr(args, "robot", None)
    named = named_robot(given or robot or "")
    config = robot_config(args)
    if named is not None and given and config != RobotConfig():
        raise TwinError(f"--robot {given}: a named robot has no description to read; the description flags apply to a "
                        "URDF or xacro")
    twin = DigitalTwin(track=track or getattr(args, "track", None) or "default",
                       robot_urdf=None if named is not None else given, robot_config=config,
                       track_metres_per_pixel=getattr(args, "metres_per_pixel", None))
    if named is not None:
        use_robot(twin, named)
    changes: dict = {}
    if getattr(args, "gains", None):
        changes.update(load_gains(args.gains, twin.space))
    if getattr(args, "params", None):
        changes.update(load_values(args.params, twin.space))
    changes.update(parse_assignments(getattr(args, "set", None)))
    model = changes.pop(MOTOR_MODEL, None)
    if model is not None and getattr(args, "motor", None) not in (None, model):
        raise TwinError(f"--motor {args.motor} and --set {MOTOR_MODEL}={model}: two motors; give one")
    twin.update(changes)
    _choose_motor(twin, getattr(args, "motor", None) or model, changes)
    return twin


def gains_warning(args: argparse.Namespace, twin: DigitalTwin) -> str | None:
    """When ``--gains`` names a file tuned for another robot, motor or track than ``twin`` runs: one line, logged as
    a warning; the command puts it in its ``--json`` too (``gains_warning``, null when the gains fit)."""
    path = getattr(args, "gains", None)
    why = mismatch(tuned_for_record(path), twin, path) if path else None
    if why:
        log.warning(why)
    return why


CATEGORICAL = {MOTOR_MODEL: catalogue_motor}  # address → its check, which names the choices


def _choose_motor(twin: DigitalTwin, name: str | None, changes: dict) -> None:
    """``--motor NAME``, or for a robot description without motor values of its own, the motor that fits it;
    values given with --gains, --params or --set still win. Says what it chose."""
    if name is None and (twin.robot_urdf is None or any(a.startswith("motor.") and a != "motor.supply_voltage"
                                                        for a in changes)):
        return
    if name is not None:
        datasheet, why = catalogue_motor(name), f"--motor {name}"
    else:
        choice = motor_for_robot(twin, twin.space.get("motor.supply_voltage"))
        datasheet, why = choice.datasheet, f"{choice.name}: {choice.reason}"
    use_motor(twin, datasheet, keep=changes)
    log.warning("motor: %s", why)
