"""Every flag that names an input file checks it with one function (:func:`lf_common.files.input_file`) and says
one thing when it is not a regular file: a FIFO would block its reader for ever (``lap --track FIFO`` once did), a
folder or a device is no file of values, images or programs either."""

from __future__ import annotations

import pytest

from bad_input import BadFiles, check_bad_input
from conftest import minimal_urdf


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> BadFiles:
    f = BadFiles(tmp_path_factory.mktemp("input_files"))
    f.fifo("fifo")
    f.fifo("fifo.png")
    f.fifo("wheel.stl")
    f.put("fifo_mesh.urdf", minimal_urdf().replace('<cylinder radius="0.02" length="0.01"/>', '<mesh filename="wheel.stl"/>'))
    return f


# every flag (and argument) that reads a file the user names
READERS = [
    "lap --robot {}",
    "convert {} -o {dir}/w.xml",
    "lap --track {}",
    "convert {fifo_mesh.urdf} -o {dir}/w.xml --track {}",
    "lap --gains {}",
    "tune --params {}",
    "align --telemetry {}",
    "diagnose --telemetry {}",
    "lap --firmware {}",
    "live --replay {}",
    "view {}",
]
KINDS = [("{fifo}", "is a FIFO, not a regular file"), ("{fifo.png}", "is a FIFO, not a regular file"),
         ("/dev/null", "is a character device, not a regular file"), ("{dir}", "is a folder, not a regular file")]


@pytest.mark.parametrize("reader", READERS)
@pytest.mark.parametrize("path, what", KINDS, ids=[k[1].split(",")[0] for k in KINDS])
def test_an_input_that_is_no_regular_file_is_named_with_one_message(files, reader, path, what, capsys):
    line = check_bad_input(reader.replace("{}", path), f"{path}: {what}", files, capsys, limit_s=20)
    assert line == f"error: {files.fill(path)}: {what}", line  # one message, word for word, whatever the flag


def test_a_mesh_that_is_a_fifo_is_named(files, capsys):
    check_bad_input("lap --robot {fifo_mesh.urdf}", "mesh {wheel.stl}: is a FIFO, not a regular file", files, capsys,
                    limit_s=20)


def test_a_track_named_without_a_folder_is_read_as_the_file_it_names(files, capsys, monkeypatch):
    """A FIFO in the working folder given by its bare name is the file, not an unknown built-in track."""
    monkeypatch.chdir(files.fill("{dir}"))
    line = check_bad_input("lap --track fifo", "fifo: is a FIFO, not a regular file", files, capsys, limit_s=20)
    assert line == "error: fifo: is a FIFO, not a regular file", line
