"""The twin in co-simulation (FMI): the twin exported as a Co-Simulation FMU (:func:`export_fmu`: the plant, or the
closed loop with its firmware; FMI 2.0 or 3.0, linux64, built from the same C core as the lap), and third-party
controller FMUs driving the twin in its own loop (:class:`ControllerFmu`, :func:`run_controller_lap`), each in a
process of its own behind a wall (:class:`WalledController`: a hang, a crash, an exit or a NaN is one error line).

The names load on first use: the controller's own process (``python -m twin.fmi.host``) imports this package and
must not pay for MuJoCo."""

__all__ = ["CLOSED_LOOP", "DRIVE_PORTS", "ControllerFmu", "ExportedFmu", "KINDS", "PLANT", "Variable",
           "WalledController", "export_fmu", "fmu_is_ours", "fmu_variables", "Link", "parse_map", "parse_params",
           "read_multi_model", "run_controller_lap", "sense_ports"]


def __getattr__(name: str):
    if name in ("DRIVE_PORTS", "ControllerFmu", "sense_ports"):
        from twin.fmi import controller as module
    elif name in ("Link", "parse_map"):
        from twin.fmi import mapping as module
    elif name == "parse_params":
        from twin.fmi import parameters as module
    elif name == "read_multi_model":
        from twin.fmi import multi_model as module
    elif name == "run_controller_lap":
        from twin.fmi import controller_lap as module
    elif name in ("ExportedFmu", "export_fmu", "fmu_is_ours"):
        from twin.fmi import export as module
    elif name in ("CLOSED_LOOP", "KINDS", "PLANT", "Variable", "fmu_variables"):
        from twin.fmi import variables as module
    elif name == "WalledController":
        from twin.fmi import wall as module
    else:
        raise AttributeError(f"module 'twin.fmi' has no attribute {name!r}")
    return getattr(module, name)
