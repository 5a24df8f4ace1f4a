"""Every benchmark runs, so none can rot, and every figure in docs/performance.md names one that measures it.

* Each ``.py`` in benchmarks/ (found on disk: a new script is picked up) runs with ``--quick`` (tiny sizes, the
  same code paths and rows) within a time limit, exits 0 and prints its figures: the rows listed in ``FIGURES``,
  each on a line with a number (a script missing from ``FIGURES`` fails, so its rows must be named).
* The table of docs/performance.md ("Measured") names a benchmark command in every row; each is a script that exists.
  Each command as cited runs with ``--quick`` added (its flags parsed as a user types them); a script the table
  does not cite runs bare.

About 13 minutes of the suite's wall time for all of them, 10 of CPU, on 2 cores (2026-12-03; each script tunes,
lays laps or starts processes of its own)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCH = os.path.join(ROOT, "benchmarks")
DOC = os.path.join(ROOT, "docs", "performance.md")
LIMIT_S = 600  # wall seconds for one --quick run on a loaded 2-core machine (the slowest takes about 2 min)

# per script: the start of each row it prints (its own words), each of which must come with a measured number
FIGURES = {
    "bench_act.py": ["failed laps: plain", "laps at 20× real time ("],
    "bench_case_studies.py": ["align to a lap time", "align to a recorded run", "lap_time  :", "diagnose  :",
                              "telemetry :", "default design study"],
    "bench_closed_loop.py": ["closed loop (C)", "ceiling (mj_step)", "Python loop", "closed / ceiling",
                             "with the trace kept", "closed / Python"],
    "bench_cluster.py": ["local, 1 worker", "local, 2 workers", "Ray, 1 CPU", "Ray, 2 CPUs", "model, 2 CPUs"],
    "bench_fmu.py": ["closed-loop FMU, outputs every 5 ms", "plant FMU", "controller FMU in the twin's loop",
                     "controller FMU behind its wall"],
    "bench_forecast.py": ["robots (linear", "linear seed 7, lap", "linear seed 7, at lap"],
    "bench_learn.py": ["analysis:"],
    "bench_motors.py": ["pololu-mp-6v-30", "pololu-3pi-30", "largest error [%]"],
    "bench_pil.py": ["PIL lap", "C lap", "MCU only", "3pi program on the board"],
    "bench_startup.py": ["python -c pass:", "worst:", "re-tune (live --act"],
    "bench_step.py": ["serial Python loop", "batch, 1 thread", "batch, all cores", "laps batched"],
    "bench_timestep.py": ["largest step keeping fidelity", "CPU per lap"],
    "bench_timing.py": ["default  default", "default  plain", "worst |mean difference|"],
    "bench_tuner.py": ["as delivered", "held-out completion", "full default tuning run", "CMA-ES", "batched / CMA-ES",
                       "price of robustness", "python -m tuner --robust -q --json"],
}
SCRIPTS = sorted(f for f in os.listdir(BENCH) if f.endswith(".py"))
CITED = re.compile(r"`python benchmarks/([^`\s]+)([^`]*)`")


def table_rows() -> list[list[str]]:
    """The cells of each figure row of docs/performance.md's "Measured" table."""
    with open(DOC, encoding="utf-8") as f:
        text = f.read()
    table = next(block for block in text.split("## Measured", 1)[1].split("\n\n") if block.startswith("| figure |"))
    lines = table.splitlines()
    assert lines[0].split("|")[1:3] == [" figure ", " command "], lines[0]
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines[2:]]


def cited_commands() -> list[tuple[str, ...]]:
    """Every benchmark command the table cites, as (script, flags...), optional parts ([--flag X]) left out."""
    out = set()
    for row in table_rows():
        for script, flags in CITED.findall(row[1]):
            out.add((script, *shlex.split(re.sub(r"\[[^\]]*\]", "", flags))))
    return sorted(out)


@pytest.mark.quick
def test_every_figure_row_cites_a_benchmark_that_exists():
    rows = table_rows()
    assert len(rows) >= 25  # the table as it stands: a parse that found nothing must not pass
    for row in rows:
        found = CITED.findall(row[1])
        assert found, f"no `python benchmarks/….py` command for the figure {row[0]!r}: {row[1]!r}"
        for script, _ in found:
            assert script in SCRIPTS, f"{row[0]!r} cites benchmarks/{script}, which does not exist"


@pytest.mark.quick
def test_every_script_names_the_figures_it_prints():
    assert sorted(FIGURES) == SCRIPTS, "a benchmark script needs its rows in FIGURES (and its --quick mode)"


PARTIAL = {"--robust-only"}  # flags after which a script prints a part of its rows only
# each command the table cites, and each script it does not cite run bare (so every script runs at least once)
RUNS = sorted(set(cited_commands()) | {(s,) for s in SCRIPTS if all(c[0] != s for c in cited_commands())})


@pytest.mark.parametrize("argv", RUNS, ids=[" ".join(r) for r in RUNS])
def test_benchmark_runs_in_quick_mode_and_prints_its_figures(argv, tmp_path, request):
    script, *flags = argv
    if script == "bench_cluster.py":  # it starts a Ray head: one at a time on the machine (conftest.one_ray_head)
        request.getfixturevalue("one_ray_head")
    try:
        run = subprocess.run([sys.executable, os.path.join(BENCH, script), *flags, "--quick"], cwd=tmp_path,
                             capture_output=True, text=True, timeout=LIMIT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{' '.join(argv)} --quick ran past {LIMIT_S} s")
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.splitlines()
    numbered = [line for line in lines if re.search(r"\d", line)]
    assert numbered, f"{' '.join(argv)} --quick printed no figure: {run.stdout!r}"
    if not PARTIAL & set(flags):  # the script's whole report: every row it names
        for row in FIGURES.get(script, []):
            assert any(row in line for line in numbered), f"{script} --quick printed no row {row!r}:\n{run.stdout}"


@pytest.mark.parametrize("flags, says", [(["--edge-seeds", "20"], "--edge-seeds 20: only with --again"),
                                         (["--again", "no-such-folder"], "--again no-such-folder: no such folder"),
                                         (["--again", ".", "--edge-seeds", "1"], "--edge-seeds 1: at least 2")])
def test_the_forecast_benchmark_refuses_bad_flags_in_one_line(flags, says, tmp_path):
    """Before it tunes or races anything: one line naming the flag, exit 2."""
    run = subprocess.run([sys.executable, os.path.join(BENCH, "bench_forecast.py"), *flags], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and run.stdout == ""
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {says}"), run.stderr
