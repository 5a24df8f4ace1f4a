"""The front door: one CLI layer over the libraries, one flag vocabulary (docs/cli.md's table = ``--help``),
``--json`` = exactly one JSON document on stdout, deprecated spellings that still work."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys

import pytest

from twin.cli import main as front_door
from twin.cli import robot, tune
from twin.link.emulator import lap_records
from twin.core.digital_twin import DigitalTwin

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = sys.executable


def parsers() -> dict[str, argparse.ArgumentParser]:
    """Every command's parser, by its name under ``python -m twin.run`` (``python -m tuner`` is ``tune``,
    ``python -m mjcf generate|convert`` are ``generate`` and ``convert``: the same options)."""
    top = front_door.parser()
    return {name: p for a in top._actions if isinstance(a, argparse._SubParsersAction) for name, p in a.choices.items()}


@pytest.mark.quick
def test_the_other_entry_points_have_the_same_options():
    assert visible_flags(tune.parser()) == visible_flags(parsers()["tune"])


def visible_flags(p: argparse.ArgumentParser) -> set[str]:
    return {s for a in p._actions if a.help != argparse.SUPPRESS for s in a.option_strings
            if s.startswith("--") and s != "--help"}


def readme_table() -> dict[str, set[str]]:
    """The "Flags" table of docs/cli.md: flag → commands that have it."""
    text = open(os.path.join(ROOT, "docs", "cli.md"), encoding="utf-8").read()
    section = text.split("\n## Flags\n", 1)[1].split("\n## ", 1)[0]
    table: dict[str, set[str]] = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.replace("\\|", "/").strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[0].startswith("`"):
            continue
        flags = re.findall(r"(--[a-z][a-z-]*)", cells[0])
        commands = {"ALL"} if cells[2] == "all commands" else set(re.findall(r"[a-z]+", cells[2]))
        for f in flags:
            table[f] = commands
    return table


@pytest.mark.quick
def test_the_readme_flag_table_matches_help():
    table = readme_table()
    found: dict[str, set[str]] = {}
    for command, p in parsers().items():
        for flag in visible_flags(p):
            found.setdefault(flag, set()).add(command)
    everyone = set(parsers())
    assert set(table) == set(found), f"in help only: {set(found) - set(table)}; in docs/cli.md only: {set(table) - set(found)}"
    for flag, commands in found.items():
        listed = everyone if table[flag] == {"ALL"} else table[flag]
        assert listed == commands, f"{flag}: docs/cli.md lists {sorted(listed)}, --help has it in {sorted(commands)}"


@pytest.mark.quick
def test_help_shows_defaults_and_every_command_is_listed_and_described():
    top = front_door.parser()
    text = top.format_help()
    for command, p in parsers().items():
        assert command in text
        assert p.description, f"{command} has no description"
    assert tune.parser().description
    lap_help = parsers()["lap"].format_help()
    assert "(default: 60.0)" in lap_help and "(default: default)" in lap_help
    assert "0.1 %" in parsers()["align"].format_help() and "%%" not in parsers()["align"].format_help()


def test_help_is_plain_text_not_rest_markup():
    for name, p in [*parsers().items(), ("twin.run", front_door.parser()), ("tuner", tune.parser()),
                    ("mjcf", robot.parser())]:
        text = p.format_help()
        assert not re.search(r"``|:(mod|func|class|meth|data):`", text), f"{name} --help shows reST markup"


def _run(*args, cwd=None, env=None, timeout=300):
    return subprocess.run([PY, "-m", *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)


@pytest.fixture(scope="module")
def wire_log(tmp_path_factory):
    """A telemetry log of two laps of a stand-in robot, in the wire form."""
    path = tmp_path_factory.mktemp("wire") / "robot.log"
    twin = DigitalTwin(track="oval")
    path.write_text("".join(line for _, line in lap_records(twin, 7, 2, 2)))
    return path


def test_every_command_prints_exactly_one_json_document(tmp_path, wire_log, third_party_urdf):
    tel = tmp_path / "lap.jsonl"
    oval = ["--track", "oval"]
    runs = {
        "lap": ["twin.run", "lap", *oval],
        "tune": ["tuner", *oval, "--max-iter", "1", "--param", "control.kp"],
        "align": ["twin.run", "align", *oval, "--measured-lap-time", "9"],
        "record": ["twin.run", "record", *oval, "--out", str(tel)],
        "design": ["twin.run", "design", *oval, "--grid", "cad.S=0.05", "--laps", "1", "--max-iter", "1", "--workers", "1",
                   "--out-dir", str(tmp_path / "study")],
        "live": ["twin.run", "live", *oval, "--replay", str(wire_log), "--seed", "0"],
        "build": ["twin.run", "build", *oval],
        "graph": ["twin.run", "graph"],
        "generate": ["mjcf", "generate", "--out-dir", str(tmp_path / "robot")],
        "convert": ["mjcf", "convert", third_party_urdf, "-o", str(tmp_path / "world.xml"), *oval],
    }
    for name, args in runs.items():
        r = _run(*args, "--json", cwd=tmp_path)
        assert r.returncode in (0, 1), f"{name}: {r.stderr}"
        doc = json.loads(r.stdout)  # exactly one document: json.loads refuses anything after it
        assert isinstance(doc, dict), name
    align_tel = _run("twin.run", "align", "--telemetry", str(tel), "--param", "motor.R_M", "--json", cwd=tmp_path)
    assert align_tel.returncode in (0, 1), align_tel.stderr
    assert json.loads(align_tel.stdout)["parameters"][0]["address"] == "motor.R_M"


def test_emulate_json_is_its_link_and_nothing_else(tmp_path):
    p = subprocess.Popen([PY, "-m", "twin.run", "emulate", "--track", "oval", "--tcp", "0", "--laps", "1", "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        doc = json.loads(p.stdout.readline())
        assert doc["link"].startswith("socket://127.0.0.1:")
    finally:
        p.terminate()
        out, _ = p.communicate(timeout=30)
    assert out == ""


def test_a_non_gain_tuning_writes_a_parameter_file_that_lap_reads(tmp_path, capsys):
    out = tmp_path / "mu.json"
    assert tune.main(["--track", "oval", "--param", "motion.mu", "--bounds", "motion.mu=0.5,1.5", "--max-iter", "1",
                      "--out", str(out), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["loads_with"] == "--params" and "gains" not in summary
    assert json.loads(out.read_text())["parameters"].keys() == {"motion.mu"}
    assert front_door.main(["lap", "--track", "oval", "--gains", str(out)]) == 2  # not a gains file
    assert "not a gains file" in capsys.readouterr().err
    assert front_door.main(["lap", "--track", "oval", "--params", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["parameters"]["motion.mu"] == summary["values"]["motion.mu"]


def test_old_spellings_work_for_one_release_with_a_warning(tmp_path, capsys):
    assert front_door.main(["lap", "--track", "oval", "--timeout", "0.5", "--json"]) == 0
    captured = capsys.readouterr()
    assert "--timeout is deprecated, use --lap-timeout" in captured.err
    assert json.loads(captured.out)["failure"] == "timeout"
    assert robot.main(["generate", "-o", str(tmp_path / "r")]) == 0
    assert "use --out-dir" in capsys.readouterr().err and (tmp_path / "r" / "robot.urdf").is_file()


def test_usage_errors_are_one_line():
    r = _run("twin.run", "lap", "--seed", "18446744073709551616")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and r.stderr.startswith("error: ")
    r = _run("twin.run", "lap", "--no-such-flag")
    assert r.returncode == 2 and r.stderr.count("\n") == 1


