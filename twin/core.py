"""The C core from Python: load ``twin._lfcore``, mirror its structs, install the control callback.

Python validates and C trusts (as ``mujoco.rollout`` does): every value written here has been checked by
the model space or the dataclasses before. At load, the struct sizes are compared with the library's own
and the MuJoCo it was compiled against with the one imported, so a stale build fails loudly.
"""

from __future__ import annotations

import ctypes
import glob
import os
from ctypes import c_double, c_int32, c_int64, c_uint16, c_uint32, c_uint64

import mujoco
import numpy as np

from twin.errors import TwinError

MAX_SENSORS = 16
MAGIC = 1279676025.0
LAYOUT_VERSION = 4


class Params(ctypes.Structure):
    """``lf_params``: see :class:`twin.controller.ControlParams`."""

    _fields_ = [
        ("count", c_int32), ("pitch_m", c_double), ("sensor_distance_m", c_double),
        ("v_max", c_double), ("k_b", c_double), ("k_p", c_double), ("k_i", c_double), ("k_d", c_double),
        ("dt_s", c_double), ("wheel_radius_m", c_double), ("half_track_m", c_double),
        ("wheel_speed_max", c_double), ("accel_max", c_double), ("integral_limit", c_double),
        ("cal_duty", c_double), ("cal_sweep_rad", c_double), ("cal_sweeps", c_int32),
    ]


class FwState(ctypes.Structure):
    """``lf_state``: see :class:`twin.controller.FirmwareState`."""

    _fields_ = [
        ("cal_min", c_uint16 * MAX_SENSORS), ("cal_max", c_uint16 * MAX_SENSORS), ("value", c_uint16 * MAX_SENSORS),
        ("position", c_int32), ("last_position", c_int32), ("line_seen", c_int32), ("mode", c_int32),
        ("tick", c_uint32), ("e", c_double), ("e_prev", c_double), ("integral", c_double), ("v", c_double),
        ("omega", c_double), ("duty_left", c_double), ("duty_right", c_double),
    ]


class SensorModelC(ctypes.Structure):
    """``lf_sensor_model``: see :class:`line_sensor.reflectance.SensorModel`."""

    _fields_ = [(n, c_double) for n in ("aperture_m", "half_angle_rad", "falloff_height_m", "t_unit_us", "timeout_us", "noise_rel")]


class Texture(ctypes.Structure):
    _fields_ = [
        ("data", ctypes.POINTER(ctypes.c_uint8)), ("width", c_int32), ("height", c_int32), ("nchannel", c_int32),
        ("origin_x", c_double), ("origin_y", c_double), ("metres_per_pixel", c_double),
    ]


RECORD_FIELDS = (
    "time_s", "x_m", "y_m", "yaw_rad", "e_rad", "v_mps", "omega_radps", "u_left_v", "u_right_v",
    "wheel_left_radps", "wheel_right_radps", "position", "line_seen", "mode", "energy_j", "height_m",
    "progress_m", "offset_m", "offset_abs_sum_m", "offset_abs_max_m",
)
RECORD_WORDS = len(RECORD_FIELDS) + 2 * MAX_SENSORS  # then raw_us[16], calibrated[16]
RAW_COLUMN = len(RECORD_FIELDS)
CALIBRATED_COLUMN = RAW_COLUMN + MAX_SENSORS


class Sim(ctypes.Structure):
    """``lf_sim``: the head of one simulation's userdata; trace records follow it."""

    _fields_ = [
        ("magic", c_double), ("layout_version", c_int32), ("nsensor", c_int32),
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
    ]


SIM_WORDS = (ctypes.sizeof(Sim) + 7) // 8


def _library_path() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    found = sorted(glob.glob(os.path.join(here, "_lfcore*.so")) + glob.glob(os.path.join(here, "_lfcore*.pyd")))
    if not found:
        raise ImportError(
            "twin._lfcore is not built: install the package (pip install -e .), which compiles twin/csrc"
        )
    return found[0]


def _load() -> ctypes.CDLL:
    lib = ctypes.CDLL(_library_path())
    sizes = (c_int64 * 8)()
    lib.lf_sizes(sizes)
    ours = (ctypes.sizeof(Sim), RECORD_WORDS * 8, ctypes.sizeof(Params), ctypes.sizeof(FwState),
            ctypes.sizeof(SensorModelC), mujoco.mj_version(), 8, MAX_SENSORS)
    names = ("lf_sim", "lf_record", "lf_params", "lf_state", "lf_sensor_model", "MuJoCo version", "mjtNum", "LF_MAX_SENSORS")
    for name, c_value, py_value in zip(names, sizes, ours):
        if c_value != py_value:
            raise ImportError(
                f"twin._lfcore does not match this Python package or MuJoCo ({name}: C {c_value}, Python {py_value}); "
                "rebuild it with pip install -e ."
            )
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
    return lib


def _mj_ray_address() -> int:
    """Address of mj_ray in the libmujoco that the mujoco module loaded (dlopen returns the same handle)."""
    here = os.path.dirname(mujoco.__file__)
    found = sorted(glob.glob(os.path.join(here, "libmujoco.so*")) + glob.glob(os.path.join(here, "libmujoco*.dylib")))
    if not found:
        raise ImportError(f"twin: no libmujoco shared library beside {mujoco.__file__}")
    return ctypes.cast(ctypes.CDLL(found[0]).mj_ray, ctypes.c_void_p).value


lib = _load()
lib.lf_set_ray.argtypes = [ctypes.c_void_p]
lib.lf_set_ray(_mj_ray_address())


def install_callback() -> None:
    """Make the C loop MuJoCo's control callback.

    The callback is process-global but acts only on data whose userdata carries the twin's mark, so other
    models stepped in the same process are untouched. Installing twice is harmless.
    """
    mujoco.set_mjcb_control(lib.lf_control_callback)


def sim_view(userdata_row: np.ndarray) -> Sim:
    """The :class:`Sim` head of one simulation's userdata (a writable float64 row), sharing its memory."""
    if userdata_row.dtype != np.float64 or not userdata_row.flags.c_contiguous or not userdata_row.flags.writeable:
        raise TwinError("userdata row must be a writable, contiguous float64 array")
    return Sim.from_buffer(userdata_row)


def records_view(userdata_row: np.ndarray) -> np.ndarray:
    """(capacity, RECORD_WORDS) view of one simulation's trace ring."""
    return userdata_row[SIM_WORDS:].reshape(-1, RECORD_WORDS)


def params_to_c(p) -> Params:
    """A :class:`twin.controller.ControlParams` as ``lf_params``."""
    return Params(**{f[0]: getattr(p, f[0]) for f in Params._fields_})


def sensor_to_c(s) -> SensorModelC:
    """A :class:`line_sensor.reflectance.SensorModel` as ``lf_sensor_model``."""
    return SensorModelC(**{f[0]: getattr(s, f[0]) for f in SensorModelC._fields_})
