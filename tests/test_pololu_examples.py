"""Pololu's own 3pi example programs (libpololu-avr's ``examples_templates``, built unmodified, kept as the HEX a 3pi
owner flashes: ``../shared/pololu-examples/``, README and licence beside them) on the twin's 3pi board, each held to
what its source or Pololu's library documents: the text it writes on the LCD, the notes it plays, the LEDs it
blinks, how it drives the motors, how it answers buttons, what it sends on its UART.

Every expectation comes from Pololu's sources at commit 718e109 (github.com/pololu/libpololu-avr; cited
``examples_templates/NAME/test.c:LINE`` or ``src/…:LINE``), or from the board's documented inputs (the 3pi's 4.8 V
battery, the trimmer's voltage), never from the twin's output. Note frequencies are the equal-tempered scale that
OrangutanBuzzer documents (``src/OrangutanBuzzer/OrangutanBuzzer.cpp:316-332``: note = key + 12 octave, A4 = 57 =
440 Hz), within 0.5 % (its table is in tenths of a hertz, Timer1 divides 20 MHz by a whole TOP), each lasting its
length in whole periods of its frequency (``:276-281``, ``:85``: up to one period more); play() strings as
``src/OrangutanBuzzer/OrangutanBuzzer.h:162-203`` documents them (T120, a quarter note 500 ms, O4, L4, V15 by
default; '>' and '<' one octave for the next note; MS plays half the length). A volume V sets OCR1B = OCR1A >> (16 -
V) (``OrangutanBuzzer.cpp:291``): a duty of 2^(V-16).

The folder is found beside the repository (``<clone>/../shared/pololu-examples``); without it, or without simavr's
glue, the tests skip, except under CI (``CI`` set), where each fails naming what is missing. Programs of our own for
the same board are in tests/test_board.py; Pololu's line followers are not among these HEX files on purpose (they
still need LIBPOLOLU_AVR, see test_board.py).
"""

from __future__ import annotations

import math
import re

import pytest

from pololu_helpers import examples  # noqa: F401  (the fixture)
from pololu_helpers import (TwinError, adc10, check_notes, first_time, hex_path, hz, led_changes, lit_share, motor_volts,
                            run, screens, timed)


# --- the LCD ----------------------------------------------------------------------------------------------------

@pytest.mark.quick
def test_lcd1_scrolls_hello_right_three_times_then_left_on_the_second_line(examples):
    """examples_templates/lcd1/test.c:20-28: "Hello" at (0, 0), lcd_scroll right 3 times every 200 ms; cleared,
    "Hello" at (3, 1), scrolled left 3 times every 200 ms; and again."""
    _, report, _ = run("lcd1", 1.8)
    shown = [(t, s) for t, s in timed(report) if s]
    expected = ["Hello", " Hello", "  Hello", "   Hello", "|   Hello", "|  Hello", "| Hello", "|Hello", "Hello"]
    assert [s for _, s in shown[:len(expected)]] == expected
    steps = [b - a for (a, _), (b, _) in zip(shown, shown[1:len(expected)])]
    assert steps == pytest.approx([0.2] * len(steps), abs=0.01)  # delay_ms(200) and lcd_scroll(.., 200) (:21-27)


def test_lcd2_shows_a_mood_character_after_each_button(examples):
    """lcd2/test.c:81-87: five custom characters loaded, "mood: ?" shown; :91-110: after the first press of any
    button a randomly chosen custom character (codes 0-4) replaces the '?' at column 6, and a new one after each
    press."""
    _, report, _ = run("lcd2", 2.0, (("A", 0.4, None, 0.2), ("C", 1.2, None, 0.2)))
    shown = timed(report)
    assert [s for _, s in shown if s.startswith("mood")][0] == "mood: ?"
    after = [s for t, s in shown if t > 0.6]
    assert after and all(re.fullmatch(r"mood: [▒▁▂▃▄▅▆▇█]", s) for s in after), after  # a custom glyph, never ROM text


