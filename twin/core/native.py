"""The C core from Python: load ``twin.core._lfcore``, mirror its structs, install the control callback.

Python validates and C trusts (as ``mujoco.rollout`` does): every value written here has been checked by
the model space or the dataclasses before. At load, every mirrored field's offset and size is compared with
the library's own, its status codes' names and values with :class:`twin.core.outcomes.Status`, and the MuJoCo it
was compiled against with the one imported, so a stale build fails loudly. The callback itself refuses a head that
does not fit the model it is stepped with (``Sim.error``).

Loading also routes MuJoCo's warnings to the ``mujoco`` logger (:func:`flush_mujoco_log`) instead of
MUJOCO_LOG.TXT in the working directory.
"""

from __future__ import annotations

import atexit
import ctypes
import glob
import logging
import os
from ctypes import c_double, c_int32, c_int64, c_uint16, c_uint32, c_uint64

import mujoco
import numpy as np

from line_sensor.geometry import MAX_SENSORS
from twin.core.outcomes import REFUSALS, c_names
from twin.errors import TwinError

MAGIC = 1279676025.0
LAYOUT_VERSION = 11
# the model sizes a head is written for, in the order of model_signature() in mujoco_glue.c
SIGNATURE = ("nbody", "nsite", "ntex", "ntexdata", "nu", "na", "nv", "nnumericdata")


class Params(ctypes.Structure):
    """``lf_params``: see :class:`twin.model.control.ControlParams`."""

    _fields_ = [
        ("count", c_int32), ("pitch_m", c_double), ("sensor_distance_m", c_double),
        ("v_max", c_double), ("k_b", c_double), ("k_p", c_double), ("k_i", c_double), ("k_d", c_double),
        ("dt_s", c_double), ("wheel_radius_m", c_double), ("half_track_m", c_double),
        ("wheel_speed_max", c_double), ("accel_max", c_double), ("integral_limit", c_double),
        ("cal_duty", c_double), ("cal_sweep_rad", c_double), ("cal_sweeps", c_int32),
    ]


class FwState(ctypes.Structure):
    """``lf_state``: see :class:`twin.model.control.FirmwareState`."""

    _fields_ = [
        ("cal_min", c_uint16 * MAX_SENSORS), ("cal_max", c_uint16 * MAX_SENSORS), ("value", c_uint16 * MAX_SENSORS),
        ("position", c_int32), ("last_position", c_int32), ("line_seen", c_int32), ("mode", c_int32),
        ("tick", c_uint32), ("e", c_double), ("e_prev", c_double), ("integral", c_double), ("v", c_double),
        ("omega", c_double), ("duty_left", c_double), ("duty_right", c_double),
        ("call_min", c_uint16 * MAX_SENSORS), ("call_max", c_uint16 * MAX_SENSORS), ("call_reads", c_int32),
    ]


class SensorModelC(ctypes.Structure):
    """``lf_sensor_model``: see :class:`line_sensor.reflectance.SensorModel`."""

    _fields_ = [(n, c_double) for n in ("aperture_m", "half_angle_rad", "falloff_height_m", "t_unit_us", "timeout_us", "noise_rel")]


class Texture(ctypes.Structure):
    """``lf_texture``: the floor texture as the sensor physics reads it."""

    _fields_ = [
        ("data", ctypes.POINTER(ctypes.c_uint8)), ("width", c_int32), ("height", c_int32), ("nchannel", c_int32),
        ("origin_x", c_double), ("origin_y", c_double), ("metres_per_pixel", c_double),
    ]


class LapLimitsC(ctypes.Structure):
    """``lf_lap_limits``: the failure thresholds of :class:`twin.core.lap.LapLimits` the C judge applies."""

    _fields_ = [(n, c_double) for n in ("max_cross_track_m", "max_progress_jump_m", "max_line_lost_s", "timeout_s",
                                        "max_backtrack_m")]

    @classmethod
    def of(cls, limits) -> "LapLimitsC":
        """The C judge's thresholds of ``limits`` (a :class:`twin.core.lap.LapLimits`), field by field by name."""
        return cls(*(getattr(limits, name) for name, _ in cls._fields_))


class JudgeC(ctypes.Structure):
    """``lf_judge``: the lap judge in C (twin/csrc/sim/lap_judge.h), Python's :class:`twin.core.lap.LapJudge` record by
    record."""

    _fields_ = [("limits", LapLimitsC), ("length_m", c_double), ("status", c_int32), ("started", c_int32),
                ("records", c_int64)] + [(n, c_double) for n in (
                    "u_last", "s_last", "u_max", "t_seen", "prev_t", "prev_u", "prev_energy", "abs_sum", "abs_max",
                    "end_t", "end_u", "end_energy")]


