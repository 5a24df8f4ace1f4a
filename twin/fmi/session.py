"""One run of a controller FMU through fmpy: extracted to a folder (a temporary one unless given), instantiated and
initialised at time 0, stepped tick by tick, freed (and a temporary folder removed) at :meth:`ControllerSession.close`.
Its log goes to the ``twin.fmi.controller`` logger; a failed call becomes one TwinError line with the FMU's last
message. It runs in the controller's own process (:mod:`twin.fmi.host`), behind the twin's wall."""

from __future__ import annotations

import collections
import ctypes
import logging
import tempfile
from typing import Mapping

from twin.errors import TwinError

log = logging.getLogger("twin.fmi.controller")
STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")
LEVEL = (logging.DEBUG, logging.WARNING, logging.WARNING, logging.ERROR, logging.ERROR, logging.INFO)
_SETTERS = {2: {"Real": "setReal", "Integer": "setInteger", "Boolean": "setBoolean"},
            3: {"Float64": "setFloat64", "Float32": "setFloat32", "Int32": "setInt32", "Int64": "setInt64",
                "Int16": "setInt16", "Int8": "setInt8", "UInt8": "setUInt8", "UInt16": "setUInt16",
                "UInt32": "setUInt32", "UInt64": "setUInt64", "Boolean": "setBoolean"}}


def _text(b) -> str:
    return b.decode("utf-8", "replace") if isinstance(b, bytes) else str(b)


class ControllerSession:
    """A running controller FMU (see :class:`twin.fmi.controller.ControllerFmu`).

    Args:
      controller: what runs: its ``path``, ``md`` (fmpy's model description), ``fmi_version``, ``sense`` ({FMU input:
        twin port}), ``drive`` ({twin drive port: FMU output}) and ``parameters`` ([(name, typed value)], set after
        instantiation, before the initialisation).
      folder: an empty folder to extract the FMU into (the caller removes it); None: a temporary one.
    """

    def __init__(self, controller, folder: str | None = None):
        from fmpy import extract

        self.controller, self.path, self.version = controller, controller.path, controller.fmi_version
        self.messages: collections.deque[str] = collections.deque(maxlen=3)
        self.fmu = None
        self._tmp = None if folder else tempfile.TemporaryDirectory(prefix="twin-controller-")
        md = controller.md
        try:
            folder = extract(self.path, unzipdir=folder or self._tmp.name)
            if self.version == 2:
                from fmpy.fmi2 import FMU2Slave as cls
                token = md.guid
            else:
                from fmpy.fmi3 import FMU3Slave as cls
                token = md.instantiationToken
            self.fmu = cls(guid=token, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                           instanceName="controller")
            if self.version == 2:
                self.fmu.instantiate(callbacks=self._fmi2_callbacks())
                self.fmu.setupExperiment(startTime=0.0)
                self._set_parameters(md, controller.parameters)
                self.fmu.enterInitializationMode()
            else:
                self.fmu.instantiate(logMessage=self._log3)
                self._set_parameters(md, controller.parameters)
                self.fmu.enterInitializationMode(startTime=0.0)
            self.fmu.exitInitializationMode()
        except TwinError:
            self.close()
            raise
        except Exception as e:
            self.close()
            raise self._error("it failed to load or initialise", e) from None
        by_name = {v.name: v for v in md.modelVariables}
        self._inputs = []  # (setter, type, [vr], [FMU input]) per type
        groups: dict[str, tuple[list, list]] = {}
        for name in controller.sense:
            v = by_name[name]
            vrs, names = groups.setdefault(v.type, ([], []))
            vrs.append(v.valueReference)
            names.append(name)
        for type_, (vrs, names) in groups.items():
            self._inputs.append((getattr(self.fmu, _SETTERS[self.version][type_]), type_, vrs, names))
        outs = [by_name[controller.drive[p]] for p in sorted(controller.drive)]  # *_left before *_right
        self._outputs = [(self._getter(v.type), v.valueReference) for v in outs]

    def _set_parameters(self, md, parameters) -> None:
        """The twin's parameter values (checked against the FMU's types by :mod:`twin.fmi.parameters`)."""
        by_name = {v.name: v for v in md.modelVariables}
        for name, value in parameters:
            v = by_name[name]
            type_ = "Integer" if self.version == 2 and v.type == "Enumeration" else v.type
            setter = _SETTERS[self.version].get(type_) or ("setString" if type_ == "String" else "setInt64")
            try:
                getattr(self.fmu, setter)([v.valueReference], [value])
            except Exception as e:
                raise self._error(f"it refused its parameter {name} = {value!r}", e) from None

    def _getter(self, type_: str):
        if self.version == 2:
            return getattr(self.fmu, "getReal" if type_ == "Real" else "getInteger")
        return getattr(self.fmu, f"get{type_}")

    def _fmi2_callbacks(self):
        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)
        from fmpy.logging import addLoggerProxy

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(ctypes.byref(callbacks))
        self._callbacks = callbacks  # kept from the garbage collector while the FMU lives
        return callbacks

    def _log2(self, env, instance, status, category, message) -> None:
        self._log(status, message)

    def _log3(self, env, status, category, message) -> None:
        self._log(status, message)

    def _log(self, status: int, message) -> None:
        text = " ".join(_text(message).split())
        if status >= 1:
            self.messages.append(text)
        log.log(LEVEL[status] if 0 <= status < len(LEVEL) else logging.ERROR, "controller FMU: %s", text)

    def _error(self, what: str, e: Exception) -> TwinError:
        said = f"; it said: {self.messages[-1]}" if self.messages else ""
        return TwinError(f"--controller-fmu {self.path}: {what} ({' '.join(str(e).split())[:200]}){said}")

    def step(self, t: float, h: float, values: Mapping[str, float]) -> tuple[float, float]:
        """Set the inputs (``values`` by the FMU's names) read at ``t`` [s], step the FMU to ``t + h``, and return its
        (left, right) outputs."""
        try:
            for setter, type_, vrs, names in self._inputs:
                if type_ == "Boolean":
                    setter(vrs, [bool(values[n] > 0) for n in names])
                elif type_ in ("Real", "Float64", "Float32"):
                    setter(vrs, [float(values[n]) for n in names])
                else:
                    setter(vrs, [int(round(values[n])) for n in names])
            self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            left, right = (float(get([vr])[0]) for get, vr in self._outputs)
        except Exception as e:
            raise self._error(f"its step at t = {t:.6g} s failed", e) from None
        return left, right

    def close(self) -> None:
        """Terminate and free the FMU, and remove its extracted files."""
        if self.fmu is not None:
            fmu, self.fmu = self.fmu, None
            try:
                fmu.terminate()
            except Exception:  # a controller that failed may refuse to terminate: it is freed all the same
                pass
            try:
                fmu.freeInstance()
            except Exception:
                pass
        if self._tmp is not None:
            self._tmp.cleanup()

    def __enter__(self) -> "ControllerSession":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
