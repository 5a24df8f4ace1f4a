"""Bad value files (``--gains``, ``--params``, ``--telemetry``: JSON and JSON Lines), one row each: exit 2, one
``error: …`` line naming the input and the fault, no traceback, in time (:mod:`bad_input`). A new fault of this
family is a new row."""

from __future__ import annotations

import json

import pytest

from bad_input import BadFiles, check_bad_input, check_in_fresh_process

HEADER = {"type": "header", "format": "lf-telemetry", "version": 1, "dt_s": 0.005, "sensors": 8}
SAMPLES = ('{"type":"sample","t":0.1,"pos":3500,"seen":1,"wl":1,"wr":1}\n'
           '{"type":"sample","t":0.2,"pos":3500,"seen":1,"wl":1,"wr":1}\n')


def _telemetry(header: dict) -> str:
    return json.dumps({**HEADER, **header}) + "\n" + SAMPLES


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> BadFiles:
    f = BadFiles(tmp_path_factory.mktemp("bad_value_files"))
    f.put("deep.json", "[" * 100_000 + "]" * 100_000)
    f.put("long_number.json", '{"control.kp": ' + "9" * 5000 + "}")
    f.put("not_json.json", "{control.kp: 3")
    f.put("list.json", "[1, 2]")
    f.put("gains_list.json", '{"gains": [1, 2]}')
    f.put("params_string.json", '{"parameters": "motion.mu=0.6"}')
    f.put("non_gain.json", '{"gains": {"motion.mu": 0.5}}')
    f.put("nan.json", '{"gains": {"control.kp": NaN}}')
    f.put("duplicate.json", '{"gains": {"control.kp": 20, "control.kd": 1, "control.kp": 30}}')
    f.put("duplicate_nested.json", '{"parameters": {"motion.mu": 0.6, "motion.mu": 0.9}}')
    f.put("tel_binary.jsonl", bytes(range(256)) * 4)
    f.put("tel_latin1.jsonl", json.dumps({**HEADER, "track": "ov\u00e9l"}, ensure_ascii=False).encode("latin-1")
          + b"\n" + SAMPLES.encode())
    f.put("tel_gains_abc.jsonl", _telemetry({"gains": {"control.kp": "abc"}}))
    f.put("tel_gains_null.jsonl", _telemetry({"gains": None}))
    f.put("tel_gains_mu.jsonl", _telemetry({"gains": {"motion.mu": 0.3}}))
    f.put("tel_track_123.jsonl", _telemetry({"track": 123}))
    f.put("tel_duplicate.jsonl", '{"type":"header","format":"lf-telemetry","version":1,"version":2,"dt_s":0.005,'
          '"sensors":8}\n' + SAMPLES)
    f.put("tel_long_number.jsonl", _telemetry({}) + '{"type":"sample","t":' + "1" * 5000 + "}\n")
    return f


# (command line with {name} placeholders, text the one error line must contain)
CASES = [
    # gains and parameter files
    ("lap --gains {deep.json}", "{deep.json}: JSON nested too deeply"),
    ("lap --gains {long_number.json}", "{long_number.json}: a whole number of 5000 digits; no value here has more than 40"),
    ("lap --params {long_number.json}", "{long_number.json}: a whole number of 5000 digits"),
    ("lap --gains {not_json.json}", "{not_json.json}: not JSON (column 2: Expecting property name"),
    ("lap --gains {list.json}", "expected an object"),
    ("lap --gains {gains_list.json}", '{gains_list.json}: "gains" must be an object of addresses and numbers, not an array'),
    ("lap --params {params_string.json}", '"parameters" must be an object of addresses and numbers, not a string'),
    ("lap --gains {non_gain.json}", "control.* parameters only"),
    ("lap --gains {nan.json}", "{nan.json}: control.kp: must be finite"),
    ("lap --gains {duplicate.json}", "{duplicate.json}: key 'control.kp' is given twice in one object"),
    ("tune --params {duplicate_nested.json}", "{duplicate_nested.json}: key 'motion.mu' is given twice"),
    ("lap --gains /dev/zero", "/dev/zero: is a character device, not a regular file"),
    ("lap --params /dev/null", "/dev/null: is a character device, not a regular file"),
    ("lap --gains {missing_dir}/g.json", "{missing_dir}/g.json: no such gains file"),
    ("lap --gains {dir}", "{dir}: is a folder, not a regular file"),
    # telemetry (JSON Lines)
    ("align --telemetry {tel_binary.jsonl}", "not UTF-8"),
    ("align --telemetry {tel_latin1.jsonl}", "not UTF-8"),
    ("align --telemetry {tel_gains_abc.jsonl}", "must be a finite number"),
    ("align --telemetry {tel_gains_null.jsonl}", "gains"),
    ("align --telemetry {tel_gains_mu.jsonl}", "control.* parameters only"),
    ("align --telemetry {tel_track_123.jsonl}", "track"),
    ("align --telemetry {tel_duplicate.jsonl}", "{tel_duplicate.jsonl}:1: key 'version' is given twice"),
    ("diagnose --telemetry {tel_long_number.jsonl}", "{tel_long_number.jsonl}:4: a whole number of 5000 digits"),
    ("align --telemetry /dev/zero", "/dev/zero: is a character device, not a regular file"),
    ("align --telemetry {missing_dir}/t.jsonl", "no such telemetry file"),
]


@pytest.mark.parametrize("row, needle", CASES, ids=[c[0] for c in CASES])
def test_bad_value_file_is_one_line_and_exit_2(files, row, needle, capsys):
    check_bad_input(row, needle, files, capsys)


def test_a_fresh_process_never_shows_a_traceback(files):
    check_in_fresh_process(["align", "--telemetry", files["tel_binary.jsonl"]])