RECORD_FIELDS = (
    "time_s", "x_m", "y_m", "yaw_rad", "e_rad", "v_mps", "omega_radps", "u_left_v", "u_right_v",
    "wheel_left_radps", "wheel_right_radps", "position", "line_seen", "mode", "energy_j", "height_m",
    "progress_m", "offset_m", "offset_abs_sum_m", "offset_abs_max_m",
)
RECORD_WORDS = len(RECORD_FIELDS) + 2 * MAX_SENSORS  # then raw_us[16], calibrated[16]
RAW_COLUMN = len(RECORD_FIELDS)
CALIBRATED_COLUMN = RAW_COLUMN + MAX_SENSORS


class TimingC(ctypes.Structure):
    """``lf_timing``: see :class:`twin.model.timing.Timing`."""

    _fields_ = [("release_us", c_double), ("compute_us", c_double), ("compute_centred_us", c_double),
                ("compute_lost_us", c_double), ("compute_calibrate_us", c_double), ("pwm_counts", c_double)]


class PowerC(ctypes.Structure):
    """``lf_power``: see :class:`twin.model.power.Power`."""

    _fields_ = [("battery_v", c_double), ("source_ohm", c_double), ("regulator_v", c_double),
                ("regulator_min_input_v", c_double)]


class Sim(ctypes.Structure):
    """``lf_sim``: the head of one simulation's userdata; trace records follow it."""

    _fields_ = [
        ("magic", c_double), ("layout_version", c_int32), ("error", c_int32),
        ("model_signature", c_int64 * len(SIGNATURE)), ("nsensor", c_int32),
        ("sensor_site", c_int32 * MAX_SENSORS), ("sensor_body", c_int32), ("texture_id", c_int32),
        ("actuator_left", c_int32), ("actuator_right", c_int32), ("dof_left", c_int32), ("dof_right", c_int32),
        ("axle_site", c_int32), ("root_body", c_int32), ("record_capacity", c_int32),
        ("centre_adr", c_int32), ("centre_count", c_int32),
        ("texture_origin_x", c_double), ("texture_origin_y", c_double), ("texture_metres_per_pixel", c_double),
        ("supply_voltage", c_double), ("timestep", c_double),
        ("sensor", SensorModelC), ("firmware", Params), ("seed", c_uint64),
        ("rng", c_uint64), ("ticks", c_int64), ("records_written", c_int64), ("segment", c_int64),
        ("phase_start_time", c_double), ("last_time", c_double), ("energy_j", c_double),
        ("offset_abs_sum_m", c_double), ("offset_abs_max_m", c_double),
        ("fw", FwState), ("raw", c_uint16 * MAX_SENSORS),
        ("judge_on", c_int32), ("stop_raised", c_int32), ("deadline_s", c_double), ("judge", JudgeC),
        ("timing", TimingC), ("duty_now", c_double * 2), ("duty_next", c_double * 2), ("apply_time_s", c_double),
        ("pending", c_int32), ("pad", c_int32), ("reads", c_int64),
        ("power", PowerC), ("terminal_min_v", c_double), ("power_off", c_int32), ("pad_power", c_int32),
    ]


SIM_WORDS = (ctypes.sizeof(Sim) + 7) // 8


def _library_path() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    found = sorted(glob.glob(os.path.join(here, "_lfcore*.so")) + glob.glob(os.path.join(here, "_lfcore*.pyd")))
    if not found:
        raise ImportError(
            "twin.core._lfcore is not built: install the package (pip install -e .), which compiles twin/csrc"
        )
    return found[0]


class Field(ctypes.Structure):
    """``lf_field``: one row of the library's layout table."""

    _fields_ = [("name", ctypes.c_char_p), ("offset", c_int64), ("size", c_int64)]


class StatusName(ctypes.Structure):
    """``lf_status_name``: one row of the library's table of status codes."""

    _fields_ = [("name", ctypes.c_char_p), ("value", c_int32)]


