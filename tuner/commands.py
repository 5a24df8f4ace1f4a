"""The case-study commands of ``python -m twin.run`` that belong to the learning model: ``align`` (and,
as they arrive, ``record`` and ``design``). ``twin.run`` imports this lazily, so the twin's own commands do not
depend on the tuner."""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from mjcf.cli import parse_assignments
from tuner.align import align_lap_time
from tuner.space import TunerError
from twin.errors import TwinError
from twin.recording import APP_ID


def _bounds(items, addresses) -> dict[str, tuple[float, float]]:
    out = {}
    for address, text in parse_assignments(items).items():
        if address not in addresses:
            raise TunerError(f"--bounds {address}: not an aligned parameter ({', '.join(addresses)})")
        try:
            lo, hi = (float(p) for p in str(text).split(","))
        except ValueError:
            raise TunerError(f"--bounds {address}={text}: expected LOWER,UPPER, e.g. motion.mu=0.3,2") from None
        out[address] = (lo, hi)
    return out


def save_alignment(out_path: str, result) -> str:
    """μ (or the aligned parameter) and lap time per iteration, as Fig. 6b–c; written atomically."""
    out_path = os.path.abspath(out_path)
    tmp = f"{out_path}.{os.getpid()}.tmp"
    rec = rr.RecordingStream(APP_ID)
    try:
        rec.save(tmp, default_blueprint=rrb.Blueprint(rrb.Vertical(
            rrb.TimeSeriesView(name=f"{result.parameter}", origin="/align/value"),
            rrb.TimeSeriesView(name="lap time [s]", contents=["/align/lap_time", "/align/measured"]),
        ), collapse_panels=True))
        pts = [p for p in result.trace if p.lap_time_s is not None]
        k = np.arange(len(pts))
        idx = [rr.TimeColumn("lap", sequence=k)]
        rr.send_columns("align/value", indexes=idx, columns=rr.Scalars.columns(scalars=[p.value for p in pts]), recording=rec)
        rr.send_columns("align/lap_time", indexes=idx, columns=rr.Scalars.columns(scalars=[p.lap_time_s for p in pts]),
                        recording=rec)
        rr.send_columns("align/measured", indexes=idx,
                        columns=rr.Scalars.columns(scalars=np.full(len(pts), result.measured_lap_time_s)), recording=rec)
        rec.flush()
        rec.disconnect()
        os.replace(tmp, out_path)
    except OSError as e:
        raise TwinError(f"{out_path}: cannot write the recording ({e.strerror or e})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return out_path


def cmd_align(args: argparse.Namespace) -> int:
    """Align a parameter (default motion.mu) so the simulated lap time equals a measured one."""
    from twin.run import _twin

    if args.seed < 0:
        raise TunerError(f"--seed: must be >= 0, got {args.seed}")
    if args.measured_lap_time is None:
        raise TunerError("align: give --measured-lap-time SECONDS")
    parameters = args.parameter or ["motion.mu"]
    if len(parameters) != 1:
        raise TunerError("--measured-lap-time aligns one parameter: one lap time cannot fix several")
    twin = _twin(args)
    bounds = _bounds(args.bounds, parameters).get(parameters[0])
    r = align_lap_time(twin, args.measured_lap_time, parameters[0], bounds=bounds, seed=args.seed)
    summary = {
        "parameter": r.parameter, "value": r.value, "simulated_lap_time_s": r.simulated_lap_time_s,
        "measured_lap_time_s": r.measured_lap_time_s, "explained": r.explained, "identifiable": r.identifiable,
        "consistent_range": r.consistent, "reachable_lap_times_s": r.reachable_s, "iterations": r.iterations,
        "laps": r.laps, "message": r.message, "trace": [p.__dict__ for p in r.trace],
    }
    if args.save:
        summary["recording"] = save_alignment(args.save, r)
    if args.json:
        print(json.dumps(summary))
    else:
        print(r.message)
        if r.reachable_s:
            print(f"lap times {r.parameter} can give with these gains: {r.reachable_s[0]:.3f}–{r.reachable_s[1]:.3f} s")
        print(f"{r.iterations} iterations, {r.laps} laps")
        if args.save:
            print(f"recording: {summary['recording']}")
    return 0 if r.explained else 1
