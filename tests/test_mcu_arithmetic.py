"""The firmware's arithmetic on the robot's MCU: the portable functions run inside simavr (the ``selftest`` program,
twin/csrc/firmware/avr/selftest.c) on a few thousand random and edge inputs, against the host build.

On the ATmega328P ``int`` is 16-bit and ``double`` is a 32-bit float. Integers must agree bit for bit. Reals are
fed as float32 values to both sides, so what differs is only the arithmetic's precision: the MCU's result must lie
within 8 single-precision roundings of the magnitudes summed (8 · 2⁻²⁴ · Σ|terms|); the host computes in double.
"""

from __future__ import annotations

import ctypes
import math
import os
import random
import struct

import numpy as np
import pytest

from twin.model import control as ref
from twin.core.native import FwState, lib, params_to_c

pytestmark = [pytest.mark.usefixtures("mcu_selftest"), pytest.mark.quick]
EPS32 = 2.0**-24
N = 2000

# the selftest program's structures as avr-gcc lays them out (no padding, lf_real = float)
PARAMS = struct.Struct("<i15fi")
# cal_min, cal_max, value, position, last_position, line_seen, mode, tick, 7 reals, call_min, call_max, call_reads
STATE = struct.Struct("<16H16H16Hiiiii7f16H16Hi")
STATE_ITEMS = 48 + 5 + 7 + 33
IN = struct.Struct("<" + PARAMS.format[1:] + STATE.format[1:] + "16Hi2fIiii")
OUT = struct.Struct("<" + STATE.format[1:] + "16Hi2fIh96s")
PARAM_FIELDS = ("pitch_m", "sensor_distance_m", "v_max", "k_b", "k_p", "k_i", "k_d", "dt_s", "wheel_radius_m",
                "half_track_m", "wheel_speed_max", "accel_max", "integral_limit", "cal_duty", "cal_sweep_rad")
READ_CALIBRATED, READ_LINE, LINE_ANGLE, CONTROL, WHEEL_DUTIES, CALIBRATION_TICKS, WIRE_SAMPLE = range(1, 8)


def f32(x: float) -> float:
    return float(np.float32(x))


@pytest.fixture(scope="module")
def mcu_selftest():
    from twin.pil import firmware as avr_firmware
    from twin.errors import TwinError
    from twin.pil.mcu import Mcu

    try:
        elf = avr_firmware.check_elf(avr_firmware.build("selftest"))
        mcu = Mcu(elf)
    except TwinError as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI installs avr-gcc and simavr: {e}")
        pytest.skip(str(e))
    # the structures packed here are the ones avr-gcc laid out
    assert (elf.sizes["st_in"], elf.sizes["st_out"]) == (IN.size, OUT.size)
    assert mcu.run_cycles(200_000) == 0  # past the C runtime's start-up (it clears st_command)
    global MCU
    MCU = mcu
    yield mcu
    mcu.close()


def random_params(rng: random.Random, count: int = 8) -> ref.ControlParams:
    return ref.ControlParams(
        count=count, pitch_m=f32(rng.uniform(0.004, 0.02)), sensor_distance_m=f32(rng.uniform(0.02, 0.12)),
        v_max=f32(rng.uniform(0, 2)), k_b=f32(rng.uniform(0, 5)), k_p=f32(rng.uniform(0, 60)),
        k_i=f32(rng.uniform(0, 50)), k_d=f32(rng.uniform(0, 2)), dt_s=f32(rng.choice([0.002, 0.005, 0.01])),
        wheel_radius_m=f32(rng.uniform(0.01, 0.04)), half_track_m=f32(rng.uniform(0.03, 0.12)),
        wheel_speed_max=f32(rng.uniform(20, 120)), accel_max=f32(rng.uniform(0.5, 10)),
        integral_limit=f32(rng.uniform(0.01, 2)), cal_duty=f32(rng.uniform(0.05, 0.5)),
        cal_sweep_rad=f32(rng.uniform(0.2, 2)), cal_sweeps=rng.randint(1, 5))


def pack_params(p: ref.ControlParams) -> bytes:
    return PARAMS.pack(p.count, *(getattr(p, f) for f in PARAM_FIELDS), p.cal_sweeps)


