"""The default learned relations: wall and CPU time of ``python -m twin.run graph --learn`` (Morris screening over
every parameter a batch can vary, then Sobol' indices, N = 256 by default) on the default robot and track, run as a
user runs it, in its own process, with its figures read from its ``--json`` document (``wall_s``, ``cpu_s``: the
analysis itself; the process's own CPU, imports included, is measured beside them).

Target: under 10 min on 2 cores.

  python benchmarks/bench_learn.py [--samples 256] [--quick] [--json]

``--quick``: two parameters (motion.mu, motor.R_M), 8 samples (for CI: the script cannot rot; the figures are not
the table's).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

TARGET_S = 600.0
QUICK = ["--param", "motion.mu", "--param", "motor.R_M"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=256, help="Sobol' samples N")
    ap.add_argument("--quick", action="store_true", help="two parameters, 8 samples (for CI)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    if args.samples < 1:
        ap.error(f"--samples {args.samples}: at least 1")
    samples = 8 if args.quick else args.samples
    with tempfile.TemporaryDirectory(prefix="bench-learn-") as folder:
        cmd = [sys.executable, "-m", "twin.run", "graph", "--learn", "--samples", str(samples), "--json",
               "--out-dir", os.path.join(folder, "out"), *(QUICK if args.quick else [])]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True, cwd=folder, timeout=3600)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode != 0:
        raise SystemExit(f"error: {' '.join(cmd[1:])} exited {run.returncode}: {run.stderr.strip()[-300:]}")
    doc = json.loads(run.stdout)
    out = {"samples": samples, "factors": len(doc["factors"]), "sobol_factors": len(doc["sobol_factors"]),
           "laps": doc["laps"], "wall_s": doc["wall_s"], "cpu_s": doc["cpu_s"], "process_wall_s": wall,
           "process_cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
           "within_target": doc["wall_s"] < TARGET_S, "cores": os.cpu_count()}
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"graph --learn, default robot and track, N = {samples}: {out['factors']} parameters screened, "
          f"{out['sobol_factors']} with Sobol' indices, {out['laps']} laps, {out['cores']} cores")
    print(f"  analysis: {out['wall_s']:.1f} s wall, {out['cpu_s']:.1f} s CPU (target < {TARGET_S / 60:.0f} min: "
          f"{'met' if out['within_target'] else 'NOT met'}); the process: {wall:.1f} s wall, "
          f"{out['process_cpu_s']:.1f} s CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
