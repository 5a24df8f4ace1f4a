"""How a lap whose motors' supply failed says so (twin.model.power): a regulator that does not start on its battery,
or one that shut off under load."""

from __future__ import annotations

from twin.model.power import Power


def does_not_start(power: Power) -> str | None:
    """Why the motors' regulator does not start on the battery at rest, or None if it does (or there is none)."""
    if power.starts():
        return None
    return (f"motor.supply_voltage: the battery's {power.battery_v:g} V is below the motors' regulator's lowest input "
            f"{power.regulator_min_input_v:g} V (power.regulator_min_input): it does not start")


def shut_off(power: Power, sim) -> str:
    """Why the motors' regulator shut off in ``sim`` (an ``lf_sim`` head: its lowest terminal voltage)."""
    return (f"the motors' regulator shut off: the battery's terminal voltage fell to {sim.terminal_min_v:.3f} V under "
            f"load, below its {power.regulator_min_input_v:g} V minimum (power.regulator_min_input; motor.supply_voltage "
            f"{power.battery_v:g} V, power.source_resistance {power.source_ohm:g} Ω)")