def mirrors() -> dict[str, dict[str, tuple[int, int]]]:
    """{C struct: {field: (offset, size) in bytes}} as this module mirrors them; records are rows of float64."""
    out = {c: {f[0]: (getattr(cls, f[0]).offset, getattr(cls, f[0]).size) for f in cls._fields_}
           for c, cls in (("lf_sim", Sim), ("lf_params", Params), ("lf_state", FwState),
                          ("lf_sensor_model", SensorModelC), ("lf_texture", Texture), ("lf_lap_limits", LapLimitsC),
                          ("lf_judge", JudgeC), ("lf_timing", TimingC),
                          ("lf_power", PowerC))}
    out["lf_record"] = {name: (8 * i, 8) for i, name in enumerate(RECORD_FIELDS)}
    out["lf_record"].update(raw_us=(8 * RAW_COLUMN, 8 * MAX_SENSORS), calibrated=(8 * CALIBRATED_COLUMN, 8 * MAX_SENSORS))
    return out


def check_same(c: dict, py: dict, what: str, library: str = "twin.core._lfcore") -> None:
    """Raise ImportError naming the first key whose value (``what``) differs between the library's table ``c`` and
    Python's ``py``, or that one of them lacks."""
    for name in sorted(set(c) | set(py)):
        if c.get(name) != py.get(name):
            raise ImportError(f"{library} does not match this Python package ({name}: {what} C {c.get(name)}, "
                              f"Python {py.get(name)}); rebuild it with pip install -e .")


def check_layout(c_fields: dict[str, tuple[int, int]], ours: dict[str, dict[str, tuple[int, int]]]) -> None:
    """Raise ImportError unless every mirrored field has the library's offset and size, and no field is missing on
    either side. ``c_fields``: {"struct.field": (offset, size)} from ``lf_layout``."""
    check_same(c_fields, {f"{struct}.{name}": at for struct, fields in ours.items() for name, at in fields.items()},
               "(offset, size)")


def library_layout(lib: ctypes.CDLL, function: str = "lf_layout") -> dict[str, tuple[int, int]]:
    """{"struct.field": (offset, size) [bytes]} from a layout table (``lf_layout``, or the glue's ``lf_avr_layout``)."""
    table = ctypes.POINTER(Field)()
    n = getattr(lib, function)(ctypes.byref(table))
    return {table[i].name.decode(): (table[i].offset, table[i].size) for i in range(n)}


def library_statuses(lib: ctypes.CDLL) -> dict[str, int]:
    """{C name: value} of every ``enum lf_status`` code, from ``lf_status_names``."""
    table = ctypes.POINTER(StatusName)()
    n = lib.lf_status_names(ctypes.byref(table))
    return {table[i].name.decode(): table[i].value for i in range(n)}


def _check_sizes(lib: ctypes.CDLL) -> None:
    ours = (ctypes.sizeof(Sim), RECORD_WORDS * 8, ctypes.sizeof(Params), ctypes.sizeof(FwState),
            ctypes.sizeof(SensorModelC), ctypes.sizeof(Texture), mujoco.mj_version(), 8, MAX_SENSORS, LAYOUT_VERSION,
            len(SIGNATURE))
    names = ("lf_sim", "lf_record", "lf_params", "lf_state", "lf_sensor_model", "lf_texture", "MuJoCo version", "mjtNum",
             "LF_MAX_SENSORS", "LF_LAYOUT_VERSION", "LF_SIGNATURE")
    sizes = (c_int64 * len(ours))()
    count = lib.lf_sizes(sizes, len(ours))
    if count != len(ours):
        raise ImportError(f"twin.core._lfcore reports {count} sizes, this package expects {len(ours)}; rebuild it with pip install -e .")
    for name, c_value, py_value in zip(names, sizes, ours):
        if c_value != py_value:
            raise ImportError(
                f"twin.core._lfcore does not match this Python package or MuJoCo ({name}: C {c_value}, Python {py_value}); "
                "rebuild it with pip install -e ."
            )


def check_library(lib: ctypes.CDLL) -> None:
    """Raise ImportError unless a library built from twin/csrc (``_lfcore``, ``_lfavr``) has this package's structs,
    status codes and MuJoCo."""
    lib.lf_sizes.restype = lib.lf_layout.restype = lib.lf_status_names.restype = c_int32
    lib.lf_sizes.argtypes = [ctypes.POINTER(c_int64), c_int32]
    lib.lf_layout.argtypes = [ctypes.POINTER(ctypes.POINTER(Field))]
    lib.lf_status_names.argtypes = [ctypes.POINTER(ctypes.POINTER(StatusName))]
    _check_sizes(lib)
    check_layout(library_layout(lib), mirrors())
    check_same(library_statuses(lib), c_names(), "value")


def mujoco_function(name: str) -> int:
    """The address of a function of the libmujoco the mujoco module loaded (for C that calls MuJoCo)."""
    return ctypes.cast(getattr(_mujoco, name), ctypes.c_void_p).value


