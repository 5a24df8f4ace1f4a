"""What a robot says about its laps: the wire lines its firmware sends (:mod:`twin.telemetry.wire`), the JSON Lines
file a run is kept in (:mod:`twin.telemetry.jsonl`), and the laps assembled from wire records and judged for
plausibility (:mod:`twin.telemetry.laps`); the commands the twin sends back and the robot's answers are wire lines too."""

from twin.telemetry.jsonl import Telemetry, lap_lines, read_telemetry, telemetry_header, write_telemetry
from twin.telemetry.laps import LapAssembler, RobotLap
from twin.telemetry.wire import (Boot, Command, Event, Header, LineSplitter, Reply, Sample, UnknownCommand, WireError,
                                  decode, encode, gains_from_wire, gains_to_wire, on_the_wire)

__all__ = ["Boot", "Command", "Event", "Header", "LapAssembler", "LineSplitter", "Reply", "RobotLap", "Sample", "Telemetry",
           "UnknownCommand", "WireError", "decode", "encode", "gains_from_wire", "gains_to_wire", "lap_lines",
           "on_the_wire", "read_telemetry", "telemetry_header", "write_telemetry"]