def test_lcd3_hello_world_prints_wraps_scrolls_and_shows_the_trimpot(examples):
    """lcd3-hello-world/test.c: "hello" 200 ms after clear (:22-25), "world" on line 2 200 ms later (:27); after 2 s
    'A'..'z' one per 50 ms, wrapping onto line 2 after 8 (:33-37); "Hex Dec" then rows "%03X %3d" for i = 0..500
    step 50, each scrolling the previous one up (:43-49); at last "Trimpot:" over the trimmer's "%4u mV" (:53-59),
    here 2500 mV (mid travel, AVCC 5 V) within one ADC step."""
    _, report, _ = run("lcd3-hello-world", 16.0)
    shown = timed(report)
    hello, world = first_time(report, "hello"), first_time(report, "hello|world")
    assert world - hello == pytest.approx(0.2, abs=0.01)
    a = first_time(report, "A")
    assert a - world == pytest.approx(2.0, abs=0.02)
    assert first_time(report, "ABCDEFGH|I") - a == pytest.approx(8 * 0.05, abs=0.01)
    rows = [f"{i:03X} {i:3d}" for i in range(0, 501, 50)]
    for above, below in zip(rows, rows[1:]):
        assert f"{above}|{below}" in [s for _, s in shown], (above, below)
    last = shown[-1][1]
    assert last.startswith("Trimpot:|") and last.endswith(" mV")
    assert abs(int(last.split("|")[1].split()[0]) - 2500) <= 5000 / 1023 + 1


# --- LEDs and digital lines -------------------------------------------------------------------------------------

@pytest.mark.quick
def test_led1_blinks_red_for_a_second_then_green_for_half_a_second(examples):
    """led1/test.c:19-26: red on 1 s, off 1 s, green on 0.5 s, off 0.5 s, over and over."""
    _, report, _ = run("led1", 3.3)
    red, green = led_changes(report, red=True), led_changes(report, red=False)
    assert [v for _, v in red] == [True, False, True] and [v for _, v in green] == [True, False]
    assert red[0][0] < 0.01
    assert [red[1][0] - red[0][0], green[0][0] - red[1][0], green[1][0] - green[0][0], red[2][0] - green[1][0]] == \
        pytest.approx([1.0, 1.0, 0.5, 0.5], abs=0.003)


def test_digital1_lights_red_while_pc1_reads_high_through_its_pull_up(examples):
    """digital1/test.c:21-32: PC1 an input with its pull-up reads high with nothing pulling it low, so PD1 (the red
    LED) is driven high, and stays so."""
    _, report, _ = run("digital1", 0.5)
    assert led_changes(report) == [(pytest.approx(0.0, abs=0.005), True)]


@pytest.mark.parametrize("trimmer_v", [1.0, 4.0])
def test_analog1_dims_the_red_led_as_the_trimmer_reads(examples, trimmer_v):
    """analog1/test.c:22-48: the trimmer averaged over 20 8-bit readings (avg), the red LED off for 256 - avg µs and on
    for avg + 1 µs: lit (avg + 1) / 257 of the time, avg = V / 5 V * 256 (8-bit ADC, ATmega328P datasheet 24.7). Far
    faster than a 1 ms physics step shows: the brightness is the LED's time lit, counted to the cycle; the loop's own
    instructions (the ADC's bookkeeping, a few µs a pass, while the LED is on) add to the on time: 0.02 of slack."""
    _, report, _ = run("analog1", 1.0, trimmer_v=trimmer_v)
    avg = min(255, int(trimmer_v / 5.0 * 256))
    assert lit_share(report) == pytest.approx((avg + 1) / 257, abs=0.02)


def test_servo_control_using_delays_pulses_pd1_every_20_ms(examples):
    """servo-control-using-delays/test.c:83-117: eight 2 ms slots and 4 ms more, 20 ms a pass; in slot 1 PD1 (the red
    LED) is high for s[1] µs, 1200..1800, then low: a rising edge every 20 ms, lit 6-9 % of the time."""
    _, report, _ = run("servo-control-using-delays", 1.0)
    rises = [t for t, v in led_changes(report) if v]
    periods = [b - a for a, b in zip(rises, rises[1:])]
    assert len(rises) >= 40 and periods == pytest.approx([0.020] * len(periods), abs=0.0015)
    assert 0.06 <= lit_share(report) <= 0.09  # the time lit, counted to the cycle


