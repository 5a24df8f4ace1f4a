"""Xacro runs in a child process under a memory and a time limit: a description that would take all memory or all
time is one line naming the file, in seconds (``${'x' * 10**10}`` once took 38 s and all memory before anything
was said)."""

from __future__ import annotations

import time

import pytest

from mjcf import xacro_expand
from mjcf.errors import MjcfError
from mjcf.robot_source import read_description

HEAD = '<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'


def _xacro(tmp_path, body: str) -> str:
    path = tmp_path / "robot.urdf.xacro"
    path.write_text(f"{HEAD}{body}</robot>")
    return str(path)


def test_memory_is_limited(tmp_path):
    path = _xacro(tmp_path, "<xacro:property name=\"big\" value=\"${'x' * (10**10)}\"/><link name=\"${big}\"/>")
    t0 = time.monotonic()
    with pytest.raises(MjcfError, match=rf"^{path}: xacro needs more than 1024 MB of memory to expand it"):
        read_description(path)
    assert time.monotonic() - t0 < 10


def test_time_is_limited(tmp_path, monkeypatch):
    monkeypatch.setattr(xacro_expand, "XACRO_SECONDS", 2.0)
    path = _xacro(tmp_path, '<xacro:property name="n" value="${(7 ** (10 ** 9)) % 10}"/><link name="l${n}"/>')
    t0 = time.monotonic()
    with pytest.raises(MjcfError, match=rf"^{path}: xacro did not finish expanding it within 2 s"):
        read_description(path)
    assert time.monotonic() - t0 < 6


def test_an_ordinary_description_expands_with_its_arguments(tmp_path):
    path = _xacro(tmp_path, '<xacro:arg name="p" default="a_"/><link name="$(arg p)base"/>')
    assert b'name="b_base"' in read_description(path, (("p", "b_"),)).xml
    with pytest.raises(MjcfError, match=r"xacro cannot expand it .*; give it with --xacro-arg q=VALUE"):
        read_description(_xacro(tmp_path, '<link name="$(arg q)base"/>'))
