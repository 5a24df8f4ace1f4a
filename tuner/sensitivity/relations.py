"""The learned graph against the declared one (paper §2, §5).

**Declared** (what ``graph`` shows, by hand): a parameter feeds its own partial model, and that model feeds the
models its declared relations (input/output ports and influences) point to. A lap's outputs are computed from
ports (:data:`OUTPUT_PORTS`: the lap time, completion and cross-track error from the pose, completion also from
the sensor readings, which say whether the line is lost; the energy from the motor's current and voltage), so a
parameter is declared to govern an output when its model produces one of those ports or has a declared relation
into a model that does: one edge of the declared graph, as a person reading it would follow it.

**Measured**: the output's total Sobol' index (or, for an output failed laps do not give, Borgonovo's δ over the
completed laps) is at least 0.05 with its 95 % interval above 0 (δ: above a dummy factor's)
(:attr:`tuner.sensitivity.analysis.Influence.measured`).

Each (parameter, output) pair is then

* ``confirmed``: declared and measured;
* ``measured, not declared``: the closed loop carries it, but no declared edge says so (the path through the
  declared relations is given);
* ``declared, negligible``: declared, but it does not move the output over the parameter's range (screened out, or
  its total index is small), or the output did not vary (every lap completed);
* ``declared, not measurable``: declared, but a batch of laps cannot vary the parameter (it rebuilds the robot or
  track, is a whole number, a numerical setting), or the analysis left it out.
"""

from __future__ import annotations

import collections
import dataclasses

from twin.model.space import ModelSpace
from tuner.sensitivity.analysis import Analysis
from tuner.sensitivity.ranges import why_not_varied

OUTPUT_PORTS: dict[str, tuple[str, ...]] = {
    "lap_time_s": ("pose",),
    "completed": ("pose", "sensor_readings"),
    "energy_j": ("motor_current", "motor_voltage"),
    "max_cross_track_m": ("pose",),
}
CONFIRMED, UNDECLARED, NEGLIGIBLE, UNMEASURABLE = ("confirmed", "measured, not declared", "declared, negligible",
                                                   "declared, not measurable")


@dataclasses.dataclass(frozen=True)
class Relation:
    """One (parameter, output) pair and its status; ``total`` is the measured index, ST or δ as ``index`` says (None
    if not measured); ``why`` the declared path or the reason it is not measurable."""

    parameter: str
    output: str
    status: str
    total: float | None
    why: str
    index: str = "ST"


def producers(space: ModelSpace, output: str) -> set[str]:
    """The models whose output ports a lap output is computed from."""
    ports = OUTPUT_PORTS[output]
    return {m.name for m in space.models.values() if any(p.name in ports for p in m.outputs)}


def _edges(space: ModelSpace) -> dict[str, set[str]]:
    out: dict[str, set[str]] = collections.defaultdict(set)
    for r in space.relations():
        out[r.source].add(r.target)
    return out


def declared(space: ModelSpace, model: str, output: str) -> bool:
    """The model produces the output's port or has a declared relation into a model that does."""
    targets = producers(space, output)
    return model in targets or bool(_edges(space)[model] & targets)


def declared_path(space: ModelSpace, model: str, output: str) -> str:
    """The shortest chain of declared relations from ``model`` to a model the output is computed from."""
    edges, targets = _edges(space), producers(space, output)
    queue, seen = collections.deque([[model]]), {model}
    while queue:
        path = queue.popleft()
        if path[-1] in targets:
            return " → ".join(path)
        for nxt in sorted(edges[path[-1]] - seen):
            seen.add(nxt)
            queue.append(path + [nxt])
    return "no declared path"


def compare(space: ModelSpace, analysis: Analysis) -> list[Relation]:
    """Every (parameter, output) pair that is declared or measured, with its status (see the module docstring)."""
    varied = {f.address for f in analysis.factors}
    left_out = analysis.extra.get("left_out", {})
    out = []
    for address in space.addresses:
        model = address.split(".")[0]
        for o in analysis.outputs:
            decl = declared(space, model, o)
            if address not in varied:
                if decl:
                    why = why_not_varied(space, address) or left_out.get(address) or "not varied in this analysis"
                    out.append(Relation(address, o, UNMEASURABLE, None, why))
                continue
            infl = analysis.influence(address, o)
            if infl.measured:
                status = CONFIRMED if decl else UNDECLARED
                why = declared_path(space, model, o)
                out.append(Relation(address, o, status, infl.index, why, infl.index_name))
            elif decl:
                stats = analysis.summary.get(o) or {}
                if not stats:
                    why = "the output has no values (no lap completed)"
                elif stats["std"] == 0:
                    why = "the output did not vary: every lap gave the same"
                elif infl.method == "morris":
                    why = f"screened out by Morris (μ* {infl.mu_star:.3g})"
                else:
                    lo, hi = infl.index_interval
                    why = f"{infl.index_name} {infl.index:.3f} [{lo:.3f}, {hi:.3f}]" + (
                        f", dummy factor's δ {infl.floor:.3f}" if infl.method == "delta" else "")
                out.append(Relation(address, o, NEGLIGIBLE, infl.index, why, infl.index_name))
    return out


def by_status(relations: list[Relation]) -> dict[str, list[Relation]]:
    groups: dict[str, list[Relation]] = {s: [] for s in (CONFIRMED, UNDECLARED, NEGLIGIBLE, UNMEASURABLE)}
    for r in relations:
        groups[r.status].append(r)
    return groups


SYMBOL = {CONFIRMED: "✓", UNDECLARED: "+", NEGLIGIBLE: "·", UNMEASURABLE: "×"}


def table(space: ModelSpace, analysis: Analysis, relations: list[Relation]) -> list[str]:
    """The comparison as text: one row per varied parameter (✓ confirmed, + measured but not declared, · declared
    but negligible, with the total index), then the parameters a batch cannot vary, one row per model and reason."""
    cell = {(r.parameter, r.output): r for r in relations}
    width = max(len(f.address) for f in analysis.factors)
    head = f"{'parameter':{width}s}  " + "  ".join(f"{o:>17s}" for o in analysis.outputs)
    lines = [head]
    for f in analysis.factors:
        cells = []
        for o in analysis.outputs:
            r = cell.get((f.address, o))
            if r is None:
                cells.append(f"{'':>17s}")
            elif r.total is not None and r.status != NEGLIGIBLE:
                mark = "δ" if r.index == "δ" else ""
                cells.append(f"{SYMBOL[r.status]} {mark}{r.total:>5.2f}".rjust(17))
            else:
                cells.append(SYMBOL[r.status].rjust(17))
        lines.append(f"{f.address:{width}s}  " + "  ".join(cells))
    groups: dict[tuple[str, str], list[str]] = collections.defaultdict(list)
    for r in relations:
        if r.status == UNMEASURABLE and r.parameter not in groups.get((r.parameter.split(".")[0], r.why), []):
            groups[(r.parameter.split(".")[0], r.why)].append(r.parameter)
    for (model, why), params in groups.items():
        outs = sorted({r.output for r in relations if r.parameter in params and r.status == UNMEASURABLE})
        lines.append(f"× {', '.join(params)}: {why} (declared for {', '.join(outs)})")
    lines.append("✓ confirmed  + measured, not declared  · declared, negligible  × declared, not measurable; "
                 "numbers: total Sobol' index, δ: Borgonovo's δ over the completed laps")
    return lines
