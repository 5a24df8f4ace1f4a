"""Nothing the user owns is deleted or overwritten; outputs are atomic; the cache is checked, not trusted."""

from __future__ import annotations

import json
import multiprocessing
import os
import subprocess
import sys

import pytest

from lf_common.cache import cached_folder
from lf_common.errors import OutputError
from lf_common.files import (
    GENERATOR, MANIFEST, atomic_file, check_output_dir, json_is_ours, output_dir, read_json, write_json,
)

PY = sys.executable


def run_cli(*args, cwd=None):
    return subprocess.run([PY, "-m", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def snapshot(folder) -> dict[str, bytes]:
    out = {}
    for here, _, names in os.walk(folder):
        for n in names:
            p = os.path.join(here, n)
            out[os.path.relpath(p, folder)] = open(p, "rb").read()
    return out


def test_generate_refuses_a_folder_holding_the_users_files(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    (d / "notes.txt").write_text("keep")
    r = run_cli("mjcf", "generate", "--out-dir", str(d))
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "notes.txt" in r.stderr and "Traceback" not in r.stderr
    assert snapshot(d) == {"notes.txt": b"keep"}


def test_generate_into_the_working_folder_is_refused_and_touches_nothing(tmp_path):
    (tmp_path / "mine.txt").write_text("mine")
    r = run_cli("mjcf", "generate", "--out-dir", ".", cwd=tmp_path)
    assert r.returncode == 2 and "current folder" in r.stderr
    assert os.listdir(tmp_path) == ["mine.txt"]


def test_our_folder_is_replaced_but_not_once_the_user_added_or_changed_a_file(tmp_path):
    out = tmp_path / "robot"
    assert run_cli("mjcf", "generate", "--out-dir", str(out)).returncode == 0
    assert run_cli("mjcf", "generate", "--out-dir", str(out), "--set", "cad.L=0.05").returncode == 0  # ours: replaced
    assert "0.05" in (out / "robot.urdf").read_text()
    urdf = (out / "robot.urdf").read_bytes()
    (out / "robot.urdf").write_bytes(urdf + b"<!-- my edit -->")
    r = run_cli("mjcf", "generate", "--out-dir", str(out))
    assert r.returncode == 2 and "robot.urdf (changed)" in r.stderr
    assert (out / "robot.urdf").read_bytes().endswith(b"<!-- my edit -->")
    (out / "robot.urdf").write_bytes(urdf)
    (out / "meshes" / "extra.stl").write_bytes(b"user")
    r = run_cli("mjcf", "generate", "--out-dir", str(out))
    assert r.returncode == 2 and "extra.stl" in r.stderr
    assert (out / "meshes" / "extra.stl").read_bytes() == b"user"


def test_convert_keeps_a_users_xml_and_a_users_assets_folder(tmp_path, third_party_urdf):
    xml = tmp_path / "world.xml"
    xml.write_text("<mujoco/>  <!-- my model -->")
    r = run_cli("mjcf", "convert", third_party_urdf, "-o", str(xml), "--track", "oval")
    assert r.returncode == 2 and "was not written by" in r.stderr
    assert xml.read_text() == "<mujoco/>  <!-- my model -->"
    assert not (tmp_path / "world_assets").exists()
    xml.unlink()
    (tmp_path / "world_assets").mkdir()
    (tmp_path / "world_assets" / "texture.png").write_bytes(b"mine")
    r = run_cli("mjcf", "convert", third_party_urdf, "-o", str(xml), "--track", "oval")
    assert r.returncode == 2 and "texture.png" in r.stderr
    assert not xml.exists() and (tmp_path / "world_assets" / "texture.png").read_bytes() == b"mine"
    (tmp_path / "world_assets" / "texture.png").unlink()
    for _ in range(2):  # an empty folder, then our own output, are replaced
        r = run_cli("mjcf", "convert", third_party_urdf, "-o", str(xml), "--track", "oval")
        assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(tmp_path)) == ["tb_like", "world.xml", "world_assets"]


def test_design_checks_its_folder_before_any_work(tmp_path):
    d = tmp_path / "study"
    d.mkdir()
    (d / "thesis.tex").write_text("x")
    r = run_cli("twin.run", "design", "--out-dir", str(d), "--grid", "cad.L=0.04,0.05", "--laps", "1")
    assert r.returncode == 2 and "thesis.tex" in r.stderr
    assert snapshot(d) == {"thesis.tex": b"x"}


@pytest.mark.quick
def test_a_failing_writer_leaves_neither_a_temporary_nor_a_changed_target(tmp_path):
    target = tmp_path / "out.json"
    write_json(str(target), {"a": 1})
    before = target.read_bytes()
    with pytest.raises(RuntimeError):
        with atomic_file(str(target), json_is_ours) as f:
            f.write("half")
            raise RuntimeError("crash while writing")
    assert target.read_bytes() == before and os.listdir(tmp_path) == ["out.json"]
    with pytest.raises(RuntimeError):
        with output_dir(str(tmp_path / "folder")) as tmp:
            open(os.path.join(tmp, "a.txt"), "w").write("a")
            raise RuntimeError("crash while writing")
    assert os.listdir(tmp_path) == ["out.json"]


@pytest.mark.quick
@pytest.mark.parametrize("make,needle", [
    (lambda p: None, "does not exist"),  # missing parent folder
    (lambda p: os.makedirs(p), "is a folder"),
    (lambda p: os.symlink("/etc/hostname", p), "symbolic link"),
])
def test_bad_output_file_paths_are_one_line_errors(tmp_path, make, needle):
    target = str(tmp_path / ("missing/x.json" if needle == "does not exist" else "x.json"))
    make(target)
    with pytest.raises(OutputError, match=needle):
        write_json(target, {})


@pytest.mark.quick
def test_read_only_folders_are_refused(tmp_path):
    # /proc refuses new files even to root; a chmod-ed folder does not stop root, so it is tried only as a user
    with pytest.raises(OutputError, match="cannot write|not writable"):
        write_json("/proc/line-follower-test.json", {})
    with pytest.raises(OutputError, match="cannot write|not writable"):
        with output_dir("/proc/line-follower-test"):
            pass
    if os.geteuid() != 0:
        os.chmod(tmp_path, 0o500)
        try:
            with pytest.raises(OutputError, match="not writable"):
                check_output_dir(str(tmp_path / "new"))
        finally:
            os.chmod(tmp_path, 0o700)


@pytest.mark.quick
def test_json_inputs_are_bounded_and_errors_are_one_line(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100000 + "]" * 100000)
    long = tmp_path / "long.json"
    long.write_text('{"control.kp": ' + "9" * 5000 + "}")
    for path, needle in ((deep, "nested too deeply"), (long, "a whole number of 5000 digits"),
                         ("/dev/zero", "is a character device, not a regular file"), (tmp_path, "is a folder")):
        with pytest.raises(Exception, match=needle) as e:
            read_json(str(path), 2**20, "gains file")
        assert "\n" not in str(e.value)


def _build_robot(cache: str) -> str:
    os.environ["TWIN_CACHE_DIR"] = cache
    from twin.core.digital_twin import DigitalTwin

    return open(DigitalTwin(track="oval")._urdf()).read()


def test_parallel_builds_of_one_new_robot_all_succeed_with_one_entry(tmp_path):
    cache = str(tmp_path / "cache")
    with multiprocessing.get_context("spawn").Pool(6) as pool:
        urdfs = pool.map(_build_robot, [cache] * 12)
    assert len(set(urdfs)) == 1
    entries = os.listdir(os.path.join(cache, "robots"))
    assert len(entries) == 1 and not entries[0].startswith(".")


@pytest.mark.quick
def test_a_damaged_cache_entry_is_rebuilt_with_a_warning(tmp_path, caplog):
    calls = []

    def build(tmp):
        calls.append(tmp)
        open(os.path.join(tmp, "a.bin"), "wb").write(b"good")

    entry = str(tmp_path / "entry")
    cached_folder(entry, build, "test entry")
    cached_folder(entry, build, "test entry")
    assert len(calls) == 1  # verified, reused
    open(os.path.join(entry, "a.bin"), "wb").write(b"swapped")
    cached_folder(entry, build, "test entry")
    assert len(calls) == 2 and open(os.path.join(entry, "a.bin"), "rb").read() == b"good"
    assert "damaged" in caplog.text
    open(os.path.join(entry, "a.bin"), "wb").truncate(0)
    os.remove(os.path.join(entry, MANIFEST))
    cached_folder(entry, build, "test entry")
    assert len(calls) == 3 and open(os.path.join(entry, "a.bin"), "rb").read() == b"good"


@pytest.mark.quick
def test_an_entry_another_process_is_building_is_waited_for_not_built_twice(tmp_path):
    """Two processes asking for one missing entry at once: one builds (slowly), the other waits for it and reads
    the same entry; no lock file is left beside it."""
    script = f"""
import os, sys, time
from lf_common.cache import cached_folder
def build(tmp):
    with open({str(tmp_path / "builds.txt")!r}, "a") as f:
        f.write(str(os.getpid()) + "\\n")
    time.sleep(1.5)
    open(os.path.join(tmp, "a.bin"), "wb").write(b"built once")
print(open(os.path.join(cached_folder({str(tmp_path / "cache" / "entry")!r}, build, "test entry"), "a.bin")).read())
"""
    procs = [subprocess.Popen([PY, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [e for _, e in outs]
    assert [o.strip() for o, _ in outs] == ["built once"] * 2
    assert len((tmp_path / "builds.txt").read_text().split()) == 1  # (without the lock: 2, both slept and built)
    assert os.listdir(tmp_path / "cache") == ["entry"]


@pytest.mark.quick
def test_an_entry_still_being_built_elsewhere_is_not_waited_for_past_the_wait_asked(tmp_path):
    """A caller that must answer soon (history --race-wait) hears StillBuilding once its wait is over, builds
    nothing and leaves the builder's lock alone; the builder done, the entry is built (here: by the caller)."""
    import fcntl
    import time

    from lf_common.cache import StillBuilding, lock_path

    entry = str(tmp_path / "entry")
    builds = []
    holder = open(lock_path(entry), "w")  # another open file: flock conflicts as another process's would
    fcntl.flock(holder, fcntl.LOCK_EX)
    t0 = time.monotonic()
    with pytest.raises(StillBuilding, match="test entry .* still being built by another process after 0.3 s"):
        cached_folder(entry, builds.append, "test entry", wait_s=0.3)
    assert 0.3 <= time.monotonic() - t0 < 3.0
    assert builds == [] and os.listdir(tmp_path) == [os.path.basename(lock_path(entry))]  # the lock is the holder's
    holder.close()  # the other process done (here without an entry: the caller builds it)
    cached_folder(entry, lambda tmp: open(os.path.join(tmp, "a.bin"), "wb").write(b"x"), "test entry", wait_s=0.3)
    assert sorted(os.listdir(tmp_path)) == ["entry"]


@pytest.mark.quick
def test_a_swapped_cached_mesh_or_texture_does_not_change_the_lap(tmp_path, monkeypatch):
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path / "cache"))
    from PIL import Image

    from twin.core.closed_loop import run_laps
    from twin.core.digital_twin import DigitalTwin

    reference = run_laps(DigitalTwin(track="oval"), [{}], seed=0)[0]
    robots = tmp_path / "cache" / "robots"
    (entry,) = os.listdir(robots)
    chassis = robots / entry / "meshes" / "chassis.stl"
    import trimesh

    trimesh.creation.box([0.3, 0.3, 0.3]).export(chassis)  # a much bigger body under the same name
    tracks = tmp_path / "cache" / "tracks"
    (tentry,) = os.listdir(tracks)
    png = tracks / tentry / "floor.png"
    w, h = Image.open(png).size
    Image.new("RGB", (w, h), "white").save(png)  # a white floor under the cached track's name
    again = run_laps(DigitalTwin(track="oval"), [{}], seed=0)[0]
    assert again.completed and again.lap_time_s == reference.lap_time_s


@pytest.mark.quick
def test_json_written_by_us_carries_the_generator(tmp_path):
    path = write_json(str(tmp_path / "x.json"), {"k": 1})
    assert json.load(open(path))["generator"] == GENERATOR
