"""A design study says, per design, whether its gains converged (issue 22.7: ``design --max-iter`` reported
"converged gains" when no search had converged): in the text, the JSON, the table, the gains files and the
charts' labels."""

from __future__ import annotations

import csv
import json

from tuner.studies.design import DesignResult
from tuner.studies.report import chart_label
from twin.run import main


def test_a_search_stopped_at_its_limit_is_said_everywhere(tmp_path, capsys):
    out = tmp_path / "study"
    # one iteration cannot converge: the descent's rule needs an accepted step smaller than 1 % of every range
    # after at least one step, and the first step from the default gains moves them by far more
    assert main(["design", "--grid", "cad.L=0.0425", "--track", "circle", "--laps", "1", "--max-iter", "1",
                 "--workers", "1", "--out-dir", str(out), "--json", "-q"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (d,) = doc["designs"]
    assert d["ok"] and d["converged"] is False and "iteration cap (1)" in d["search"]
    (row,) = list(csv.DictReader(open(out / "designs.csv")))
    assert row["converged"] == "False" and "iteration cap" in row["search"]
    (gains_file,) = (out / "gains").iterdir()
    assert json.loads(gains_file.read_text())["converged"] is False
    assert main(["design", "--grid", "cad.L=0.0425", "--track", "circle", "--laps", "1", "--max-iter", "1",
                 "--workers", "1", "--out-dir", str(tmp_path / "again")]) == 0
    text = "".join(capsys.readouterr())
    assert "gains not converged" in text and "1 of 1 designs stopped at --max-iter 1" in text


def test_chart_labels_mark_designs_whose_gains_did_not_converge():
    def result(converged):
        return DesignResult({"cad.L": 0.045}, True, None, {}, 1, 1, converged, (7.0,), 0, 0.003, 0.0)

    assert "not converged" in chart_label(result(False))
    assert "not converged" not in chart_label(result(True))


def test_a_trend_is_stated_over_converged_designs_only():
    """Issue 36: ``design --max-iter 5`` said "larger cad.L raises the converged lap time" above "2 of 2 designs …
    before their gains converged"."""
    from tuner.studies.design import trend

    def result(length, median, converged):
        return DesignResult({"cad.L": length}, True, None, {}, 5, 5, converged, (median,), 0, 0.003, 0.0)

    stopped = [result(0.035, 7.0, False), result(0.055, 8.0, False)]
    line = trend(stopped, "cad.L")
    assert "raises" not in line and "not enough designs with converged gains" in line and "2 designs left out" in line
    mixed = [result(0.035, 7.0, True), result(0.045, 9.5, False), result(0.055, 8.0, True), result(0.065, 7.5, True)]
    line = trend(mixed, "cad.L")  # over 7.0, 8.0, 7.5: not monotonic; with the stopped 9.5 it would still not be
    assert "0.035 → 7.000 s, 0.055 → 8.000 s, 0.065 → 7.500 s" in line and "0.045" not in line, line
    assert "1 design left out: gains not converged, raise --max-iter" in line
    assert "raises" in trend(mixed[:3], "cad.L") and "0.045" not in trend(mixed[:3], "cad.L")