# --- the buzzer -------------------------------------------------------------------------------------------------

@pytest.mark.quick
def test_simple_test_says_hello_plays_an_arpeggio_and_alternates_the_leds(examples):
    """simple-test/test.c:5 "Hello!"; :7 play("L16 ceg>c"): C4 E4 G4 C5, 125 ms each (a sixteenth at T120);
    :9-20 green then red, each 100 ms, over and over."""
    _, report, _ = run("simple-test", 1.0)
    assert screens(report)[-1] == "Hello!"
    check_notes(report.notes, [("C4", 125), ("E4", 125), ("G4", 125), ("C5", 125)])
    green, red = led_changes(report, red=False), led_changes(report, red=True)
    assert green[0][1] and green[0][0] < red[0][0]
    flips = sorted(t for t, _ in green + red)
    gaps = [b - a for a, b in zip(flips, flips[1:]) if b - a > 0.01]  # red and green flip together
    assert len(gaps) >= 8 and gaps == pytest.approx([0.1] * len(gaps), abs=0.003)


# buzzer1/test.c:26-27 and :49 (the melody's first twelve entries: note, ms; None a rest)
BUZZER1 = [("E5", 100), (None, 25), ("E5", 125), (None, 125), ("E5", 125), (None, 125), ("C5", 125), ("E5", 250),
           ("G5", 250), (None, 250), ("G4", 250), (None, 250)]


def test_buzzer1_plays_its_melody_note_by_note_and_shows_each_note_number(examples):
    """buzzer1/test.c:77-87: each entry played at volume 15 as the last ends, its note number (key + 12 octave) on
    line 2 (E5 = 64); "Music!" on line 1 (:71)."""
    _, report, _ = run("buzzer1", 2.2, ())
    check_notes(report.notes, BUZZER1)
    assert screens(report)[1] == "Music!|64"
    assert "Music!|67" in screens(report)  # G5 = 7 + 12 * 5


def test_buzzer1_top_button_stops_the_melody(examples):
    """buzzer1/test.c:96-103: the top button (C on the 3pi, src/OrangutanPushbuttons/OrangutanPushbuttons.h:76)
    silences the buzzer and ends the melody: no note starts after it."""
    _, report, _ = run("buzzer1", 2.0, (("C", 0.9, None, 0.2),))
    assert report.notes and report.notes[-1][1] <= 0.9 + 0.11
    assert all(start < 0.9 + 0.1 for start, *_ in report.notes)


def test_buzzer2_answers_each_button_with_its_melody(examples):
    """buzzer2/test.c:76-78 "Press a|button.."; A (the bottom button, OrangutanPushbuttons.h:78) plays A5 for 200 ms
    and shows "note A5" (:59-70); B (middle) plays "! V8 cdefgab>cbagfedc", quarter notes at V8 (duty 1/256), showing
    "C Major|RAM ->" (:52-57); C (top) plays the fugue from flash, "! O5 L16 agafaea…" (:28, :44-50)."""
    presses = (("A", 0.6, None, 0.2), ("B", 1.4, None, 0.2), ("C", 5.6, None, 0.2))
    _, report, _ = run("buzzer2", 6.9, presses)
    shown = screens(report)
    assert shown[1:] == ["Press a|button..", "note A5", "C Major|RAM ->", "Fugue!|flash ->"]
    shown_at = first_time(report, "Fugue!|flash ->")  # played, then printed (:46-48)
    a5, scale, fugue = report.notes[0], report.notes[1:9], [n for n in report.notes if n[0] > shown_at - 0.005]
    check_notes([a5], [("A5", 200)])
    check_notes(scale, [(n, 500) for n in ("C4", "D4", "E4", "F4", "G4", "A4", "B4", "C5")], duty=2 ** (8 - 16))
    check_notes(fugue, [(n, 125) for n in ("A5", "G5", "A5", "F5", "A5", "E5", "A5")])


