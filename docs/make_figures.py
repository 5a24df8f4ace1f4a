"""Regenerate the README's figures from the project's own commands, into ``docs/figures/``.

    .venv/bin/python docs/make_figures.py            # about 4 minutes on 2 cores

* ``lap_viewer.png``: ``twin.run lap --save`` opened in rerun's web viewer (headless Chromium, see
  :mod:`twin.viz.web_viewer`; needs Debian's ``chromium`` and the ``test`` extra's Playwright).
* ``tuning_trace.png``: ``python -m tuner --robust --json``: the cost and each scenario's worst lap per iteration.
* ``design_lap_times.png``, ``design_pareto.png``: the charts ``twin.run design`` writes.

The folder is replaced as a whole, atomically (it is this script's; a folder it did not write is refused).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from lf_common.files import output_dir  # noqa: E402

RUN = [sys.executable, "-m", "twin.run"]
STEP_LIMIT_S = 900  # [s] per command: nothing hangs


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def run(args: list[str], what: str) -> str:
    """Run one of the project's commands; its stdout (the --json document)."""
    say(f"[{time.strftime('%H:%M:%S')}] {what}: {' '.join(args)}")
    r = subprocess.run([*RUN, *args], stdout=subprocess.PIPE, stderr=None, text=True, timeout=STEP_LIMIT_S)
    if r.returncode not in (0, 1):  # 1: a lap that failed is still a result
        sys.exit(f"error: {what} exited {r.returncode}")
    return r.stdout


def lap_in_viewer(work: str, out: str) -> None:
    from twin.viz.web_viewer import headless_chromium, screenshot_when_settled, served

    rrd = os.path.join(work, "lap.rrd")
    run(["lap", "--save", rrd, "--json"], "a lap")
    say("  screenshot of the web viewer")
    with headless_chromium() as browser, served(rrd) as url:
        page = browser.new_page(viewport={"width": 1600, "height": 900}, device_scale_factor=1)
        page.goto(url, timeout=60_000)
        if not screenshot_when_settled(page, os.path.join(out, "lap_viewer.png"), min_wait_s=10):
            say("  warning: the viewer kept changing; kept the last screenshot")


def tuning_trace(work: str, out: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    doc = json.loads(run(["tune", "--robust", "--json", "-q", "-o", os.path.join(work, "gains.json")],
                         "robust tuning"))
    its = doc["per_iteration"]
    k = [it["iteration"] for it in its]
    fig, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    ax.plot(k, [it["cost_s"] for it in its], color="0.75", lw=7, label="cost (worst lap, failures penalised)")
    for i, name in enumerate(s["scenario"] for s in its[0]["scenarios"]):
        worst = [max(s["lap_times_s"]) for it in its for s in it["scenarios"] if s["scenario"] == name]
        ax.plot(k, worst, lw=1.5, marker="o", ms=4, ls=("-", "--", "-.", ":")[i % 4], label=f"{name}: worst lap")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_xlabel("iteration")
    ax.set_ylabel("lap time [s]")
    ax.set_title(f"python -m tuner --robust: {doc['iterations']} iterations, {doc['laps_simulated']} laps "
                 f"in {doc['wall_s']:.0f} s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(os.path.join(out, "tuning_trace.png"), dpi=120)
    plt.close(fig)


def design_charts(work: str, out: str) -> None:
    study = os.path.join(work, "study")
    run(["design", "--out-dir", study, "--json", "-q"], "design study")
    for name in ("lap_times.png", "pareto.png"):
        shutil.copyfile(os.path.join(study, name), os.path.join(out, f"design_{name}"))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--out-dir", default=os.path.join(HERE, "figures"), help="folder to (re)write")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as work, output_dir(args.out_dir, "figures folder") as out:
        lap_in_viewer(work, out)
        tuning_trace(work, out)
        design_charts(work, out)
    say(f"wrote {args.out_dir}")


if __name__ == "__main__":
    main()
