"""The one home of reference gains: what ``tune`` answers today, tuned when asked (``tuned_gains``), never a copy.

The tests' session fixtures ``plain_gains`` and ``robust_gains`` (conftest.py) and the benchmarks that need tuned or
robust gains (``sys.path`` to this folder, as ``bench_fmu.py`` does for fmu_helpers) all call it, so no gain set held
in a file can drift away from the tuner's current answer. Not a test module.

One gain set is held on purpose instead (``PLAIN_HELD``): the tests and benchmarks of wear, acting and forecasts
need gains that fail at a known place in a drift's range whatever the tuner answers tomorrow, and they share it, so
the races the twin runs for those gains (its session cache) are run once for all of them."""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import sys
import tempfile

from twin.cli.main import main


def code_digest() -> str:
    """What the tuner's answer depends on beside its flags: every file of every package of ours (source, the C
    core, tracks and robot data), not their bytecode."""
    import twin
    from lf_common.files import files_digest

    top = os.path.dirname(os.path.dirname(os.path.abspath(twin.__file__)))
    return files_digest([os.path.join(root, name) for package in PACKAGES
                         for root, dirs, names in os.walk(os.path.join(top, package)) if "__pycache__" not in root
                         for name in names if not name.endswith(".pyc")], top)


# held, not tuned: aggressive gains (tune's plain answer of an earlier day) whose laps begin to fail below μ ≈ 0.73,
# inside the grip drifts the tests and benchmarks run, and come and go below that (tests/test_failure_model.py)
PLAIN_HELD = {"control.v_max": 1.5, "control.kb": 0.125, "control.kp": 33.52, "control.ki": 0.0, "control.kd": 1.118}

PACKAGES = ("lf_common", "line_sensor", "mjcf", "motors", "tuner", "twin")


def tuned_gains(*flags: str) -> dict[str, float]:
    """The gains ``python -m tuner -q FLAGS`` writes (default robot and track unless ``flags`` say otherwise; e.g.
    ``"--robust"``, ``"--track", "oval"``, ``"--max-iter", "1"``), by address. Tuned once per code and flags: the
    answer is kept in ``$LF_REFERENCE_GAINS_DIR`` (the tests' run sets it for both its processes) or the cache
    folder's ``reference-gains/``, and every process that asks (the test processes, the benchmarks they start)
    reads it, one tuning at a time (a lock), instead of tuning again."""
    from lf_common.cache import cache_dir

    key = hashlib.sha256(json.dumps([code_digest(), sys.version, list(flags)]).encode()).hexdigest()[:32]
    folder = os.environ.get("LF_REFERENCE_GAINS_DIR") or os.path.join(cache_dir(), "reference-gains")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, key + ".json")
    with open(os.path.join(folder, key + ".lock"), "w") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX)  # another process tuning the same: wait for its answer
        if os.path.isfile(path):
            with open(path) as f:
                return json.load(f)["gains"]
        gains = _tune(flags)
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "w") as f:
            json.dump({"flags": list(flags), "gains": gains}, f)
        os.replace(tmp, path)
        return gains


def _tune(flags) -> dict[str, float]:
    with tempfile.TemporaryDirectory(prefix="tuned-") as folder:
        path = os.path.join(folder, "gains.json")
        with contextlib.redirect_stdout(sys.stderr):  # its summary: a caller's stdout may be one JSON document
            status = main(["tune", "-q", "-o", path, *flags])
        if status != 0:
            raise RuntimeError(f"tune {' '.join(flags)} exited {status}")
        with open(path) as f:
            return json.load(f)["gains"]


def set_flags(gains: dict[str, float]) -> list[str]:
    """``gains`` as the ``--set ADDRESS=VALUE`` flags of a command, at full precision."""
    return [w for a, v in gains.items() for w in ("--set", f"{a}={v!r}")]
