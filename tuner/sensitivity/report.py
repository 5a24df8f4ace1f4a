"""An analysis as a document and a folder: the JSON a command prints (influences, relations, laps, wall time), and
``learned_graph.json``, ``influences.csv``, ``learned_graph.png`` and ``indices.png`` written atomically into an
output folder of ours (``lf_common.files.output_dir``)."""

from __future__ import annotations

import csv
import dataclasses
import json
import os

from lf_common.files import GENERATOR, json_safe, output_dir
from twin.model.space import ModelSpace
from tuner.sensitivity.analysis import CONFIDENCE, MIN_GIVEN, MIN_TOTAL, SCREEN_SHARE, Analysis
from tuner.sensitivity.precision import TOO_FEW
from tuner.sensitivity.charts import graph_chart, indices_chart
from tuner.sensitivity.relations import Relation, by_status

INFLUENCE_FIELDS = ("parameter", "output", "first", "first_interval", "total", "total_interval", "method", "mu_star",
                    "mu_star_interval", "sigma", "delta", "delta_interval", "floor", "measured")


def document(space: ModelSpace, analysis: Analysis, relations: list[Relation]) -> dict:
    """Everything the analysis found, JSON-ready: ``influences`` (one per parameter and output: Sobol' indices with
    95 % bootstrap intervals where measured, Morris μ* for every factor), the factors and their ranges, the
    relations against the declared graph by status, laps and wall time."""
    extra = analysis.extra
    return {
        "influences": [{k: getattr(i, k) for k in INFLUENCE_FIELDS} for i in analysis.influences],
        "factors": [dataclasses.asdict(f) for f in analysis.factors],
        "left_out": extra.get("left_out", {}),
        "sobol_factors": list(analysis.selected),
        "outputs": {o: analysis.summary.get(o, {}) for o in analysis.outputs},
        "relations": {status: [dataclasses.asdict(r) for r in rs] for status, rs in by_status(relations).items()},
        "laps": extra.get("laps", analysis.runs), "morris_laps": analysis.morris_runs, "sobol_laps": analysis.sobol_runs,
        "wall_s": extra.get("wall_s"), "cpu_s": extra.get("cpu_s"), "completion_rate": extra.get("completion_rate"),
        "failures": extra.get("failures", {}), "track": extra.get("track"),
        "method": {"screening": f"Morris, {analysis.trajectories} trajectories, 4 levels; a factor goes on when its μ* "
                                f"reaches {SCREEN_SHARE:g} of the largest on some output",
                   "indices": f"Sobol' first and total order, Saltelli sampling N = {analysis.samples} on a scrambled "
                              f"Sobol' sequence, {CONFIDENCE:.0%} bootstrap intervals (SALib)",
                   "measured": f"total index (or δ) ≥ {MIN_TOTAL:g} with its interval above 0 (δ: above a dummy "
                               "factor's δ)",
                   "failed_laps": "completed is 1 or 0 (its own Sobol' indices); a failed lap has no lap time, energy "
                                  "or cross-track error and none is written in: Morris uses the steps whose two laps "
                                  "completed, and where a Sobol' stage has failed laps those outputs get Borgonovo's "
                                  "moment-independent δ and the given-data S1 over the completed laps (Borgonovo 2007; "
                                  "Plischke, Borgonovo & Smith 2013; SALib delta), which need no sampling design and "
                                  f"allow dependent inputs; at least {MIN_GIVEN} completed laps",
                   "seed": analysis.seed},
        "notes": list(analysis.notes),
        "warnings": [n for n in analysis.notes if n.startswith(TOO_FEW)],
    }


def write_folder(out_dir: str, space: ModelSpace, analysis: Analysis, relations: list[Relation], title: str) -> dict:
    """``learned_graph.json``, ``influences.csv``, ``learned_graph.png``, ``indices.png`` into ``out_dir`` (new,
    empty, or ours), atomically; returns their paths."""
    doc = document(space, analysis, relations)
    with output_dir(out_dir, "learned graph folder") as tmp:
        with open(os.path.join(tmp, "learned_graph.json"), "w") as f:
            json.dump(json_safe({"generator": GENERATOR, **doc}), f, indent=1, allow_nan=False)
        with open(os.path.join(tmp, "influences.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["parameter", "output", "method", "first", "first_low", "first_high", "total", "total_low",
                        "total_high", "mu_star", "mu_star_low", "mu_star_high", "sigma", "delta", "delta_low",
                        "delta_high", "delta_dummy"])
            blank = lambda v: "" if v is None else v  # noqa: E731
            for i in analysis.influences:
                fi, ti, di = (iv or ("", "") for iv in (i.first_interval, i.total_interval, i.delta_interval))
                w.writerow([i.parameter, i.output, i.method, blank(i.first), *fi, blank(i.total), *ti, i.mu_star,
                            *i.mu_star_interval, i.sigma, blank(i.delta), *di, blank(i.floor)])
        graph_chart(os.path.join(tmp, "learned_graph.png"), analysis, relations, title)
        indices_chart(os.path.join(tmp, "indices.png"), analysis, title)
    out = os.path.abspath(out_dir)
    return {"folder": out, **{k: os.path.join(out, n) for k, n in (
        ("json", "learned_graph.json"), ("csv", "influences.csv"), ("graph_png", "learned_graph.png"),
        ("indices_png", "indices.png"))}}