def pack_state(s: FwState) -> bytes:
    return STATE.pack(*s.cal_min, *s.cal_max, *s.value, s.position, s.last_position, s.line_seen, s.mode, s.tick,
                      s.e, s.e_prev, s.integral, s.v, s.omega, s.duty_left, s.duty_right, *s.call_min, *s.call_max,
                      s.call_reads)


def run(command: int, p: ref.ControlParams, state: FwState | None = None, raw=(0,) * 16, position=0, a=0.0, b=0.0,
        t_ms=0, seen=0, wl=0, wr=0) -> dict:
    """Run one selftest command on the MCU; its st_out as a dict."""
    state = state or FwState()
    data = pack_params(p) + pack_state(state) + struct.pack("<16Hi2fIiii", *raw, position, a, b, t_ms, seen, wl, wr)
    MCU.poke("st_in", data)
    MCU.poke("st_command", bytes([command]))
    assert MCU.run_until_clear("st_command", 5_000_000) == 0  # each call is well under 5 M cycles (0.25 s)
    out = OUT.unpack(MCU.peek("st_out", OUT.size))
    st = dict(zip(("position", "last_position", "line_seen", "mode", "tick", "e", "e_prev", "integral", "v", "omega",
                   "duty_left", "duty_right"), out[48:60]))
    n = STATE_ITEMS
    return {"state": st, "cal_min": out[:16], "values": out[n:n + 16], "position": out[n + 16], "a": out[n + 17],
            "b": out[n + 18], "ticks": out[n + 19], "length": out[n + 20], "text": out[n + 21]}


def test_eq8_read_calibrated_bit_for_bit():
    rng = random.Random(8)
    lib.lf_read_calibrated.argtypes = [ctypes.POINTER(FwState), ctypes.POINTER(ctypes.c_uint16),
                                       ctypes.POINTER(ctypes.c_uint16), ctypes.c_int32]
    for k in range(N):
        count = rng.randint(1, 16)
        s = FwState()
        for i in range(16):
            lo, hi = rng.randint(0, 2600), rng.randint(0, 2600)
            if k % 5 == 0:
                lo, hi = rng.choice([(0, 0), (2500, 2500), (65535, 0), (0, 65535), (100, 101)])  # edges: empty, reversed, widest
            s.cal_min[i], s.cal_max[i] = lo, hi
        raw = [rng.choice([0, 1, 2500, 65535, rng.randint(0, 3000)]) for _ in range(16)]
        host = (ctypes.c_uint16 * 16)()
        lib.lf_read_calibrated(ctypes.byref(s), (ctypes.c_uint16 * 16)(*raw), host, count)
        mcu = run(READ_CALIBRATED, ref.ControlParams(**{**random_params(rng).__dict__, "count": count}), s, raw)
        assert list(mcu["values"][:count]) == list(host[:count]), (count, raw, list(s.cal_min), list(s.cal_max))


def test_read_line_bit_for_bit():
    rng = random.Random(9)
    for k in range(N):
        count = rng.randint(2, 16)
        values = [rng.choice([0, 50, 51, 200, 201, 1000, rng.randint(0, 1000)]) for _ in range(16)]
        s = FwState()
        s.last_position = rng.randint(0, (count - 1) * 1000)
        host = FwState()
        host.last_position = s.last_position
        pos = lib.lf_read_line(ctypes.byref(host), (ctypes.c_uint16 * 16)(*values), count)
        mcu = run(READ_LINE, ref.ControlParams(**{**random_params(rng).__dict__, "count": count}), s, values)
        assert (mcu["position"], mcu["state"]["line_seen"], mcu["state"]["last_position"]) == (
            pos, host.line_seen, host.last_position), (count, values)


def test_eq9_line_angle_within_single_precision():
    rng = random.Random(10)
    for _ in range(N):
        p = random_params(rng, rng.randint(2, 16))
        position = rng.randint(0, (p.count - 1) * 1000)
        host = lib.lf_line_angle(position, p.count, p.pitch_m, p.sensor_distance_m)
        mcu = run(LINE_ANGLE, p, position=position)["a"]
        # atan2(y, S) with y = ((count-1)*500 - position) * pitch / 1000: a few roundings of |angle| (≤ π/2)
        assert abs(mcu - host) <= 8 * EPS32 * (abs(host) + 1e-7), (p, position, mcu, host)


