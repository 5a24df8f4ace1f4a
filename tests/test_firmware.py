"""Firmware (Eqs. 8–11): hand-computed cases, C equal to the Python reference, and an ATmega328P build."""

from __future__ import annotations

import ctypes
import math
import os
import random
import shutil
import subprocess

import pytest

from line_sensor.processing import calibrate_update, read_calibrated, read_line, line_angle
from twin.model import control as ref
from twin.core.native import FwState, lib, params_to_c

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)

FIRMWARE = os.path.join(os.path.dirname(__file__), "..", "twin", "csrc", "firmware")
PITCH, S = 0.009525, 0.040


def params(**kw) -> ref.ControlParams:
    base = dict(count=8, pitch_m=PITCH, sensor_distance_m=S, v_max=0.8, k_b=0.6, k_p=12.0, k_i=3.0, k_d=0.4,
                dt_s=0.005, wheel_radius_m=0.016, half_track_m=0.0425, wheel_speed_max=75.4, accel_max=5.0,
                integral_limit=0.5, cal_duty=0.15, cal_sweep_rad=1.0, cal_sweeps=2)
    base.update(kw)
    return ref.ControlParams(**base)


# --- Eq. 8 by hand
def test_eq8_scales_between_calibrated_min_and_max():
    cal_min, cal_max = [200, 200, 200, 100], [2200, 2200, 2200, 100]
    # (1200-200)*1000/2000 = 500; below min clips to 0; above max clips to 1000; max == min reads 0
    assert read_calibrated([1200, 100, 3000, 100], cal_min, cal_max) == [500, 0, 1000, 0]
    # integer division truncates as the MCU does: (201-200)*1000/2000 = 0.5 -> 0, (203-200)*1000/2000 = 1.5 -> 1
    assert read_calibrated([201, 203, 2199, 100], cal_min, cal_max) == [0, 1, 999, 0]


# --- Eq. 9 by hand
def test_eq9_centred_line_is_zero_angle():
    pos, seen, _ = read_line([0, 0, 0, 1000, 1000, 0, 0, 0], 0)
    assert (pos, seen) == (3500, True)  # (1000*3000 + 1000*4000) / 2000
    assert line_angle(pos, 8, PITCH, S) == 0.0


def test_eq9_line_under_sensor_zero_is_left_and_positive():
    pos, seen, last = read_line([1000, 0, 0, 0, 0, 0, 0, 0], 3500)
    assert (pos, seen, last) == (0, True, 0)
    assert line_angle(pos, 8, PITCH, S) == pytest.approx(math.atan2(3.5 * PITCH, S), abs=1e-15)
    assert line_angle(7000, 8, PITCH, S) == pytest.approx(-math.atan2(3.5 * PITCH, S), abs=1e-15)


def test_eq9_noise_threshold_and_weights():
    # 50 is not above the noise threshold; 51 is: (51*1000 + 400*2000) / 451 = 1886.9 -> 1886
    assert read_line([0, 51, 400, 50, 0, 0, 0, 0], 0)[0] == (51 * 1000 + 400 * 2000) // 451 == 1886


def test_eq9_lost_line_reports_the_side_last_seen():
    faint = [150, 120, 60, 0, 0, 60, 120, 150]  # nothing above 200: the line is lost
    assert read_line(faint, 1000) == (0, False, 1000)  # last seen on the left
    assert read_line(faint, 6000) == (7000, False, 6000)  # last seen on the right
    assert read_line(faint, 3500) == (7000, False, 3500)  # Pololu: centre counts as right


# --- Eqs. 10–11 by hand
def test_eq10_11_two_ticks_by_hand():
    p = params(accel_max=1000.0)
    s = ref.FirmwareState.uncalibrated(8, 2500)
    ref.control(s, p, 0.1)
    assert s.v == pytest.approx(0.8 - 0.6 * 0.1)
    assert s.omega == pytest.approx(12.0 * 0.1 + 3.0 * 0.1 * 0.005 + 0.0)  # no derivative on the first tick
    s.tick = 1
    ref.control(s, p, -0.2)
    assert s.v == pytest.approx(0.8 - 0.6 * 0.2)
    integral = 0.1 * 0.005 - 0.2 * 0.005
    assert s.omega == pytest.approx(12.0 * -0.2 + 3.0 * integral + 0.4 * (-0.2 - 0.1) / 0.005)


