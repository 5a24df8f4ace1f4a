"""A stand-in robot for the forecast's tests: the twin with its own noise seeds, its parameters drifting lap by lap
(``emulate --drift``'s shapes), its laps as the history holds them: completed, lap time and the line's mean offset
and side from its telemetry (every 5th control tick, as ``emulate --every 5`` sends it)."""

from __future__ import annotations

from tuner.history.twin_edge import line_offset_m, line_side_m
from twin.core.closed_loop import run_laps
from twin.link.emulator import Drift


def robot_laps(twin, gains: dict, drifts: list[str], laps: int, first_seed: int) -> list[dict]:
    """``laps`` laps on ``gains``, lap k on noise seed ``first_seed`` + k, with the ``drifts`` (``--drift`` texts)."""
    ds = [Drift.parse(d, twin) for d in drifts]
    runs = run_laps(twin, [{**gains, **{d.address: d.at(k) for d in ds}} for k in range(laps)],
                    seed=[first_seed + k for k in range(laps)])
    pitch = twin.space.get("sensor.pitch")
    def telemetry(r, read):
        return read(r.trace.column("position")[::5], r.trace.count, pitch) if r.trace is not None else None

    return [{"n": k, "completed": r.completed, "gains": gains, "lap_time_s": r.lap_time_s,
             "xte_mean_m": telemetry(r, line_offset_m), "line_side_m": telemetry(r, line_side_m)}
            for k, r in enumerate(runs)]
