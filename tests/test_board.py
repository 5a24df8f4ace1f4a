"""Any 3pi program on the twin's model of the 3pi's board (twin.pil.board, twin/csrc/pil): programs of our own
(tests/firmware/board3pi: a register-level driver written for these tests, driving the lines the way libpololu-avr
does), each checked against an independent expectation: the LCD text it wrote and the ADC readings it printed
(the battery's 4.8 V through the 2/3 divider, the trimmer at mid travel), the wheel speed its PWM duty reaches (the
DC motor's no-load speed at duty x supply), the buttons it saw pressed (by the default operator reading its LCD, or
by a script), the notes it played (Timer1's frequency and the overflow count it timed them with), a lap it follows.
A program that writes garbage or never drives is a lap result with a reason, within the time limit.

Pololu's own line followers (3pi-linefollower, 3pi-linefollower-pid; 3pi-mazesolver in the maze) run when
LIBPOLOLU_AVR names a libpololu-avr source tree with the library built for the atmega328p (it never goes into the
project; see the README): the only skip CI keeps, as it builds nothing from Pololu. 27 of Pololu's other 3pi examples,
as HEX files beside the repository, run always (tests/test_pololu_examples.py).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from twin.core.lap import LapLimits
from twin.errors import TwinError

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCE = os.path.join(HERE, "firmware", "board3pi")
RUN_CLI = [sys.executable, "-m", "twin.run"]


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    """build(name, **defines) → the ELF of tests/firmware/board3pi/<name>.c, built once per set of defines."""
    gcc = shutil.which("avr-gcc")
    try:
        from twin.pil.mcu import glue

        glue()
    except TwinError as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI installs gcc-avr, simavr and libsimavr-dev before pip install -e .: {e}")
        pytest.skip(str(e))
    if not gcc:
        if os.environ.get("CI"):
            pytest.fail("avr-gcc is missing: CI installs gcc-avr and avr-libc")
        pytest.skip("avr-gcc is not installed")
    out, built = tmp_path_factory.mktemp("board3pi"), {}

    def make(name: str, **defines) -> str:
        key = (name, tuple(sorted(defines.items())))
        if key not in built:
            elf = str(out / f"{name}-{len(built)}.elf")
            subprocess.run([gcc, "-mmcu=atmega328p", "-DF_CPU=20000000UL", "-Os", "-Wall", "-Werror",
                            *(f"-D{k}={v}" for k, v in defines.items()), "-o", elf, os.path.join(SOURCE, f"{name}.c"),
                            os.path.join(SOURCE, "board3pi.c")], check=True, capture_output=True, timeout=120)
            built[key] = elf
        return built[key]

    return make


def hex_of(elf: str) -> str:
    out = elf[:-4] + ".hex"
    subprocess.run(["avr-objcopy", "-R", ".eeprom", "-O", "ihex", elf, out], check=True, timeout=60)
    return out


def three_pi(track: str = "oval"):
    from twin.core.digital_twin import DigitalTwin
    from twin.model.robots import THREE_PI, use_robot

    twin = DigitalTwin(track=track)
    use_robot(twin, THREE_PI)
    return twin


def run(path: str, timeout_s: float = 3.0, track: str = "oval", **kw):
    from twin.pil.board import run_board_lap
    from twin.pil.program import load_program

    return run_board_lap(three_pi(track), load_program(path), limits=LapLimits(timeout_s=timeout_s), **kw)


def texts(report) -> list[str]:
    return [" ".join(text.split()) for _, text in report.lcd]


def test_lcd_text_and_adc_readings_as_written_elf_and_hex_alike(build):
    elf = build("hello")
    lap, report = run(elf)
    assert not lap.completed and lap.failure == "timeout" and "did not drive" in lap.detail
    shown = texts(report)
    assert shown[0] == "Hello twin 3pi"
    battery_mv, trimmer = shown[1].split("mV t")
    # 4 AAA cells, 4.8 V, seen through the 2/3 divider against AVCC = 5 V: within one ADC step of 4800 mV
    assert abs(int(battery_mv) - 4800) <= 1.5 * 5000 / 1023 + 1
    assert abs(int(trimmer) - 2.5 / 5.0 * 1023) <= 1  # the trimmer at mid travel
    assert report.format == "elf" and report.ram_bytes is not None
    lap_hex, report_hex = run(hex_of(elf))
    assert report_hex.format == "hex" and report_hex.ram_bytes is None
    assert report_hex.lcd == report.lcd and report_hex.cycles == report.cycles and lap_hex.detail == lap.detail


@pytest.mark.parametrize("duty", [128, -96])
def test_pwm_duty_reaches_the_motor_model_wheel_speed(build, duty):
    lap, report = run(build("drive", LEFT=duty, RIGHT=duty), keep_trace=True)
    assert report.lap_start_s == pytest.approx(0.1, abs=0.002)  # the program drives after its 100 ms pause
    tr = lap.trace
    t = tr.time_s
    window = (t > 0.4) & (t < 0.8)
    measured = np.concatenate([tr.column("wheel_left_radps")[window], tr.column("wheel_right_radps")[window]])
    twin = three_pi()
    # inverted fast PWM: a line held at OCR = 0 and the other at OCR = |duty| drive |duty| of 256 counts
    expected = twin.motor().no_load_speed_wheel(duty / 256 * twin.power().nominal_v)  # the regulated 9.25 V
    assert np.all(np.sign(measured) == np.sign(duty))
    assert np.mean(measured) == pytest.approx(expected, rel=0.05)
    assert np.mean(tr.column("u_left_v")[window]) == pytest.approx(duty / 256 * 9.25, rel=1e-6)


def test_a_program_driving_the_line_backwards_is_judged_wrong_way_as_soon_as_it_is_25_cm_back(build):
    """Both motors at duty -96 from the start line: the robot follows the oval's straight backwards. The judge ends
    the lap as wrong_way (LapLimits.max_backtrack_m, 25 cm) instead of at the 30 s timeout: after 0.25 m at the
    motors' no-load wheel speed for that voltage (the spin-up adds a little), not before."""
    lap, report = run(build("drive", LEFT=-96, RIGHT=-96), timeout_s=30.0)
    assert lap.failure == "wrong_way" and "25 cm behind" in lap.detail, (lap.failure, lap.detail)
    twin = three_pi()
    speed = abs(twin.motor().no_load_speed_wheel(-96 / 256 * twin.power().nominal_v)) * twin.space.get("cad.R")
    assert 1.0 <= lap.simulated_s / (LapLimits().max_backtrack_m / speed) <= 1.25, (lap.simulated_s, speed)


