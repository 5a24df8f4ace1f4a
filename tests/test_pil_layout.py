"""The processor in the loop's mirrored structs (twin.pil.layout), field by field, three ways:

* the glue's table (``lf_avr_layout``) equals Python's mirrors: checked when the glue loads, and here;
* Python's mirrors of the firmware's structs (``avr.lf_state``, ``avr.lf_config``) equal what avr-gcc makes of the
  firmware's own headers (line_follower.h, avr/config.h): a probe of static assertions, one per field;
* the EEPROM image ``config_image`` packs each field where the table says.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess

import numpy as np
import pytest

from twin.core import native as core
from twin.errors import TwinError
from twin.model.control import ControlParams
from twin.pil import firmware as fw
from twin.pil import layout

FIRMWARE = os.path.join(os.path.dirname(__file__), "..", "twin", "csrc", "firmware")


@pytest.fixture(scope="module")
def glue():
    from twin.pil.mcu import glue

    try:
        return glue()
    except TwinError as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI installs simavr and libsimavr-dev: {e}")
        pytest.skip(str(e))


def avr_rows(table: dict[str, tuple[int, int]]) -> dict[str, tuple[int, int]]:
    return {name: at for name, at in table.items() if name.startswith("avr.")}


def probe(table: dict[str, tuple[int, int]], tmp_path) -> subprocess.CompletedProcess:
    """avr-gcc on a file of static assertions: each avr.* row's offset and size as the firmware's headers lay it out."""
    lines = ["#include <stddef.h>", '#include "line_follower.h"', '#include "avr/config.h"']
    for name, (offset, size) in avr_rows(table).items():
        struct_name, _, field = name[len("avr."):].partition(".")
        if field:
            test = (f"offsetof({struct_name}, {field}) == {offset} && "
                    f"sizeof((({struct_name} *)0)->{field}) == {size}")
        else:
            test = f"sizeof({struct_name}) == {size}"
        lines.append(f'_Static_assert({test}, "{name}");')
    src = tmp_path / "layout_probe.c"
    src.write_text("\n".join(lines) + "\n")
    return subprocess.run([shutil.which("avr-gcc"), f"-mmcu={fw.MCU}", "-std=gnu11", "-fsyntax-only", f"-I{FIRMWARE}",
                           str(src)], capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def avr_gcc():
    if not shutil.which("avr-gcc"):
        if os.environ.get("CI"):
            pytest.fail("CI installs gcc-avr and avr-libc")
        pytest.skip("avr-gcc not installed (apt-get install gcc-avr avr-libc)")


def test_the_glue_table_is_the_mirror(glue):
    assert core.library_layout(glue, "lf_avr_layout") == layout.mirrors()
    assert core.library_statuses(glue) == core.library_statuses(core.lib)  # the same enumeration in both libraries


def test_a_mirror_that_drifted_fails_the_glue_check(glue):
    c = core.library_layout(glue, "lf_avr_layout")
    ours = layout.mirrors()
    moved = {**ours, "avr.lf_config.params.k_p": (ours["avr.lf_config.params.k_p"][0] + 4, 4)}
    with pytest.raises(ImportError, match=r"twin.pil._lfavr .*avr.lf_config.params.k_p.*rebuild"):
        core.check_same(c, moved, "(offset, size)", layout.LIBRARY)
    missing = {n: at for n, at in ours.items() if n != "lf_avr_status.uart_lost"}
    with pytest.raises(ImportError, match="lf_avr_status.uart_lost"):
        core.check_same(c, missing, "(offset, size)", layout.LIBRARY)


@pytest.mark.parametrize("struct_name", ["avr.lf_state", "avr.lf_config", "lf_avr_status"])
def test_the_fields_leave_no_byte_out(struct_name):
    """Packed structs (and lf_avr_status, all 8-byte fields) have no padding: fields in offset order tile the struct,
    so a field missing from the mirror would leave a hole."""
    table = layout.mirrors()
    rows = sorted(at for name, at in table.items() if name.startswith(struct_name + "."))
    end = 0
    for offset, size in rows:
        assert offset == end
        end += size
    assert end == table[struct_name][1]


def test_avr_gcc_lays_the_firmware_structs_out_as_the_mirrors(avr_gcc, tmp_path):
    done = probe(layout.mirrors(), tmp_path)
    assert done.returncode == 0, done.stderr
    assert len(avr_rows(layout.mirrors())) == 1 + 18 + 1 + 22  # every field was probed, wholes included


@pytest.mark.parametrize("name", ["avr.lf_config.timeout_us", "avr.lf_state.tick", "avr.lf_config"])
def test_a_field_that_moved_fails_the_avr_gcc_probe(avr_gcc, tmp_path, name):
    table = layout.mirrors()
    offset, size = table[name]
    moved = {**table, name: (offset + 2, size) if "." in name[4:] else (offset, size + 2)}
    done = probe(moved, tmp_path)
    assert done.returncode != 0 and name in done.stderr, done.stderr


def test_the_eeprom_image_holds_each_field_where_the_table_says():
    p = ControlParams(count=8, pitch_m=0.009525, sensor_distance_m=0.04, v_max=0.8, k_b=0.6, k_p=12.0, k_i=3.0,
                      k_d=0.4, dt_s=0.005, wheel_radius_m=0.016, half_track_m=0.0425, wheel_speed_max=75.4,
                      accel_max=5.0, integral_limit=0.5, cal_duty=0.15, cal_sweep_rad=1.0, cal_sweeps=3)
    image = fw.config_image(p, 2400, 7)
    at = fw.config_layout()
    assert len(image) == fw.CONFIG_BYTES == sum(size for _, size in at.values())

    def read(name: str, code: str):
        offset, size = at[name]
        assert struct.calcsize("<" + code) == size
        return struct.unpack_from("<" + code, image, offset)[0]

    assert read("magic", "I") == fw.CONFIG_MAGIC and read("size", "H") == fw.CONFIG_BYTES
    assert read("params.count", "i") == 8 and read("params.cal_sweeps", "i") == 3
    assert read("params.k_p", "f") == np.float32(12.0) and read("params.cal_sweep_rad", "f") == np.float32(1.0)
    assert read("timeout_us", "H") == 2400 and read("telemetry_every", "H") == 7
    assert at["crc"][0] == len(image) - 2  # the CRC covers every byte before it (config.c)