def test_buzzer3_plays_the_rhapsody_blinks_and_times_twenty_counts(examples):
    """buzzer3/test.c:63 "O6 T40 L16 d#<b<f#<d#<f#<bd#f#" "T80 c#<b-<f#<c#<f#<b-c#8": sixteenths of 375 ms, then of
    187.5 ms; :85-97 "blink!" while red blinks 500 ms on, 500 ms off, 8 times; :99-124 then "timing", and the
    longest of 8000 ~250 µs waits on Timer0 "max=20" (:32-35: "The maximum recorded time should be 20")."""
    _, report, _ = run("buzzer3", 10.6, ())
    check_notes(report.notes, [(n, 375) for n in ("D#6", "B5", "F#5", "D#5", "F#5", "B5", "D#6", "F#6")] +
                [(n, 187.5) for n in ("C#6", "B-5", "F#5", "C#5", "F#5", "B-5")] + [("C#6", 375)], gap_ms=1.0)
    red = led_changes(report)
    rises = [t for t, v in red if v][:8]
    assert len(rises) == 8 and [b - a for a, b in zip(rises, rises[1:])] == pytest.approx([1.0] * 7, abs=0.01)
    assert all(f - r == pytest.approx(0.5, abs=0.005) for (r, v), (f, _) in zip(red, red[1:]) if v)
    shown = screens(report)
    # "max=20" printed, the loop's next pass at once writes "blink!" over "timing" (:85-86)
    assert shown[1] == "blink!" and "timing" in shown and shown[-1] == "blink!|max=20"


def test_pushbuttons2_beeps_on_press_and_release_and_shows_the_time(examples):
    """pushbuttons2/test.c:30-54: a press of A, B, C plays A4, B4, C5, its release A5, B5, C6, each 50 ms at volume 10
    (duty 2^-6); :56-64: the time since power-up as [m]m:ss.cc, printed on line 2 with printf, whose putchar scrolls
    it up when the line fills (src/OrangutanLCD/OrangutanLCD.cpp:146-212): line 1 shows the clock."""
    presses = (("A", 0.5, None, 0.2), ("B", 1.0, None, 0.2), ("C", 1.5, None, 0.2))
    _, report, _ = run("pushbuttons2", 2.0, presses)
    expected = [(note, p.t + p.hold * released) for p, notes in zip(report.presses, (("A4", "A5"), ("B4", "B5"),
                ("C5", "C6"))) for released, note in enumerate(notes)]
    assert len(report.notes) == len(expected) == 6, report.notes
    for (start, end, f, duty), (note, at) in zip(report.notes, expected):
        assert f == pytest.approx(hz(note), rel=5e-3) and duty == pytest.approx(2 ** -6, rel=0.02), (note, f, duty)
        assert 0.049 <= end - start <= 0.051 + 1 / f and at <= start < at + 0.03, (note, start)  # debounced: 15 ms
    clocks = [(t, s.split("|")[0]) for t, s in timed(report) if t > 0.1]
    assert len(clocks) >= 10
    for t, clock in clocks:
        m, s = re.fullmatch(r" ?(\d+):(\d\d\.\d\d)", clock).groups()
        assert 60 * int(m) + float(s) == pytest.approx(t, abs=0.06), (t, clock)


def test_pushbuttons1_names_the_top_or_bottom_button_and_its_release(examples):
    """pushbuttons1/test.c:19-33: "Waiting" until the top (C) or bottom (A) button; "top down" or "bot down" while it
    is held, "released" once let go, for 1 s, then "Waiting" again; B is not waited for."""
    presses = (("B", 0.3, None, 0.2), ("A", 0.8, None, 0.3), ("C", 2.4, None, 0.3))
    _, report, _ = run("pushbuttons1", 3.8, presses)
    assert [s for s in screens(report) if s] == ["Waiting", "bot down", "released", "Waiting", "top down", "released",
                                                 "Waiting"]
    _, a, c = report.presses
    assert a.t <= first_time(report, "bot down") < a.t + 0.03
    released = [t for t, s in timed(report) if s == "released"]
    assert a.t + a.hold <= released[0] < a.t + a.hold + 0.03 and c.t + c.hold <= released[1] < c.t + c.hold + 0.03
    waiting = [t for t, s in timed(report) if s == "Waiting"]
    assert waiting[1] - released[0] == pytest.approx(1.0, abs=0.02)


# --- motors and the trimmer -------------------------------------------------------------------------------------