def test_the_default_operator_presses_the_button_the_lcd_asks_for(build):
    lap, report = run(build("buttons"))
    assert [p.button for p in report.presses] == ["A", "C"]
    assert texts(report) == ["", "Press A", "A seen", "Press C", "C seen", "done"][-len(report.lcd):]
    times = dict((" ".join(text.split()), t) for t, text in report.lcd)
    a, c = report.presses
    assert times["Press A"] + 0.5 <= a.t < times["A seen"] < a.t + a.hold + 0.1  # seen once released
    assert times["Press C"] + 0.5 <= c.t < times["C seen"]
    assert not lap.completed and "did not drive" in lap.detail


def test_a_script_presses_at_a_time_and_on_a_screen(build, tmp_path):
    from twin.pil.board import load_script

    script = tmp_path / "presses.json"
    script.write_text('{"presses": [{"button": "B", "at": 0.3}, {"button": "A", "at": 1.0, "hold": 0.3},'
                      ' {"button": "C", "lcd": "press c"}]}')
    lap, report = run(build("buttons"), operator=load_script(str(script)))
    assert [(p.button, p.by) for p in report.presses] == [("B", "script"), ("A", "script"), ("C", "script")]
    b, a, c = report.presses
    assert b.t == pytest.approx(0.3, abs=1e-6) and a.t == pytest.approx(1.0, abs=1e-6) and a.hold == 0.3
    times = dict((" ".join(text.split()), t) for t, text in report.lcd)
    assert times["A seen"] > 1.3 > times["Press A"]  # B was not what it waited for
    assert c.t >= times["Press C"] and times["C seen"] > c.t


