"""What a robot says about its laps: the wire lines its firmware sends (:mod:`twin.telemetry.wire`), the JSON Lines
file a run is kept in (:mod:`twin.telemetry.jsonl`), and the laps assembled from wire records and judged for
plausibility (:mod:`twin.telemetry.laps`)."""

from twin.telemetry.jsonl import Telemetry, lap_lines, read_telemetry, telemetry_header, write_telemetry
from twin.telemetry.laps import LapAssembler, RobotLap
from twin.telemetry.wire import Event, Header, LineSplitter, Sample, WireError, decode, encode

__all__ = ["Event", "Header", "LapAssembler", "LineSplitter", "RobotLap", "Sample", "Telemetry", "WireError", "decode",
           "encode", "lap_lines", "read_telemetry", "telemetry_header", "write_telemetry"]