def test_eq10_speed_ramp_and_floor():
    p = params(accel_max=4.0, k_b=10.0)
    s = ref.FirmwareState.uncalibrated(8, 2500)
    ref.control(s, p, 0.0)
    assert s.v == pytest.approx(4.0 * 0.005)  # ramped from rest
    ref.control(s, p, 0.5)
    assert s.v == 0.0  # v_max - K_B|e| < 0 is held at 0


def test_wheel_duties_keep_turn_rate_when_saturated():
    p = params()
    full = p.wheel_radius_m * p.wheel_speed_max  # m/s at duty 1
    left, right = ref.wheel_duties(p, full, 2.0)
    assert right == 1.0
    assert (right - left) * full == pytest.approx(2 * 2.0 * p.half_track_m)  # ω kept exactly
    assert ref.wheel_duties(p, 0.0, 1000.0) == (-1.0, 1.0)


# --- C equals Python
def c_state(count: int, timeout: int) -> FwState:
    s = FwState()
    lib.lf_calibrate_reset(ctypes.byref(s), timeout)
    return s


def assert_same(c: FwState, py: ref.FirmwareState, count: int) -> None:
    assert list(c.cal_min[:count]) == py.cal_min and list(c.cal_max[:count]) == py.cal_max
    assert c.call_reads == len(py.call)
    if py.call:  # the calibration call under way: C keeps its extremes, Python its readings
        assert list(c.call_min[:count]) == [min(col) for col in zip(*py.call)]
        assert list(c.call_max[:count]) == [max(col) for col in zip(*py.call)]
    assert list(c.value[:count]) == py.value
    assert (c.position, c.last_position, bool(c.line_seen), c.mode, c.tick) == (
        py.position, py.last_position, py.line_seen, py.mode, py.tick)
    # bit equality, not closeness: the same operations in the same order
    for name in ("e", "e_prev", "integral", "v", "omega", "duty_left", "duty_right"):
        assert getattr(c, name) == getattr(py, name), name


@pytest.mark.parametrize("count", [8, 5, 16])
def test_c_firmware_equals_python_reference(count):
    rng = random.Random(count)
    p = params(count=count, cal_sweeps=1, accel_max=3.0)
    cp = params_to_c(p)
    c = c_state(count, 2500)
    py = ref.FirmwareState.uncalibrated(count, 2500)
    lib.lf_reset(ctypes.byref(c), ref.CALIBRATE)
    py.reset(ref.CALIBRATE)
    centre = rng.uniform(0, count - 1)
    raw_t = (ctypes.c_uint16 * 16)()
    n_cal = ref.calibration_ticks(p)
    assert lib.lf_calibration_ticks(ctypes.byref(cp)) == n_cal
    for tick in range(n_cal + 600):
        if tick == n_cal + 1:
            assert c.mode == py.mode == ref.IDLE
            lib.lf_reset(ctypes.byref(c), ref.RUN)
            py.reset(ref.RUN)
        centre = min(count + 1.0, max(-2.0, centre + rng.gauss(0, 0.3)))  # wander, off both ends too
        raw = [int(min(2500, 200 + 2200 * math.exp(-((i - centre) ** 2)) + rng.randint(0, 40))) for i in range(count)]
        for i, r in enumerate(raw):
            raw_t[i] = r
        lib.lf_step(ctypes.byref(c), ctypes.byref(cp), raw_t)
        ref.firmware_step(py, p, raw)
        assert_same(c, py, count)