def test_motors2_at_mid_travel_shows_the_pot_and_stands_still(examples):
    """motors2/test.c:24-47: "pot=" the trimmer (0-1023), "spd=" (512 - pot) / 2 (C's division, toward zero), both
    motors at that speed, green lit forward, red backward: at mid travel speed 0, LEDs off, no drive."""
    lap, report, _ = run("motors2", 1.0, (), trace=True)
    first, second = screens(report)[-1].split("|")
    pot = int(first.removeprefix("pot="))
    assert abs(pot - adc10(2.5)) <= 1 and second == f"spd={int((512 - pot) / 2)}" == "spd=0"
    assert not any(r or g for _, r, g in report.leds)
    tr = lap.trace  # (from the motors' first configuration on: a sub-millisecond glitch as the timers start)
    later = tr.time_s > 0.05
    assert later.sum() > 500 and not tr.column("u_left_v")[later].any() and not tr.column("u_right_v")[later].any()


def test_motors2_with_the_trimmer_turned_down_drives_forward_with_green(examples):
    """motors2/test.c:32-44 with the trimmer at 1 V: pot ≈ 205, speed (512 - pot) / 2 forward on both motors, green
    lit, red off."""
    lap, report, _ = run("motors2", 0.6, (), trimmer_v=1.0, trace=True)
    first, second = screens(report)[-1].split("|")
    pot = int(first.removeprefix("pot="))
    speed = int((512 - pot) / 2)
    assert abs(pot - adc10(1.0)) <= 1 and second == f"spd={speed}"
    assert report.leds and report.leds[-1][1:] == (False, True)
    tr = lap.trace
    for side in ("u_left_v", "u_right_v"):
        assert tr.column(side)[-1] == pytest.approx(motor_volts(speed), abs=motor_volts(1)), side