def test_eqs10_11_control_within_single_precision():
    rng = random.Random(11)
    for _ in range(N):
        p = random_params(rng)
        s = FwState()
        s.tick = rng.choice([0, 1, 1000])
        s.e_prev, s.integral, s.v = f32(rng.uniform(-1, 1)), f32(rng.uniform(-p.integral_limit, p.integral_limit)), f32(rng.uniform(0, 2))
        e = f32(rng.uniform(-1.2, 1.2))
        host = FwState.from_buffer_copy(s)
        lib.lf_control(ctypes.byref(host), ctypes.byref(params_to_c(p)), e)
        mcu = run(CONTROL, p, s, a=e)["state"]
        derivative = 0.0 if s.tick == 0 else (abs(e) + abs(s.e_prev)) / p.dt_s
        omega_scale = abs(p.k_p * e) + abs(p.k_i * p.integral_limit) + abs(p.k_d) * derivative
        assert abs(mcu["omega"] - host.omega) <= 8 * EPS32 * omega_scale + 1e-9, (p, e, mcu, host.omega)
        assert abs(mcu["v"] - host.v) <= 8 * EPS32 * (p.v_max + p.k_b * abs(e) + s.v + p.accel_max * p.dt_s)
        assert abs(mcu["integral"] - host.integral) <= 8 * EPS32 * (abs(s.integral) + abs(e * p.dt_s))
        assert mcu["e_prev"] == pytest.approx(host.e_prev, abs=0)  # a copy of e: exact


def test_wheel_duties_within_single_precision():
    rng = random.Random(12)
    for _ in range(N):
        p = random_params(rng)
        v, w = f32(rng.uniform(-3, 3)), f32(rng.uniform(-100, 100))
        left, right = ctypes.c_double(), ctypes.c_double()
        lib.lf_wheel_duties(ctypes.byref(params_to_c(p)), v, w, ctypes.byref(left), ctypes.byref(right))
        mcu = run(WHEEL_DUTIES, p, a=v, b=w)
        scale = (abs(v) + abs(w * p.half_track_m)) / (p.wheel_radius_m * p.wheel_speed_max) + 1.0
        assert abs(mcu["a"] - left.value) <= 16 * EPS32 * scale and abs(mcu["b"] - right.value) <= 16 * EPS32 * scale


def test_calibration_length_integer_except_at_rounding_ties():
    """lf_calibration_ticks rounds a real tick count: the MCU's float may land on the other side of a .5 tie."""
    rng = random.Random(13)
    ties = 0
    for _ in range(N):
        p = random_params(rng)
        host = lib.lf_calibration_ticks(ctypes.byref(params_to_c(p)))
        mcu = run(CALIBRATION_TICKS, p)["ticks"]
        omega = p.cal_duty * p.wheel_speed_max * p.wheel_radius_m / p.half_track_m
        quarter = p.cal_sweep_rad / (omega * p.dt_s)
        if mcu != host:
            ties += 1
            assert abs(quarter - math.floor(quarter) - 0.5) < 1e-5 * quarter, (p, quarter, mcu, host)
            assert abs(mcu - host) == 4 * p.cal_sweeps  # one quarter tick more or less in each of 4 per sweep
    assert ties <= N // 100


def test_wire_sample_lines_byte_for_byte():
    rng = random.Random(14)
    buf = ctypes.create_string_buffer(96)
    edges = [0, 1, 9, 10, 99999, 2**31 - 1, -(2**31), -1, 2**32 - 1]
    for k in range(N):
        t = rng.choice([rng.randrange(2**32), 0, 9, 10, 2**32 - 1])
        pos, seen = rng.choice([rng.randrange(-(2**31), 2**31), *edges[:8]]), rng.randrange(2)
        wl, wr = (rng.randrange(-(2**31), 2**31) for _ in range(2))
        n = lib.lf_wire_sample(buf, ctypes.c_uint32(t), pos, seen, wl, wr)
        host = buf.raw[:n]
        mcu = run(WIRE_SAMPLE, random_params(rng), position=pos, t_ms=t, seen=seen, wl=wl, wr=wr)
        assert mcu["length"] == n and mcu["text"][:n] == host, (t, pos, wl, wr)