def test_c_line_angle_and_duties_equal_python():
    cp = params_to_c(params())
    left, right = ctypes.c_double(), ctypes.c_double()
    rng = random.Random(1)
    for _ in range(2000):
        pos = rng.randint(0, 7000)
        assert lib.lf_line_angle(pos, 8, PITCH, S) == line_angle(pos, 8, PITCH, S)
        v, w = rng.uniform(-2, 2), rng.uniform(-80, 80)
        lib.lf_wheel_duties(ctypes.byref(cp), v, w, ctypes.byref(left), ctypes.byref(right))
        assert (left.value, right.value) == ref.wheel_duties(params(), v, w)


# --- the robot's MCU
def test_firmware_builds_for_atmega328p(capsys):
    """The robot's whole program (drivers, calibration, Eqs. 8–11, telemetry, soft-float library) for the 3pi."""
    from twin.pil import firmware as avr_firmware
    if not (shutil.which("avr-gcc") and shutil.which("avr-size")):
        if os.environ.get("CI"):
            pytest.fail("avr-gcc is missing: .ci/run installs gcc-avr and avr-libc")
        pytest.skip("avr-gcc not installed (apt-get install gcc-avr avr-libc)")
    elf = avr_firmware.build("robot")
    info = avr_firmware.check_elf(elf, need=avr_firmware.TRACE_SYMBOLS)
    # avr-size, an independent reader of the same ELF, agrees with the figures the twin reports
    out = subprocess.run(["avr-size", "-A", elf], check=True, capture_output=True, text=True).stdout
    size = {line.split()[0]: int(line.split()[1]) for line in out.splitlines() if line.startswith(".")}
    assert info.flash_bytes == size[".text"] + size.get(".data", 0)
    assert info.ram_bytes == size.get(".data", 0) + size.get(".bss", 0)
    with capsys.disabled():  # the figures belong in the CI log
        print(f"\nfirmware on the ATmega328P (avr-gcc -Os): flash {info.flash_bytes} B of 32768, RAM {info.ram_bytes} B of 2048")
    # budgets: under 40 % of the MCU each, so a bootloader (512 B), the stack (the control path's soft-float calls
    # need ~150 B) and the LCD driver the 3pi ships with still fit; a regression (a printf, a double table, a buffer
    # per sensor) crosses them
    assert info.flash_bytes <= 12 * 1024
    assert info.ram_bytes <= 768


def test_eeprom_configuration_image_layout():
    """config.h by hand: magic, size, lf_params as 32-bit floats, timeout, rate, CRC-16/XMODEM."""
    import struct

    from twin.pil.firmware import CONFIG_BYTES, config_image, intel_hex

    image = config_image(params(), 2500, 2)
    assert len(image) == CONFIG_BYTES == 80
    assert image[:4] == b"LFC1" and struct.unpack_from("<H", image, 4)[0] == 80
    assert struct.unpack_from("<i", image, 6)[0] == 8 and struct.unpack_from("<f", image, 10)[0] == pytest.approx(PITCH, rel=1e-7)
    assert struct.unpack_from("<HH", image, 74) == (2500, 2)
    # CRC-16/XMODEM check value of "123456789" is 0x31C3 (the catalogue of CRC parameters); the image's is over bytes 0..77
    import binascii
    assert binascii.crc_hqx(b"123456789", 0) == 0x31C3
    assert struct.unpack_from("<H", image, 78)[0] == binascii.crc_hqx(image[:78], 0)
    hex_text = intel_hex(image)
    assert hex_text.splitlines()[0].startswith(":10000000") and hex_text.endswith(":00000001FF\n")
    assert all(sum(bytes.fromhex(line[1:])) % 256 == 0 for line in hex_text.splitlines())  # each record sums to 0


