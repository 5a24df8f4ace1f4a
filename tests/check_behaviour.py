"""Behaviour unchanged across a refactor: record the JSON of three commands, later compare bit for bit.

    python tests/check_behaviour.py record DIR    # on the commit before the change
    python tests/check_behaviour.py compare DIR   # after it: exit 1 and the differing keys if any

The commands are ``lap --json``, ``tune --json`` (default seed) and ``align --measured-lap-time 13.165 --json``.
Wall-clock fields (``wall_s``) and output paths are dropped; every other value, floats included, must be equal.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

COMMANDS = {
    "lap": ["lap", "--json"],
    "tune": ["tune", "--json"],
    "align": ["align", "--measured-lap-time", "13.165", "--json"],
}
VOLATILE = {"wall_s", "out", "recording"}


def strip(value):
    if isinstance(value, dict):
        return {k: strip(v) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [strip(v) for v in value]
    return value


def run(args: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as tmp:  # tune writes its gains file into the working folder
        done = subprocess.run([sys.executable, "-m", "twin.run", *args], capture_output=True, text=True, cwd=tmp,
                              env={**os.environ, "PYTHONPATH": os.getcwd()}, timeout=600)
    if done.returncode != 0:
        sys.exit(f"{' '.join(args)} failed: {done.stderr.strip().splitlines()[-1:]}")
    return strip(json.loads(done.stdout))


def differences(a, b, path="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b)) for d in differences(a.get(k), b.get(k), f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def main() -> int:
    if len(sys.argv) != 3 or sys.argv[1] not in ("record", "compare"):
        sys.exit(__doc__)
    mode, folder = sys.argv[1:]
    os.makedirs(folder, exist_ok=True)
    failed = 0
    for name, args in COMMANDS.items():
        path = os.path.join(folder, f"{name}.json")
        now = run(args)
        if mode == "record":
            with open(path, "w") as f:
                json.dump(now, f, indent=1)
            print(f"recorded {name}")
            continue
        with open(path) as f:
            diffs = differences(json.load(f), now)
        failed += bool(diffs)
        print(f"{name}: {'identical' if not diffs else f'{len(diffs)} differences'}")
        for d in diffs[:20]:
            print("   ", d)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
