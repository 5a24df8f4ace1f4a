"""The learned graph drawn for a person: parameters on the left (by partial model), the lap's outputs on the right,
an edge per relation (measured and declared: green; measured only: orange; declared but negligible or not
measurable: grey, dotted), its width the total Sobol' index (or δ); and the indices themselves, per output, with their
95 % intervals. PNG files (matplotlib, no display needed)."""

from __future__ import annotations

import collections
from typing import Sequence

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from tuner.sensitivity.analysis import Analysis  # noqa: E402
from tuner.sensitivity.relations import CONFIRMED, NEGLIGIBLE, UNDECLARED, UNMEASURABLE, Relation  # noqa: E402

STYLE = {CONFIRMED: ("tab:green", "-"), UNDECLARED: ("tab:orange", "-"), NEGLIGIBLE: ("0.6", ":"),
         UNMEASURABLE: ("0.75", ":")}
MODEL_COLOURS = ("tab:blue", "tab:red", "tab:purple", "tab:brown", "tab:olive", "tab:cyan", "tab:pink", "tab:gray")


def _nodes(analysis: Analysis, relations: Sequence[Relation]) -> list[str]:
    """Left-hand nodes: the varied parameters, then one node per model whose parameters a batch cannot vary."""
    left = [f.address for f in analysis.factors]
    for r in relations:
        group = r.parameter.split(".")[0] + ".* (not varied)"
        if r.status == UNMEASURABLE and group not in left:
            left.append(group)
    return left


def graph_chart(path: str, analysis: Analysis, relations: Sequence[Relation], title: str) -> None:
    left = _nodes(analysis, relations)
    outs = list(analysis.outputs)
    y_left = {n: 1 - i / max(1, len(left) - 1) for i, n in enumerate(left)}
    y_right = {o: 1 - (i + 0.5) / len(outs) for i, o in enumerate(outs)}
    models = list(dict.fromkeys(n.split(".")[0] for n in left))
    colour = {m: MODEL_COLOURS[i % len(MODEL_COLOURS)] for i, m in enumerate(models)}
    fig, ax = plt.subplots(figsize=(10, max(5.0, 0.28 * len(left) + 1.5)), dpi=110)
    drawn = collections.Counter()
    for r in relations:
        src = r.parameter if r.parameter in y_left else r.parameter.split(".")[0] + ".* (not varied)"
        key = (src, r.output, r.status)
        if drawn[key]:
            continue  # one edge per group node and output
        drawn[key] += 1
        c, ls = STYLE[r.status]
        width = 0.6 if r.total is None or r.status in (NEGLIGIBLE, UNMEASURABLE) else 0.8 + 6 * max(0.0, r.total)
        ax.plot([0, 1], [y_left[src], y_right[r.output]], color=c, ls=ls, lw=width, alpha=0.85, zorder=1)
    for n, y in y_left.items():
        ax.text(-0.02, y, n, ha="right", va="center", fontsize=8, color=colour[n.split(".")[0]])
        ax.plot([0], [y], "o", ms=4, color=colour[n.split(".")[0]], zorder=2)
    for o, y in y_right.items():
        ax.text(1.02, y, o, ha="left", va="center", fontsize=10, weight="bold")
        ax.plot([1], [y], "s", ms=7, color="k", zorder=2)
    handles = [Line2D([], [], color=STYLE[s][0], ls=STYLE[s][1], lw=2, label=s) for s in STYLE]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.01), ncol=4, fontsize=8, frameon=False)
    ax.set_xlim(-0.55, 1.35)
    ax.set_ylim(-0.06, 1.04)
    ax.axis("off")
    ax.set_title(title + "\nedge width: total Sobol' index (δ over the completed laps where laps failed)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def indices_chart(path: str, analysis: Analysis, title: str) -> None:
    """Per output: S1 and ST of the factors with Sobol' indices, with their 95 % intervals."""
    outs = list(analysis.outputs)
    names = list(analysis.selected)
    fig, axes = plt.subplots(1, len(outs), figsize=(3.2 * len(outs) + 1.5, max(3.0, 0.35 * len(names) + 1.5)),
                             dpi=110, sharey=True)
    axes = list(axes) if len(outs) > 1 else [axes]
    ys = list(range(len(names)))[::-1]
    for ax, o in zip(axes, outs):
        rows = [analysis.influence(n, o) for n in names]
        if not names or all(r is None or r.index is None for r in rows):
            ax.text(0.5, 0.5, "did not vary", ha="center", va="center", transform=ax.transAxes, fontsize=9)
        labelled = False
        for y, r in zip(ys, rows):
            if r is None or r.index is None:
                continue
            (lo, hi), v = r.index_interval, r.index
            ax.barh(y + 0.18, v, height=0.34, color="tab:green" if r.method == "delta" else "tab:blue",
                    label=None if labelled else f"{'δ (completed laps)' if r.method == 'delta' else 'total ST'}")
            ax.errorbar(v, y + 0.18, xerr=[[v - lo], [hi - v]],
                        fmt="none", ecolor="k", lw=0.8, capsize=2)
            ax.barh(y - 0.18, r.first, height=0.34, color="tab:orange", label=None if labelled else "first S1")
            labelled = True
            ax.errorbar(r.first, y - 0.18, xerr=[[r.first - r.first_interval[0]], [r.first_interval[1] - r.first]],
                        fmt="none", ecolor="k", lw=0.8, capsize=2)
        ax.set_title(o, fontsize=9)
        ax.set_xlim(-0.15, 1.15)
        ax.axvline(0, color="0.5", lw=0.5)
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(ys, names, fontsize=8)
    handles, labels = max((ax.get_legend_handles_labels() for ax in axes), key=lambda hl: len(hl[0]))
    if handles:
        axes[-1].legend(handles, labels, fontsize=8, loc="lower right")
    fig.suptitle(title + " (bars: Sobol' index, whiskers: 95 % bootstrap interval)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
