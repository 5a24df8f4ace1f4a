"""What a forecast's note says the value now rests on: read from the robot's laps, or carried on at its rate from
the last lap read when the laps since failed (a failed lap says only that the value is past where the gains fail,
not how far: issue 35, a battery held at 3.95 V read as 3.35 V after its laps began to fail)."""

from __future__ import annotations

import pytest

from tuner.history import forecast_failure
from tuner.history.forecast import carried_on
from tuner.prognostics import Outcome
from twin.core.digital_twin import DigitalTwin

from reference_gains import PLAIN_HELD as PLAIN

SAID = "say only which side of the twin's edge it lies"


@pytest.mark.quick
def test_a_value_carried_past_the_last_lap_read_says_so():
    """Laps 11-14 after the last lap read (10), two of them failed: the value now is carried on from lap 10."""
    outcomes = [Outcome(n, n in (12, 14)) for n in range(15)]
    assert carried_on(14, outcomes, 14) == "" and carried_on(10, outcomes, 10) == ""
    assert carried_on(10, outcomes, 14) == (f"carried on at its rate from lap 10, the last lap read: the 4 lap(s) "
                                            f"since (2 failed) {SAID}")


def test_the_note_of_a_forecast_past_its_last_lap_read_says_the_value_is_carried_on():
    """Grip aligned on laps 4-5, 14-15 and 24-25 (0.9 − 0.005·lap), laps 0-25 finished and 26-28 failed: at lap 25
    the value is read; at lap 28 it is carried on from lap 25, the three failed laps counted."""
    twin = DigitalTwin()
    twin.model()
    alignments = [{"first_lap": lap - 1, "lap": lap, "address": "motion.mu", "explained": True,
                   "value": 0.9 - 0.005 * (lap - 0.5), "interval": [0.895 - 0.005 * lap, 0.905 - 0.005 * lap]}
                  for lap in (5, 15, 25)]
    laps = [{"n": n, "completed": n < 26, "gains": PLAIN} for n in range(29)]
    read = forecast_failure(twin, PLAIN, alignments, laps, "motion.mu", now_lap=25)
    assert read.note.startswith("motion.mu is ") and "carried on" not in read.note
    late = forecast_failure(twin, PLAIN, alignments, laps, "motion.mu", now_lap=28)
    assert f"; carried on at its rate from lap 25, the last lap read: the 3 lap(s) since (3 failed) {SAID}), from 3 " \
           "alignments" in late.note
    assert "already fail" in late.statement  # its last lap failed
    assert read.evidence["last_read_lap"] == late.evidence["last_read_lap"] == 25  # the JSON's, which the CLI says
    assert (read.evidence["carried_on"], late.evidence["carried_on"]) == (False, True)  # one condition, note and CLI


@pytest.mark.quick
def test_the_history_command_says_carried_on_when_the_forecast_does(capsys):
    """The command's value line says "carried on" from the forecast's own flag (evidence.carried_on), the note's
    condition: a last lap read before the lap now with no lap outcome since (another gains' laps) is not carried."""
    from twin.cli.history import say_entry
    from twin.cli.output import Output

    def entry(carried: bool) -> dict:
        forecast = {"value_now": 0.7, "now_lap": 28, "rate": (-0.006, -0.005, -0.004), "misfit": None,
                    "statement": "", "evidence": {"alignments": 0, "alignments_used": 0, "observed_laps": 20,
                                                  "laps": 29, "last_read_lap": 25, "carried_on": carried}}
        return {"kind": "robot", "robot": "r", "laps": 29, "completed": 26, "failed": 3, "median_lap_time_s": None,
                "changes": [], "forecasts": {"motion.mu": forecast}, "forecast": None, "advice": []}

    say_entry(Output(False), entry(True))
    said = capsys.readouterr().out
    assert "motion.mu: 0.7 at lap 28 (carried on from lap 25, the last lap read), -0.005 per lap" in said
    say_entry(Output(False), entry(False))
    assert "carried on" not in capsys.readouterr().out