def test_c_wire_lines_equal_the_python_encoding():
    """The firmware's telemetry lines (lf_wire.c) are byte for byte what twin.telemetry.wire encodes and decodes."""
    from twin.telemetry.wire import Event, Header, Sample, decode, encode

    buf = ctypes.create_string_buffer(96)
    rng = random.Random(2)
    for _ in range(500):
        t_ms, pos, seen = rng.randrange(0, 2**32 - 1), rng.randrange(0, 7001), rng.randrange(2)
        wl, wr = rng.randrange(-20000, 20000), rng.randrange(-20000, 20000)
        n = lib.lf_wire_sample(buf, ctypes.c_uint32(t_ms), pos, seen, wl, wr)
        line = buf.raw[:n].decode()
        assert line == encode(Sample(t_ms / 1000, pos, seen, wl / 100, wr / 100))
        assert decode(line) == Sample(t_ms / 1000, pos, seen, wl / 100, wr / 100)
    n = lib.lf_wire_header(buf, 8, 5000, 2)
    assert buf.raw[:n].decode() == encode(Header(8, 0.005, 2))
    n = lib.lf_wire_lap(buf, ctypes.c_uint32(7310), ctypes.c_uint32(7310))
    assert buf.raw[:n].decode() == encode(Event(7.31, "LAP", lap_time_s=7.31))
    n = lib.lf_wire_start(buf, ctypes.c_uint32(0))
    assert buf.raw[:n].decode() == encode(Event(0.0, "START"))


def pololu_calibrate(cal_min: list[int], cal_max: list[int], reads: list[list[int]]) -> None:
    """libpololu-avr's PololuQTRSensors::calibrateOnOrOff as its source states it (src/PololuQTRSensors/
    PololuQTRSensors.cpp): ten reads; per sensor the largest and smallest of them; then "if (min_sensor_values[i] >
    (*calibratedMaximum)[i]) (*calibratedMaximum)[i] = min_sensor_values[i]" and "if (max_sensor_values[i] <
    (*calibratedMinimum)[i]) (*calibratedMinimum)[i] = max_sensor_values[i]"."""
    max_values, min_values = [0] * len(cal_min), [0] * len(cal_min)
    for j in range(10):
        for i, v in enumerate(reads[j]):
            if j == 0 or max_values[i] < v:
                max_values[i] = v
            if j == 0 or min_values[i] > v:
                min_values[i] = v
    for i in range(len(cal_min)):
        if min_values[i] > cal_max[i]:
            cal_max[i] = min_values[i]
        if max_values[i] < cal_min[i]:
            cal_min[i] = max_values[i]


@pytest.mark.parametrize("count", [5, 8])
def test_calibration_follows_pololus_rule_ten_reads_per_call(count):
    """The C firmware (one reading per tick) and its Python reference against Pololu's rule, call by call."""
    rng = random.Random(10 + count)
    c, py = c_state(count, 2500), ref.FirmwareState.uncalibrated(count, 2500)
    pololu_min, pololu_max = [2500] * count, [0] * count
    raw = (ctypes.c_uint16 * 16)()
    for call in range(40):
        reads = [[rng.choice([rng.randint(80, 300), rng.randint(1500, 2500), rng.randint(0, 2500)])
                  for _ in range(count)] for _ in range(10)]
        for read in reads:
            raw[:count] = read
            lib.lf_calibrate_update(ctypes.byref(c), raw, count)
            calibrate_update(py.cal_min, py.cal_max, py.call, read)
        pololu_calibrate(pololu_min, pololu_max, reads)
        assert list(c.cal_min[:count]) == pololu_min == py.cal_min, call
        assert list(c.cal_max[:count]) == pololu_max == py.cal_max, call
        assert c.call_reads == 0 and py.call == []


def test_a_noise_spike_does_not_widen_the_calibrated_range():
    c = c_state(1, 2500)
    raw = (ctypes.c_uint16 * 16)()
    for k in range(30):  # three calls over white (~200 us), a black spike (2400 us) in the second
        raw[0] = 2400 if k == 13 else 200 + k % 3
        lib.lf_calibrate_update(ctypes.byref(c), raw, 1)
    assert c.cal_max[0] == 200 and c.cal_min[0] == 202  # the spike never became the maximum
    raw[0] = 2000
    for _ in range(5):  # a call cut short is not counted
        lib.lf_calibrate_update(ctypes.byref(c), raw, 1)
    lib.lf_reset(ctypes.byref(c), ref.IDLE)
    assert c.cal_max[0] == 200 and c.call_reads == 0