def test_notes_have_the_frequency_and_length_the_program_timed(build):
    _, report = run(build("buzzer"))
    assert len(report.notes) == 2
    (s1, e1, f1, d1), (s2, e2, f2, d2) = report.notes
    # phase-correct PWM at F_CPU with TOP = 10e6 / f: f = F_CPU / (2 TOP); the note lasts ms * f / 1000 overflows
    for (start, end, hz, duty), (f, ms) in zip(report.notes, [(440, 250), (1000, 100)]):
        top = 10_000_000 // f
        assert hz == pytest.approx(20e6 / (2 * top), rel=1e-9)
        assert end - start == pytest.approx((ms * f // 1000) * 2 * top / 20e6, abs=2e-4)
        assert duty == pytest.approx(0.5, abs=1e-3)
    assert s2 - e1 == pytest.approx(0.1, abs=0.002)
    assert texts(report)[-1] == "done"


def test_a_screen_rewritten_without_pause_is_seen_whole_as_it_changes(build):
    """A program that rewrites the LCD in a loop is never quiet for 5 ms: its screens are kept as each pass begins,
    whole (never half written), at most every 0.1 s, its count rising, and the last one is the final text."""
    lap, report = run(build("counter"), timeout_s=2.0)
    screens = [(t, text.split("\n")) for t, text in report.lcd if text.strip()]
    assert len(screens) >= 10, report.lcd  # ~2 s of passes
    counts = []
    for t, (first, second) in screens:
        assert first.strip() == "pass" and second.strip().isdigit(), (t, first, second)
        counts.append(int(second))
    assert counts == sorted(counts) and len(set(counts)) == len(counts)
    times = [t for t, _ in screens]
    assert min(b - a for a, b in zip(times, times[1:])) >= 0.1 - 1e-6
    assert report.lcd_final == report.lcd[-1][1] and int(report.lcd_final.split("\n")[1]) == max(counts)


def test_timer1_with_top_icr1_set_after_its_clock_counts_to_the_new_top(build):
    """Timer1 in fast PWM with TOP = ICR1, its clock started before ICR1 is written (OrangutanServos' order): clk/8
    and ICR1 = 9999 give 20 MHz / (8 * 10000) = 250 periods a second (datasheet 15.9.3), each with one compare match A
    and one input-capture flag at TOP, so 400 ms count 100 of each (± 1), on the screen about 0.4 s after power-up
    (simavr alone keeps TOP 0, an interrupt every few cycles, and never flags the capture at TOP)."""
    lap, report = run(build("timer1"), timeout_s=2.0)
    shown = [(t, text.split("\n")) for t, text in report.lcd if text.startswith("m")]
    assert shown, report.lcd
    t, (matches, captures) = shown[0]
    assert abs(int(matches[1:]) - 100) <= 1 and abs(int(captures[1:]) - 100) <= 1 and 0.4 < t < 0.6, shown[0]
    assert report.unmodelled == (), report.unmodelled  # the capture at TOP is modelled: no note


def test_timer1_phase_correct_matches_up_and_down_and_drives_oc1b(build):
    """Timer1 in phase-correct PWM with TOP = ICR1 (WGM 10), clk/8, ICR1 = 10000, OCR1B = 2500, COM1B = 2 on PB2
    (tests/firmware/board3pi/phase_pwm.c), counted over ~405 ms: 125 periods a second (20 MHz / (2 * 8 * 10000),
    datasheet, "Phase Correct PWM Mode"), each with two compare B matches (counting up and down) and one capture
    flag (TOP); PB2 changes twice a period as the pin-change interrupt reads it (a rise once), and a program's
    writes to PORTB leave it to the compare output; TCNT1 read in the compare interrupt is OCR1B plus the
    interrupt's latency counting up and minus about the same counting down (at most 20 counts = 160 cycles). The
    buzzer is OC1B: 125 Hz, duty 0.25. First, the interrupt flags (datasheet, "Reset and Interrupt Handling"):
    Timer2's overflow flag set while TOIE2 is off runs its interrupt once TOIE2 is set (L1), and a pin-change flag
    cleared by writing a one to PCIFR does not interrupt while one left set does (F0, then 1: "F1"). Last, Timer0's
    8-bit phase-correct PWM on PD6, timed the same way."""
    lap, report = run(build("phase_pwm"), timeout_s=3.0)
    shown = {text[0]: text for _, text in report.lcd if text}
    values = {line[0]: int(line[1:]) for text in shown.values() for line in text.split("\n") if line.strip()}
    assert values["L"] == 1 and values["F"] == 1, shown
    periods = values["C"]
    assert 49 <= periods <= 52 and values["W"] == 50, values
    # two a period, less the first period's match counting up: OCR1B, written after the start, is taken at TOP
    assert abs(values["B"] - 2 * periods) <= 2 and abs(values["P"] - 2 * periods) <= 2, values
    assert abs(values["R"] - periods) <= 1, values
    latency = values["U"] - 2500  # counts (8 cycles each) from the match to the interrupt's read of TCNT1
    # (the pin-change interrupt, served first, runs two more statements on a rise: up to 3 counts more down)
    assert 0 < latency <= 20 and 0 <= 2500 - values["D"] - latency <= 3, values
    note = report.notes[0]
    assert note[2] == pytest.approx(125.0, rel=1e-6) and note[3] == pytest.approx(0.25)
    # Timer0's 8-bit phase-correct PWM (WGM 1, clk/64, OCR0A = 64, COM0A = 2 on PD6): 20 MHz / (2 * 255 * 64) =
    # 612.7 periods a second, 61 in 100 ms; high 2 * 64 * 64 cycles = 1024 counts of Timer1 at clk/8. The glue
    # counts 2 (TOP + 1) timer clocks a period, not 2 TOP (docs/models.md): a pulse around BOTTOM is one timer clock
    # (64 cycles, 8 counts) longer
    assert abs(values["X"] - 61) <= 1 and 1024 <= values["H"] <= 1024 + 8 + 1, values


def test_garbage_on_the_lcd_lines_is_a_result_in_time(build):
    t0 = time.monotonic()
    lap, report = run(build("garbage"), timeout_s=1.5)
    assert not lap.completed and lap.failure == "timeout" and "did not drive" in lap.detail
    assert report.cycles == pytest.approx(1.5 * 20e6, rel=0.07)
    assert time.monotonic() - t0 < 60
    assert all(len(text.split("\n")) == 2 for _, text in report.lcd)


def test_unmodelled_peripherals_are_named_and_the_uart_lights_the_red_led(build):
    lap, report = run(build("peripherals"), timeout_s=0.5)
    assert [line.split(":")[0] for line in report.unmodelled] == ["SPI", "ADC0-5", "UART receive"]
    assert report.leds[-1][1:] == (True, False) and not lap.completed  # TX idles high on the red LED's line


def test_a_register_level_follower_laps_the_oval_deterministically(build):
    path = build("follower")
    lap, report = run(path, timeout_s=30.0, keep_trace=True)
    assert lap.completed, lap.detail
    assert [p.button for p in report.presses] == ["B"] and report.lap_start_s > report.presses[0].t
    assert lap.max_cross_track_m < 0.02 and 5.0 < lap.lap_time_s < 20.0
    again, report2 = run(path, timeout_s=30.0, keep_trace=True)
    assert again.lap_time_s == lap.lap_time_s and np.array_equal(again.trace.records, lap.trace.records)
    assert report2.lcd == report.lcd


def test_a_maze_solver_of_our_own_reaches_the_finish_spot(build):
    lap, report = run(build("maze"), timeout_s=60.0, track="maze", keep_trace=True)
    assert lap.completed and lap.detail == "finish reached", lap.detail
    assert lap.distance_m > lap.track_length_m  # it explored before it found the way
    assert lap.max_cross_track_m < 0.1 and [p.button for p in report.presses] == ["B"]
    xy = lap.trace.records[-1, 1:3]
    from mjcf.maze import Maze

    assert np.hypot(*(xy - Maze().finish_xy)) <= Maze().finish_radius_m


def cli(*args):
    return subprocess.run([*RUN_CLI, *args], capture_output=True, text=True, timeout=600)


def test_cli_runs_a_hex_on_the_3pi_and_reports_what_it_showed(build, tmp_path):
    done = cli("lap", "--firmware", hex_of(build("hello")), "--lap-timeout", "1", "--json", "--track", "oval")
    assert done.returncode == 0, done.stderr
    import json

    doc = json.loads(done.stdout)
    assert doc["completed"] is False and doc["failure"] == "timeout"
    assert doc["parameters"]["sensor.count"] == 5 and doc["parameters"]["power.regulator_voltage"] == 9.25  # the 3pi
    assert doc["parameters"]["motor.supply_voltage"] == 4.8  # its battery: four AAA NiMH cells
    board = doc["board"]
    assert board["format"] == "hex" and " ".join(board["lcd_final"].split()).endswith("t511")
    assert set(board["leds"]) == {"final", "changes", "lit_share"} and board["awake_share"] == 1.0


def test_a_sweep_runs_a_3pi_program_lap_by_lap_as_lap_does(build, tmp_path):
    """sweep --firmware PROGRAM: each grid point's lap is the lap `lap` runs with that value (a fresh operator for
    every lap presses as it did alone), on the 3pi; the program's own gains cannot be swept."""
    program = hex_of(build("follower"))
    common = ["--firmware", program, "--track", "oval", "--lap-timeout", "30"]
    done = cli("sweep", "motion.mu=0.6:1:2", "--seeds", "1", *common, "--json", "--out-dir", str(tmp_path / "s"))
    assert done.returncode == 0, done.stderr
    import json

    doc = json.loads(done.stdout)
    assert doc["base"] is None and doc["firmware"] == program
    for point in doc["points"]:
        lap = cli("lap", *common, "--set", f"motion.mu={point['motion.mu']}", "--json")
        assert lap.returncode == 0, lap.stderr
        assert point["completion_rate"] == 1.0 and point["median_lap_time_s"] == json.loads(lap.stdout)["lap_time_s"]
    refused = cli("sweep", "control.kp=10:20:2", *common, "--out-dir", str(tmp_path / "k"))
    assert refused.returncode == 2 and "keeps its own gains" in refused.stderr and refused.stderr.count("\n") == 1


def test_a_design_study_races_a_3pi_program_on_each_design_as_lap_does(build, tmp_path):
    """design --firmware PROGRAM: the designs start from the 3pi, are not tuned (the program's gains are its own),
    and each design's lap with seed 1 is the lap `lap` runs on that design."""
    program = hex_of(build("follower"))
    done = cli("design", "--grid", "cad.L=0.035,0.047", "--laps", "1", "--firmware", program, "--track", "oval",
               "--workers", "1", "--json", "--out-dir", str(tmp_path / "d"))
    assert done.returncode == 0, done.stderr
    import json

    doc = json.loads(done.stdout)
    assert doc["fixed"]["sensor.count"] == 5 and doc["fixed"]["motor.model"] == "pololu-3pi-30"
    times = []
    for d in doc["designs"]:
        assert d["ok"] and d["gains"] == {} and d["search"].startswith("not tuned"), d
        lap = cli("lap", "--firmware", program, "--track", "oval", "--seed", "1", "--set", f"cad.L={d['design']['cad.L']}",
                  "--json")
        assert lap.returncode == 0, lap.stderr
        assert d["median_lap_time_s"] == json.loads(lap.stdout)["lap_time_s"]
        times.append(d["median_lap_time_s"])
    assert times[0] != times[1] and os.listdir(tmp_path / "d" / "gains") == []
    refused = cli("design", "--grid", "control.kp=10,20", "--firmware", program, "--out-dir", str(tmp_path / "k"))
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr


def test_emulate_paces_a_program_that_sends_nothing_at_its_speed(build):
    """emulate --firmware PROGRAM streams at --speed times real time from power-up: a program that sends no line
    (the gate's LAP line is all there is) still takes the lap's simulated time / speed to report it, not just the
    time its simulation took. How fast the board runs is bench_pil.py's row, not this test's: the lap may come later
    than its pace only by what the emulator's own CPU time says it could not keep up with (on the slowest machine
    this ran on, a third as fast per core as the first and beside other tests, the board ran at ~0.6× real time)."""
    import json
    import socket
    import time

    emu = subprocess.Popen([*RUN_CLI, "emulate", "--firmware", hex_of(build("follower")), "--track", "oval", "--laps",
                            "1", "--speed", "2", "--tcp", "0", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    try:
        host, port = json.loads(emu.stdout.readline())["link"].split("//")[-1].rsplit(":", 1)
        t0 = time.monotonic()
        received = b""
        with socket.create_connection((host, int(port)), timeout=120) as s:
            while b",LAP," not in received and b",FAIL," not in received:
                chunk = s.recv(4096)
                assert chunk, received
                received += chunk
        waited = time.monotonic() - t0
        with open(f"/proc/{emu.pid}/stat") as f:  # its CPU time so far: utime, stime (fields 14, 15) in ticks
            fields = f.read().rsplit(")", 1)[1].split()
        cpu_s = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        assert emu.wait(timeout=60) == 0
    finally:
        emu.kill()
    gate = received.decode().strip().splitlines()[-1]  # $LFE,<ms since power-up>,LAP,<lap ms>*checksum
    simulated_s = int(gate.split(",")[1]) / 1000
    assert ",LAP," in gate and simulated_s > 8.0  # calibration, presses and a lap: several seconds to pace
    assert simulated_s / 2 * 0.95 <= waited, (waited, gate)  # paced: not sooner than its time at --speed 2
    # and no later than its pace, or its own work where that took longer (twice that: the machine is shared)
    assert waited <= 2 * max(simulated_s / 2, cpu_s) + 5.0, (waited, cpu_s, gate)


def test_bad_programs_and_inputs_are_one_line_and_exit_2(build, tmp_path):
    src = tmp_path / "main.c"
    src.write_text("int main(void) { for (;;) {} }\n")
    u4, m644 = tmp_path / "u4.elf", tmp_path / "m644.elf"
    subprocess.run(["avr-gcc", "-mmcu=atmega32u4", "-o", str(u4), str(src)], check=True)
    subprocess.run(["avr-gcc", "-mmcu=atmega644p", "-o", str(m644), str(src)], check=True)
    good = hex_of(build("hello"))
    lines = open(good).read().splitlines()
    truncated, damaged = tmp_path / "truncated.hex", tmp_path / "damaged.hex"
    truncated.write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    damaged.write_text("\n".join([lines[0][:-2] + ("00" if lines[0][-2:] != "00" else "01")] + lines[1:]) + "\n")
    script = tmp_path / "bad.json"
    script.write_text('{"presses": [{"button": "D", "at": 1}]}')
    cases = [
        (["--firmware", sys.executable], "not an AVR"),
        (["--firmware", str(u4)], "built for the atmega32u4"),
        (["--firmware", hex_of(str(m644))], "vector table has"),
        (["--firmware", str(truncated)], "truncated"),
        (["--firmware", str(damaged)], "checksum"),
        (["--firmware", good, "--set", "sensor.count=8"], "reads the board's 5 reflectance sensors"),
        (["--firmware", good, "--operator", str(script)], "button must be A, B or C"),
        (["--firmware", good, "--operator", str(tmp_path / "none.json")], "no such file"),
        (["--operator", str(script)], "--operator: presses buttons for a 3pi program"),
        (["--track", "maze"], "has no maze strategy"),
    ]
    for args, needle in cases:
        done = cli("lap", "--track", "oval", *args)
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and needle in done.stderr, (args, done.stderr)


POLOLU = os.environ.get("LIBPOLOLU_AVR")


@pytest.mark.skipif(not POLOLU, reason="LIBPOLOLU_AVR (a built libpololu-avr source tree) is not set")
@pytest.mark.parametrize("example, track", [("3pi-linefollower", "default"), ("3pi-linefollower-pid", "default"),
                                            ("3pi-mazesolver", "maze")])
def test_pololus_own_examples_lap_the_default_track_and_solve_the_maze(example, track, tmp_path):
    """Pololu's examples, built unmodified as their Makefile builds them (examples_templates/<example>/Makefile)."""
    src = os.path.join(POLOLU, "examples_templates", example)
    include = tmp_path / "include"
    (include / "pololu").mkdir(parents=True)
    for f in os.listdir(os.path.join(POLOLU, "pololu")):
        shutil.copy(os.path.join(POLOLU, "pololu", f), include / "pololu")
    shutil.copytree(os.path.join(POLOLU, "src"), include / "pololu", dirs_exist_ok=True)
    elf = str(tmp_path / f"{example}.elf")
    subprocess.run(["avr-gcc", "-g", "-Wall", "-mcall-prologues", "-mmcu=atmega328p", "-Os", f"-I{include}",
                    *(os.path.join(src, f) for f in os.listdir(src) if f.endswith(".c")), f"-L{POLOLU}",
                    "-Wl,-gc-sections", "-lpololu_atmega328p", "-Wl,-relax", "-o", elf], check=True, timeout=300)
    lap, report = run(hex_of(elf), timeout_s=60.0, track=track)
    assert lap.completed, lap.detail
    assert [p.button for p in report.presses] == ["B", "B"] and report.restarts == 1  # go, calibrate, go
    assert math.isfinite(lap.lap_time_s) and lap.max_cross_track_m < 0.05
