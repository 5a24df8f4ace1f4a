"""The common model space (paper §2, §3.8).

Each partial model declares its input and output ports and its parameters, with units. The space

* derives the **input/output** relations by matching an output port of one model with the input port of
  the same name on another;
* holds the declared **influences** relations (a change in one model invalidates another);
* gives every parameter one address ``model.name`` (``cad.L``, ``motion.mu``) to read and write, and
  says what a change costs: rebuilding URDF and MJCF, editing compiled model fields, or only the
  controller's parameters.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import math
from typing import Iterable

from twin.errors import TwinError


class ChangeCost(enum.Enum):
    """What a parameter change invalidates, cheapest last."""

    REBUILD = "rebuild URDF and MJCF"
    MODEL_FIELD = "edit compiled model fields"
    CONTROLLER = "controller parameters only"


@dataclasses.dataclass(frozen=True)
class Port:
    """A signal a model takes or produces. ``unit`` in SI; ``shape`` as words (e.g. "2: left, right")."""

    name: str
    unit: str
    description: str = ""


@dataclasses.dataclass(frozen=True)
class Parameter:
    """A named, bounded scalar parameter of one partial model.

    Attributes:
      name: name within its model (the address is ``model.name``).
      unit: SI unit, "-" for dimensionless.
      default: nominal value.
      lower, upper: allowed closed range.
      cost: what a change invalidates.
      description: what it is, with its source where it has one.
      strictly_positive: lower bound is exclusive (e.g. masses).
      integer: only whole numbers (e.g. a sensor count).
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    cost: ChangeCost
    description: str = ""
    strictly_positive: bool = False
    integer: bool = False

    def check(self, address: str, value: float) -> float:
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise TwinError(f"{address}: not a number: {value!r}") from None
        if not math.isfinite(v):
            raise TwinError(f"{address}: must be finite, got {value!r}")
        unit = "" if self.unit in ("", "-") else f" {self.unit}"  # (a ratio's unit "-" reads as a stray dash)
        if self.strictly_positive and v <= 0:
            raise TwinError(f"{address}: must be > 0, got {v:g}{unit}")
        if not (self.lower <= v <= self.upper):
            raise TwinError(f"{address}: {v:g}{unit} is outside [{self.lower:g}, {self.upper:g}]")
        if self.integer and v != round(v):
            raise TwinError(f"{address}: must be a whole number, got {v:g}")
        return v


@dataclasses.dataclass(frozen=True)
class PartialModel:
    """One partial model: ports, parameters, and what realises it in code."""

    name: str
    description: str
    inputs: tuple[Port, ...] = ()
    outputs: tuple[Port, ...] = ()
    parameters: tuple[Parameter, ...] = ()
    realised_by: str = ""


@dataclasses.dataclass(frozen=True)
class Relation:
    """``kind`` is "input/output" (source's output port feeds target's input port) or "influences"."""

    kind: str
    source: str
    target: str
    port: str = ""
    reason: str = ""


