"""One lap's parameters in a batch of laps: the twin's values with some addresses changed.

A variant is derived from a mapping of values and never written to the twin, so the twin's space and model
are the same before, during and after a batch (and another thread reading the twin sees its own values).
"""

from __future__ import annotations

import dataclasses
from typing import Mapping

from line_sensor.reflectance import SensorModel
from mjcf.world import PhysicsOptions
from motors import MotorConstants
from twin.model.control import ControlParams
from twin.model.power import Power
from twin.model.timing import Timing
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.model.space import ChangeCost


def field_key(twin: DigitalTwin, values: Mapping[str, float]) -> tuple:
    """The model-field values (``motion.*``, ``motor.*``): laps with equal keys simulate one model."""
    return tuple(v for a, v in values.items() if twin.space.parameter(a).cost is ChangeCost.MODEL_FIELD)


@dataclasses.dataclass(frozen=True)
class Variant:
    """What one lap runs: every address's value, and the firmware, sensor, motor and physics they give."""

    values: dict[str, float]
    params: ControlParams
    sensor: SensorModel
    motor: MotorConstants
    physics: PhysicsOptions
    timing: Timing
    power: Power
    field_key: tuple

    @classmethod
    def of(cls, twin: DigitalTwin, changes: Mapping[str, float]) -> "Variant":
        """The twin's values with ``changes`` (checked as :meth:`DigitalTwin.set` checks them)."""
        values = twin.checked_values(changes)
        base = twin.space.values
        for address in changes:
            if twin.space.parameter(address).cost is ChangeCost.REBUILD and values[address] != base[address]:
                raise TwinError(
                    f"{address}: rebuilds the robot or track, so it cannot vary between the laps of one batch"
                )
        if (values["motor.L_M"] > 0) != (base["motor.L_M"] > 0):  # adds or removes the motors' current state
            raise TwinError("motor.L_M: switching between zero and non-zero rebuilds the model, so it cannot vary "
                            "between the laps of one batch")
        return cls(values, twin.control_params(values), twin.sensor_model(values), twin.motor(values),
                   twin.physics(values), twin.timing(values), twin.power(values), field_key(twin, values))

    def calibration_key(self, seed: int) -> tuple:
        """Everything the calibration turn depends on: physics fields, sensor model, geometry and turn settings,
        the seed. Not the gains: the turn does not use them."""
        turn = dataclasses.replace(self.params, v_max=0.0, k_b=0.0, k_p=0.0, k_i=0.0, k_d=0.0, accel_max=0.0,
                                   integral_limit=0.0)
        return self.field_key, dataclasses.astuple(self.sensor), turn, dataclasses.astuple(self.timing), int(seed)
