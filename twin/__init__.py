"""The digital twin of a line-following robot, in rooms (``docs/architecture.md`` draws them):

* :mod:`twin.model`: the common model space, the partial models' declarations and parameters, the control model
  (the firmware's Python reference), tracks, motors on a twin, parameter files;
* :mod:`twin.core`: the twin itself (model-space values → a compiled MuJoCo world), the C core's Python face, laps
  in closed loop and their judge;
* :mod:`twin.telemetry`: what a robot says: the wire lines, the JSON Lines file, laps assembled from them;
* :mod:`twin.pil`: the robot's firmware binary in the loop (AVR build, simavr MCU, PIL laps);
* :mod:`twin.link`: the serial link to the robot, and the emulated robot at its other end;
* :mod:`twin.viz`: rerun recordings and viewers;
* :mod:`twin.cli`: the one command-line layer (``python -m twin.run``).

Arrows point one way: model ← core ← telemetry ← pil ← link; viz reads core and telemetry; cli reads all.
Importing ``twin`` loads nothing at all (``python -m twin.run`` handles Ctrl-C from its first instant, and the package
is imported before that handler is installed); ``TwinError`` loads on first use.
"""

__all__ = ["TwinError"]


def __getattr__(name: str):
    if name == "TwinError":
        from twin.errors import TwinError

        return TwinError
    raise AttributeError(f"module 'twin' has no attribute {name!r}")