@pytest.mark.parametrize("trimmer_v", [2.5, 4.0])
def test_motors1_drives_as_the_trimmer_says_and_blinks_faster_the_faster(examples, trimmer_v):
    """motors1/test.c:24-39: speed = pot / 2 - 256 on both motors; the red LED on, then off, each for 256 - |speed| ms.
    Mid travel: speed -1 or 0, 255-256 ms; 4 V: pot ≈ 819, speed ≈ 153 forward, 103 ms."""
    lap, report, _ = run("motors1", 1.2, (), trimmer_v=trimmer_v, trace=True)
    pot = adc10(trimmer_v)
    speeds = {int(p) // 2 - 256 for p in (math.floor(pot) - 1, math.floor(pot), math.floor(pot) + 1)}
    half = [b - a for (a, _), (b, _) in zip(led_changes(report), led_changes(report)[1:])]
    assert len(half) >= 3
    assert min(256 - abs(s) for s in speeds) / 1e3 - 0.001 <= min(half) <= max(half) <= \
        max(256 - abs(s) for s in speeds) / 1e3 + 0.003, half
    if trimmer_v > 3:
        u = lap.trace.column("u_left_v")[-1], lap.trace.column("u_right_v")[-1]
        assert all(min(motor_volts(s) for s in speeds) - 1e-6 <= x <= max(motor_volts(s) for s in speeds) + 1e-6
                   for x in u), u


def test_analog2_on_the_3pi_shows_the_trimmer_and_the_battery(examples):
    """analog2/test.c:49-57: "select|device", 1 s, "A  B  C|LV SV 3p"; C (the 3pi) → "  3pi| Robot" (:75-78); then
    every 50 ms the trimmer in mV and read_battery_millivolts() (:92-122): 2500 mV at mid travel and the 3pi's
    4.8 V (four AAA cells), through the 2/3 divider on ADC6 (src/OrangutanAnalog/OrangutanAnalog.cpp:430-436),
    within an ADC step or two."""
    from twin.model.robots import THREE_PI

    _, report, _ = run("analog2", 3.0, (("C", None, "LV SV 3p", 0.2),))
    shown = [s for s in screens(report) if s]
    assert shown[:3] == ["select|device", "A  B  C|LV SV 3p", "  3pi| Robot"]
    assert first_time(report, "A  B  C|LV SV 3p") - first_time(report, "select|device") == pytest.approx(1.0, abs=0.01)
    trimmer, battery = (int(line.split()[0]) for line in shown[-1].split("|"))
    step = 5000 / 1023
    assert abs(trimmer - 2500) <= step + 1 and abs(battery - THREE_PI.battery_v * 1e3) <= 2 * 1.5 * step + 1


# --- serial -----------------------------------------------------------------------------------------------------

def test_serial1_greets_on_its_uart_at_each_press_of_the_middle_button(examples):
    """serial1/test.c:117-123: the middle button (B) sends "Hi there!\\r\\n" on TXD, once a press."""
    _, report, lines = run("serial1", 2.0, (("B", 0.5, None, 0.2), ("A", 1.0, None, 0.2), ("B", 1.5, None, 0.2)))
    assert [line for _, line in lines] == ["Hi there!\r\n"] * 2
    assert [round(t, 1) for t, _ in lines] == pytest.approx([0.6, 1.6], abs=0.11)  # drained every 0.1 s


def test_the_serial_master_alone_looks_for_its_slave_and_never_connects(examples):
    """3pi-serial-master/master.c:166-174: "Master" on the LCD, 0x81 sent, six bytes awaited for 50 ms, again; with
    no slave on its serial port it never shows "Connect" (:176-180) and never drives."""
    lap, report, _ = run("3pi-serial-master", 1.5, ())
    assert set(s for s in screens(report) if s) == {"Master"}
    assert report.lap_start_s is None and "did not drive" in lap.detail


def test_the_serial_slave_alone_waits_silently_for_commands(examples):
    """3pi-serial-slave/slave.c:382-395: the LCD cleared, the receiver started at 115.2 kbaud, then nothing until a
    command byte arrives: no text, no note, no drive, nothing sent."""
    lap, report, lines = run("3pi-serial-slave", 1.5, ())
    assert all(not s for s in screens(report)) and report.notes == () and lines == []
    assert report.lap_start_s is None
    assert any(u.startswith("UART receive") for u in report.unmodelled)  # the board names the unconnected RX


# --- the 3pi's own demo -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, wait_s", [("3pi-demo-program", 0.0), ("3pi-demo-or-serial-slave", 0.5)])
def test_the_3pi_demo_welcomes_asks_for_b_and_opens_its_menu(examples, name, wait_s):
    """3pi-demo-program/test.c:22-48 and :444-531 (3pi-demo-or-serial-slave/demo.c:26-50, :473-574, which first waits
    0.5 s for a serial master, :483-490): the welcome tune ">g32>>c32" (G5, C6, 62.5 ms each, :65) and three
    screens of 1 s each, " Pololu|3π Robot" (0xF7 is π in the LCD's ROM), "Demo|Program", "Use B to|select.", then
    "Press B|-try it!"; B beeps "!e32" (E4) and, let go, "  Thank|  you!" with ">>c32>g32" (C6, G5), "  Main|  Menu"
    for 1 s, then the first entry, "Battery"; B there shows the battery, "NNNNmV" (:137-145), 4.8 V on the 3pi."""
    from twin.model.robots import THREE_PI

    _, report, _ = run(name, 7.9, None)  # the default operator: B asked for, B in the menu
    shown = timed(report)
    texts = [s for _, s in shown if s]
    assert texts[:7] == [" Pololu|3π Robot", "Demo|Program", "Use B to|select.", "Press B|-try it!", " Thank|  you!",
                         "  Main|  Menu", texts[6]]
    assert texts[6].startswith("Battery|") and "A" in texts[6] and "B C" in texts[6]
    times = [first_time(report, s) for s in texts[:4]]
    assert wait_s <= times[0] <= wait_s + 0.1  # (after the LCD's own start-up)
    # delay_ms(1000) (test.c:422) is a busy loop of delayMicroseconds(1000) (src/OrangutanTime/OrangutanTime.cpp:
    # 157-161) that interrupts (the clock's Timer2 overflow, the tune) make longer, never shorter
    assert all(1.0 <= b - a <= 1.04 for a, b in zip(times, times[1:])), times
    check_notes(report.notes[:2], [("G5", 62.5), ("C6", 62.5)])
    press = report.presses[0].t
    beep, thanks = report.notes[2], report.notes[3:5]
    assert press <= beep[0] < press + 0.05
    check_notes([beep], [("E4", 62.5)])
    check_notes(thanks, [("C6", 62.5), ("G5", 62.5)])
    assert thanks[0][0] >= press + report.presses[0].hold
    assert [p.button for p in report.presses][:2] == ["B", "B"]
    battery = [s.split("|")[0] for s in texts if re.match(r"\d+mV\|", s)]
    assert battery and all(abs(int(b[:-2]) - THREE_PI.battery_v * 1e3) <= 16 for b in battery), battery


# --- the watchdog and encoders ----------------------------------------------------------------------------------

def test_wdt_counts_down_while_a_button_is_held_and_the_watchdog_resets_it(examples):
    """wdt/test.c:31-45: "boot" and four dots 150 ms apart, then the watchdog at 2 s; :53-62 the last reset's cause,
    "POWER-ON" after power-up; :64-91 " BUTTON " while nothing is held; a held button stops wdt_reset() and shows
    "WD s.cc" counting down from 2 s; held past 2 s, the watchdog resets the MCU: "boot" again, then "WATCHDOG"."""
    _, report, _ = run("wdt", 5.2, (("B", 1.45, None, 3.0),))
    press = report.presses[0].t
    shown = timed(report)
    texts = [s for _, s in shown if s]
    assert texts[:6] == ["boot", "boot.", "boot..", "boot...", "boot....", "POWER-ON| BUTTON"]
    dots = [first_time(report, s) for s in texts[:5]]
    assert [b - a for a, b in zip(dots, dots[1:])] == pytest.approx([0.15] * 4, abs=0.01)
    countdown = [(t, s.split("|")[1]) for t, s in shown if s.startswith("POWER-ON|WD ")]
    assert len(countdown) >= 5
    for t, text in countdown:
        assert float(text[3:-1]) == pytest.approx(max(0.0, 2.0 - (t - press)), abs=0.12), (t, text)  # :78-82
    reboot = [t for t, s in shown if s == "boot" and t > press]
    # WDTO_2S: 256K cycles of the 128 kHz watchdog oscillator (datasheet 10.9.2), whose frequency varies with supply
    assert reboot and reboot[0] == pytest.approx(press + 2.0, abs=0.2)
    assert texts[-1].startswith("WATCHDOG|")


def test_wheel_encoders1_counts_nothing_on_a_3pi_without_encoders(examples):
    """wheel-encoders1/test.c:25-51: encoder inputs on PC2-PC5 (the 3pi's sensor lines, nothing turning them): the
    counts of motor 1 at (0, 0) and motor 2 at (4, 0) stay 0, and no "Error" is shown."""
    _, report, _ = run("wheel-encoders1", 0.6)
    assert screens(report)[-1] == "0   0" and not any("Error" in s for s in screens(report))


# --- Timer1's phase-correct PWM with interrupts: OrangutanServos and OrangutanPulseIn ----------------------------

def test_servos1_pulses_pd1_for_1700_us_every_20_ms(examples):
    """OrangutanServos (src/OrangutanServos/OrangutanServos.cpp:73-196, :434-444) as servos1/test.c:44-53 starts it,
    servo 1 on PD1 (the red LED) at 1700 µs: Timer1 phase-correct with TOP = ICR1 = 25000 at 20 MHz, a 2.5 ms slot
    per servo, eight slots; in a servo's slot its pin is toggled at the down-counting match with OCR1B and again at
    the up-counting one (datasheet, "Phase Correct PWM Mode": two matches a period), high for the target width once every 20 ms. Read
    once the target is in force (from 0.2 s on): before, OCR1B is 0 and its one match a period, at BOTTOM, leaves the
    pin high."""
    rises = [t for t, v in led_changes(run("servos1", 1.0)[1]) if v and t >= 0.2]
    periods = [b - a for a, b in zip(rises, rises[1:])]
    assert len(periods) >= 38 and periods == pytest.approx([0.020] * len(periods), abs=0.0015)
    lit = [run("servos1", t)[1].led_lit_s[0] for t in (0.2, 1.0)]
    assert (lit[1] - lit[0]) / 0.8 == pytest.approx(1700e-6 / 0.020, rel=0.01)  # the period: 2 (TOP + 1) clocks


def test_pulsein1_pulses_pd1_for_the_trimmer_s_width_in_its_servo_slot(examples):
    """pulsein1/test.c:33, :43, :61: servo 0 on PD1 at 1250 + trimmer / 2 µs (1505 µs at mid travel) by
    OrangutanServos, as servos1's. Its main loop also writes the LCD all the time, and OrangutanLCD's send() keeps
    PORTD before each byte and writes it back after (pulsein1.hex: in r16, 0x0b at 0x34e, out 0x0b, r16 at 0x37a):
    when the servo's interrupt toggles PD1 in between, the write-back undoes it and PD1 stays high to its next
    slot. That race is the program's own, on the robot as here (measured: 18 of the 40 slots from 0.2 s to 1 s show
    a clean pulse). Each clean pulse (at most two 1 ms steps lit) starts on the 20 ms grid."""
    changes = [(t, v) for t, v in led_changes(run("pulsein1", 1.0)[1]) if t >= 0.2]
    pulses = [(a, b - a) for (a, up), (b, _) in zip(changes, changes[1:]) if up]
    short = [a for a, width in pulses if width <= 0.0025]
    assert len(short) >= 13  # of 40 slots: a third
    assert all(abs((a - short[0] + 0.01) % 0.020 - 0.01) <= 0.0015 for a in short)


def test_pulsein1_sees_d0_held_high_by_its_pull_up(examples):
    """pulsein1/test.c:47 PD0 an input with its pull-up, nothing driving it: after 100 ms without a change
    "D0: HIGH" on line 1 and line 2 blank (:70-77)."""
    _, report, _ = run("pulsein1", 0.8, ())
    assert screens(report)[-1] == "D0: HIGH"


def test_pulsein2_measures_the_buzzers_pwm_frequency_and_duty(examples):
    """pulsein2/test.c:36 "!L4 MS EDCDEEE2…" (E4 first, 330 Hz at V15, duty 50 %); :64-84 while a note sounds its PB2
    pulses are timed by pin-change interrupts and Timer2's ticks: "330 Hz" on line 1, "DC: 50%" on line 2. Needs OC1B
    to drive PB2 in Timer1's phase-correct mode and OrangutanTime's overflow interrupt, masked for a few cycles on
    every read of its clock, to run once unmasked (datasheet, "Reset and Interrupt Handling": a flag is remembered until it is enabled)."""
    _, report, _ = run("pulsein2", 0.3, ())
    check_notes(report.notes[:1], [("E4", 250)])
    first, second = screens(report)[-1].split("|")
    assert abs(int(first.split()[0]) - hz("E4")) <= 2 and second == "DC: 50%"


def test_servos_and_buzzer_plays_its_fugue_then_asks_for_a_button(examples):
    """servos-and-buzzer/test.c:48-49 the fugue "! O5 L16 agafaea…" from flash (sixteenths, 125 ms); :135-153
    "Fugue" and a dot every 200 ms, 500 ms more, then "Press a|button"."""
    _, report, _ = run("servos-and-buzzer", 1.3, ())
    check_notes(report.notes, [(n, 125) for n in ("A5", "G5", "A5", "F5", "A5", "E5", "A5", "D5", "A5", "C#5")])
    texts = [s for s in screens(report) if s]
    assert texts == ["Fugue", "Fugue.", "Fugue..", "Fugue...", "Press a|button"]
    assert first_time(report, "Press a|button") - first_time(report, "Fugue...") == pytest.approx(0.5, abs=0.01)


def test_a_trimmer_outside_the_supply_is_refused_before_the_run(examples):
    """The trimmer divides AVCC (5 V): run_board_lap refuses another voltage in one line, naming it."""
    from twin.core.digital_twin import DigitalTwin
    from twin.model.robots import THREE_PI, use_robot
    from twin.pil.board import run_board_lap
    from twin.pil.program import load_program

    twin = DigitalTwin(track="oval")
    use_robot(twin, THREE_PI)
    with pytest.raises(TwinError, match=r"trimmer_v: .* got 5\.5"):
        run_board_lap(twin, load_program(hex_path("led1")), trimmer_v=5.5)