def _load() -> ctypes.CDLL:
    lib = ctypes.CDLL(_library_path())
    try:
        lib.lf_sizes.restype = lib.lf_layout.restype = lib.lf_status_names.restype = c_int32
    except AttributeError as e:  # built before the layout or status tables existed
        raise ImportError(f"twin.core._lfcore is out of date ({e}); rebuild it with pip install -e .") from None
    check_library(lib)
    P, S = ctypes.POINTER, ctypes.POINTER(FwState)
    u16p = P(c_uint16)
    lib.lf_reset.argtypes = [S, c_int32]
    lib.lf_calibrate_reset.argtypes = [S, c_uint16]
    lib.lf_step.argtypes = [S, P(Params), u16p]
    lib.lf_control.argtypes = [S, P(Params), c_double]
    lib.lf_line_angle.argtypes = [c_int32, c_int32, c_double, c_double]
    lib.lf_line_angle.restype = c_double
    lib.lf_read_line.argtypes = [S, u16p, c_int32]
    lib.lf_read_line.restype = c_int32
    lib.lf_wheel_duties.argtypes = [P(Params), c_double, c_double, P(c_double), P(c_double)]
    lib.lf_calibration_ticks.argtypes = [P(Params)]
    lib.lf_calibration_ticks.restype = c_uint32
    lib.lf_footprint_radius.argtypes = [P(SensorModelC), c_double]
    lib.lf_footprint_radius.restype = c_double
    lib.lf_footprint_reflectance.argtypes = [P(Texture), c_double, c_double, c_double]
    lib.lf_footprint_reflectance.restype = c_double
    lib.lf_raw_reading.argtypes = [P(SensorModelC), c_double, c_double, c_double]
    lib.lf_raw_reading.restype = c_uint16
    lib.lf_locate.argtypes = [P(c_double), c_int32, c_double, c_double, c_double, P(c_int64), P(c_double), P(c_double)]
    lib.lf_rng_next.argtypes = [P(c_uint64)]
    lib.lf_rng_next.restype = c_uint64
    lib.lf_noise.argtypes = [P(c_uint64)]
    lib.lf_noise.restype = c_double
    lib.lf_noise_base.argtypes = [c_uint64, c_int32]
    lib.lf_noise_base.restype = c_uint64
    lib.lf_reading_noise.argtypes = [c_uint64, c_int64, c_int32]
    lib.lf_reading_noise.restype = c_double
    lib.lf_judge_start.argtypes = [P(JudgeC), c_double, P(LapLimitsC)]
    lib.lf_judge_feed.argtypes = [P(JudgeC), P(c_double)]
    lib.lf_judge_feed.restype = c_int32
    return lib


def _libmujoco() -> ctypes.CDLL:
    """The libmujoco that the mujoco module loaded (dlopen returns the same handle)."""
    here = os.path.dirname(mujoco.__file__)
    found = sorted(glob.glob(os.path.join(here, "libmujoco.so*")) + glob.glob(os.path.join(here, "libmujoco*.dylib")))
    if not found:
        raise ImportError(f"twin: no libmujoco shared library beside {mujoco.__file__}")
    return ctypes.CDLL(found[0])


lib = _load()
_mujoco = _libmujoco()
lib.lf_set_ray.argtypes = [ctypes.c_void_p]
lib.lf_set_ray(mujoco_function("mj_ray"))

# --- MuJoCo's log: the C handler keeps a few messages and counts the rest (an unstable simulation warns at every
# step, ~750 KB a lap); flush_mujoco_log hands them to Python's logging
mujoco_log = logging.getLogger("mujoco")
LOG_KEEP, LOG_TEXT = 8, 512  # distinct messages and bytes of each asked for at a flush (the library keeps LF_LOG_KEEP)
_LEVELS = (logging.DEBUG, logging.INFO, logging.WARNING, logging.ERROR)  # mjtLogLevel
lib.lf_log_drain.argtypes = [ctypes.c_char_p, ctypes.POINTER(c_int32), ctypes.POINTER(c_int64), c_int32, c_int32]
lib.lf_log_drain.restype = c_int64
lib.lf_log_pending.restype = c_int64
lib.lf_log_chain.argtypes = [ctypes.c_void_p]
_mujoco.mju_setLogHandler.argtypes = [ctypes.c_void_p]
_mujoco.mju_setLogHandler.restype = ctypes.c_void_p
lib.lf_log_chain(_mujoco.mju_setLogHandler(ctypes.cast(lib.lf_log_handler, ctypes.c_void_p).value))


