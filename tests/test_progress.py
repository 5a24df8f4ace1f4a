"""Progress on every phase that can take more than 2 s (issue 37.4): each bar counts what its phase knows it will do
and ends full at its real end, on stderr, silent under -q and --json. tqdm hides a bar when stderr is not a
terminal (as under pytest), so these tests hand the commands bars that draw into a buffer and read them back."""

from __future__ import annotations

import argparse
import io
import json

import pytest
from tqdm import tqdm

from twin.cli import progress
from twin.core import DigitalTwin
from twin.run import main


@pytest.fixture
def bars(monkeypatch):
    """Every bar a command opens, drawn into a buffer as on a terminal (still silent under -q and --json)."""
    made = []

    def drawn(args, total, desc, unit):
        b = tqdm(total=total, desc=desc, unit=unit, file=io.StringIO(), disable=progress.silent(args), mininterval=0)
        made.append(b)
        return b

    monkeypatch.setattr(progress, "bar", drawn)
    return made


@pytest.mark.quick
def test_json_and_quiet_are_silent_and_a_bar_draws_on_stderr():
    assert progress.bar(argparse.Namespace(quiet=False, json=True), 5, "x", "it").disable is True
    assert progress.bar(argparse.Namespace(quiet=True, json=False), 5, "x", "it").disable is True
    assert progress.silent(argparse.Namespace(quiet=False, json=False)) is False  # then tqdm's rule: a terminal


@pytest.mark.quick
def test_a_phase_that_ends_early_ends_full():
    b = tqdm(total=30, file=io.StringIO(), disable=False)
    b.update(11)
    progress.finish(b)
    assert (b.n, b.total) == (11, 11)
    calls = progress.Phases(argparse.Namespace(quiet=False, json=False), "re-tune", "step")
    calls(1, 8)
    calls(2, 8)
    calls(2, 2)  # its real end, before the 8 it planned
    assert calls.bar is None  # closed; the next re-tune opens a new one


def test_a_converged_tune_ends_full_and_its_held_out_race_counts_laps(bars, capsys):
    """The search converges in 2 iterations of 5 (v_max held at its upper bound): the old bar ended at 2/5."""
    assert main(["tune", "--param", "control.v_max", "--bounds", "control.v_max=0.3,0.6", "--track", "circle",
                 "--max-iter", "5", "--held-out", "3"]) == 0
    tune_bar, race = bars
    assert tune_bar.desc.startswith("tuning") and tune_bar.n == tune_bar.total == 2
    assert race.desc == "held-out race" and race.n == race.total == 3
    assert "2/2" in tune_bar.fp.getvalue() and "3/3" in race.fp.getvalue()
    capsys.readouterr()
    assert main(["tune", "--param", "control.v_max", "--bounds", "control.v_max=0.3,0.6", "--track", "circle",
                 "--max-iter", "5", "--held-out", "3", "--json"]) == 0
    json.loads(capsys.readouterr().out)  # one document
    assert all(b.disable for b in bars[2:]) and len(bars) == 4


def test_a_design_study_counts_the_iterations_and_laps_of_its_first_design(bars, tmp_path):
    """One design, --max-iter 2, --laps 2: four steps planned, and the bar moves before the design ends."""
    assert main(["design", "--grid", "cad.L=0.0425", "--track", "circle", "--laps", "2", "--max-iter", "2",
                 "--workers", "1", "--out-dir", str(tmp_path / "e")]) == 0
    (b,) = bars
    assert b.n == b.total and b.total <= 4
    text = b.fp.getvalue()
    assert "1/4" in text or "1/3" in text, text  # a step drawn while the first (and only) design still ran


def test_a_design_studys_steps_reach_the_parent_from_its_worker_processes():
    from tuner.studies.design import steps_per_design, study

    base = {"track": "circle", "metres_per_pixel": None, "values": {}, "robust": False}
    designs = [{"cad.L": 0.0425}, {"cad.L": 0.05}]
    seen = {1: [], 2: []}
    for workers in (1, 2):
        study(designs, base, laps=1, max_iter=1, workers=workers, on_step=lambda k, n: seen[workers].append((k, n)))
    for workers, steps in seen.items():
        done = sum(n for k, n in steps if k == "done")
        skipped = sum(n for k, n in steps if k == "skipped")
        assert done + skipped == len(designs) * steps_per_design(1, 1), (workers, steps)
        assert done >= len(designs)  # at least each design's lap
    assert sorted(seen[1]) == sorted(seen[2])  # the same steps, whichever process ran them


def test_diagnose_counts_its_candidates(bars, capsys):
    assert main(["diagnose", "--measured-lap-time", "6.0", "--track", "circle", "--candidate", "motion.mu",
                 "--candidate", "motor.supply_voltage"]) in (0, 1)
    (b,) = bars
    assert b.total == b.n == 2 and "2/2" in b.fp.getvalue()
    out = capsys.readouterr().out
    assert "  motion.mu: " in out and "  motor.supply_voltage: " in out  # each candidate's line, as before


def test_a_retune_reports_its_steps_and_ends_at_its_real_end():
    """The gains in force already finish the envelope: one race of them (and the longer race that keeps them), so
    the re-tune ends after 1 of the 8 steps it planned (6 descent iterations, 2 races)."""
    from tuner.live.retune import RETUNE_DESCENT, retune_gains

    calls = []
    r = retune_gains(DigitalTwin(track="circle"), "motion.mu", 0.85, 0.95, (0, 1), progress=lambda d, p: calls.append((d, p)))
    assert not r.changed
    assert calls[0] == (1, RETUNE_DESCENT.max_iter + 2) and calls[-1] == (1, 1)


def test_a_bar_started_in_a_worker_thread_does_not_touch_the_signal_handlers():
    """live --act re-tunes in a worker thread and shows its progress there: only the main thread may set a signal's
    handler (Python raises ValueError elsewhere), so loading the bar's library from a worker must not try."""
    import argparse
    import threading

    from twin.cli import progress

    errors = []

    def work():
        try:
            phases = progress.Phases(argparse.Namespace(quiet=False, json=False), "re-tune", "step")
            phases(1, 2)
            phases(2, 2)
        except Exception as e:  # noqa: BLE001 - the test reports whatever a worker raised
            errors.append(e)

    t = threading.Thread(target=work)
    t.start()
    t.join(30)
    assert not errors, errors