class ModelSpace:
    """Partial models joined by their relations, with one address per parameter.

    Args:
      models: the partial models; names must be unique.
      influences: (source model, target model, reason) triples.
    """

    def __init__(self, models: Iterable[PartialModel], influences: Iterable[tuple[str, str, str]] = ()):
        self.models: dict[str, PartialModel] = {}
        for m in models:
            if m.name in self.models:
                raise TwinError(f"model space: two models named {m.name!r}")
            self.models[m.name] = m
        self._params: dict[str, Parameter] = {}
        for m in self.models.values():
            for p in m.parameters:
                self._params[f"{m.name}.{p.name}"] = p
        self.values: dict[str, float] = {a: p.default for a, p in self._params.items()}
        self.influences = []
        for src, dst, reason in influences:
            for n in (src, dst):
                if n not in self.models:
                    raise TwinError(f"model space: influence names unknown model {n!r}")
            self.influences.append(Relation("influences", src, dst, reason=reason))

    # --- parameters
    @property
    def addresses(self) -> list[str]:
        return list(self._params)

    def parameter(self, address: str) -> Parameter:
        try:
            return self._params[address]
        except KeyError:
            close = difflib.get_close_matches(address, self._params, n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            raise TwinError(f"{address}: unknown parameter address{hint}") from None

    def get(self, address: str) -> float:
        self.parameter(address)
        return self.values[address]

    def set(self, address: str, value: float) -> ChangeCost:
        """Check and store a value; returns what the change costs."""
        p = self.parameter(address)
        self.values[address] = p.check(address, value)
        return p.cost

    def update(self, changes: dict[str, float]) -> set[ChangeCost]:
        """Set several values, all checked before any is stored."""
        checked = {a: self.parameter(a).check(a, v) for a, v in changes.items()}
        self.values.update(checked)
        return {self._params[a].cost for a in checked}

    def model_values(self, model: str) -> dict[str, float]:
        """{name: value} of one model's parameters."""
        return {p.name: self.values[f"{model}.{p.name}"] for p in self.models[model].parameters}

    # --- relations
    def io_relations(self) -> list[Relation]:
        """Output port of one model → input port of the same name on another."""
        out = []
        for src in self.models.values():
            for port in src.outputs:
                for dst in self.models.values():
                    if dst is not src and any(p.name == port.name for p in dst.inputs):
                        out.append(Relation("input/output", src.name, dst.name, port=port.name))
        return out

    def relations(self) -> list[Relation]:
        return self.io_relations() + list(self.influences)

    def unconnected_inputs(self) -> list[tuple[str, str]]:
        """(model, port) inputs no model produces: the space's external inputs."""
        produced = {p.name for m in self.models.values() for p in m.outputs}
        return [(m.name, p.name) for m in self.models.values() for p in m.inputs if p.name not in produced]

    # --- export
    def to_dict(self) -> dict:
        return {
            "models": [
                {
                    "name": m.name,
                    "description": m.description,
                    "realised_by": m.realised_by,
                    "inputs": [dataclasses.asdict(p) for p in m.inputs],
                    "outputs": [dataclasses.asdict(p) for p in m.outputs],
                    "parameters": [
                        {
                            "address": f"{m.name}.{p.name}",
                            "value": self.values[f"{m.name}.{p.name}"],
                            "unit": p.unit,
                            "default": p.default,
                            "range": [p.lower, p.upper],
                            "change_cost": p.cost.name.lower(),
                            "description": p.description,
                        }
                        for p in m.parameters
                    ],
                }
                for m in self.models.values()
            ],
            "relations": [dataclasses.asdict(r) for r in self.relations()],
            "external_inputs": [f"{m}.{p}" for m, p in self.unconnected_inputs()],
        }

    def describe(self) -> str:
        """A human-readable listing: models, ports, parameters with values and units, relations."""
        lines = []
        for m in self.models.values():
            lines.append(f"{m.name}: {m.description}  [{m.realised_by}]")
            for kind, ports in (("in ", m.inputs), ("out", m.outputs)):
                for p in ports:
                    lines.append(f"  {kind} {p.name} [{p.unit}]  {p.description}")
            for p in m.parameters:
                v = self.values[f"{m.name}.{p.name}"]
                lines.append(f"  par {m.name}.{p.name} = {v:.6g} {p.unit}  ({p.cost.value})  {p.description}")
        lines.append("relations:")
        for r in self.io_relations():
            lines.append(f"  {r.source} --{r.port}--> {r.target}")
        for r in self.influences:
            lines.append(f"  {r.source} ~influences~> {r.target}: {r.reason}")
        ext = self.unconnected_inputs()
        if ext:
            lines.append("external inputs: " + ", ".join(f"{m}.{p}" for m, p in ext))
        return "\n".join(lines)