def flush_mujoco_log() -> int:
    """Log the MuJoCo messages received since the last flush to the ``mujoco`` logger: a few distinct ones with
    how often each came, the rest as one count. Returns how many there were. Safe to call from any thread."""
    if not lib.lf_log_pending():
        return 0
    text = ctypes.create_string_buffer(LOG_KEEP * LOG_TEXT)
    levels, counts = (c_int32 * LOG_KEEP)(), (c_int64 * LOG_KEEP)()
    total = lib.lf_log_drain(text, levels, counts, LOG_KEEP, LOG_TEXT)
    for i in range(LOG_KEEP):
        if counts[i]:
            message = text.raw[i * LOG_TEXT: (i + 1) * LOG_TEXT].split(b"\0", 1)[0].decode(errors="replace").strip()
            times = f" (×{counts[i]})" if counts[i] > 1 else ""
            mujoco_log.log(_LEVELS[min(max(levels[i], 0), 3)], "%s%s", message, times)
    rest = total - sum(counts)
    if rest:
        mujoco_log.warning("%d more MuJoCo messages", rest)
    return int(total)


atexit.register(flush_mujoco_log)  # what the last calls left


def install_callback() -> None:
    """Make the C loop MuJoCo's control callback.

    The callback is process-global but acts only on data whose userdata carries the twin's mark, so other
    models stepped in the same process are untouched. Installing twice is harmless.
    """
    mujoco.set_mjcb_control(lib.lf_control_callback)
    _mjcb_time.value = _PACKAGE_TIMER if MUJOCO_PROFILER else None


# the mujoco package installs a high-resolution timer as MuJoCo's profiling callback (mjcb_time), which every mj_step
# calls at each of its stages: ~5 % of a lap's CPU time. Nothing here reads mjData.timer, so install_callback turns it
# off unless this is True (a benchmark of the code as it was)
MUJOCO_PROFILER = False
_mjcb_time = ctypes.c_void_p.in_dll(_mujoco, "mjcb_time")
_PACKAGE_TIMER = _mjcb_time.value


def model_signature(model: mujoco.MjModel) -> tuple[int, ...]:
    """The sizes of ``model`` that a head records (``SIGNATURE``): the callback refuses a model of other sizes."""
    return tuple(int(getattr(model, name)) for name in SIGNATURE)


def refusal(sim: Sim) -> str | None:
    """Why the callback refused this simulation, or None if it did not."""
    if sim.error == 0:
        return None
    return "the C loop refused the simulation: its userdata did not match the model (" + \
        REFUSALS.get(sim.error, f"error {sim.error}") + ")"


def sim_view(userdata_row: np.ndarray) -> Sim:
    """The :class:`Sim` head of one simulation's userdata (a writable float64 row), sharing its memory."""
    if userdata_row.dtype != np.float64 or not userdata_row.flags.c_contiguous or not userdata_row.flags.writeable:
        raise TwinError("userdata row must be a writable, contiguous float64 array")
    return Sim.from_buffer(userdata_row)


def records_view(userdata_row: np.ndarray) -> np.ndarray:
    """(capacity, RECORD_WORDS) view of one simulation's trace ring."""
    return userdata_row[SIM_WORDS:].reshape(-1, RECORD_WORDS)


def records_since(userdata_row: np.ndarray, sim: Sim, consumed: int) -> np.ndarray:
    """The trace records written since the first ``consumed``, in order; TwinError if the ring has overwritten
    some of them (more were written than it holds)."""
    written, capacity = sim.records_written, sim.record_capacity
    if written - consumed > capacity:
        raise TwinError(f"trace ring overflowed ({written - consumed} records for {capacity} slots)")
    return records_view(userdata_row)[np.arange(consumed, written) % capacity]


def params_to_c(p) -> Params:
    """A :class:`twin.model.control.ControlParams` as ``lf_params``."""
    return Params(**{f[0]: getattr(p, f[0]) for f in Params._fields_})


def timing_to_c(t) -> TimingC:
    """A :class:`twin.model.timing.Timing` as ``lf_timing``."""
    return TimingC(**{name: getattr(t, name) for name, _ in TimingC._fields_})


def power_to_c(p) -> PowerC:
    """A :class:`twin.model.power.Power` as ``lf_power``."""
    return PowerC(battery_v=p.battery_v, source_ohm=p.source_ohm, regulator_v=p.regulator_v,
                  regulator_min_input_v=p.regulator_min_input_v)


def sensor_to_c(s) -> SensorModelC:
    """A :class:`line_sensor.reflectance.SensorModel` as ``lf_sensor_model``."""
    return SensorModelC(**{f[0]: getattr(s, f[0]) for f in SensorModelC._fields_})
