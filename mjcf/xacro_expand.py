"""Xacro expanded by the ``xacro`` package in a child process, under a memory and a time limit.

A xacro file is a program: ``${'x' * 10**10}`` or a macro that calls itself takes all the memory, or all the time,
that it is given. So it runs in a child (``python -m mjcf.xacro_expand``) that limits its own address space
(``RLIMIT_AS``) before xacro is imported, and that the parent kills after ``XACRO_SECONDS``; either way the
answer is one line naming the file. ``$(find PKG)`` normally asks ROS; the child answers it with
:class:`mjcf.ros_packages.PackageSearch`. The child imports only the standard library, xacro and that module.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys

from mjcf.errors import MjcfError
from mjcf.ros_packages import PackageSearch

XACRO_MEMORY_BYTES = 2**30  # the child's address space: ~20 MB to start, a 16 MB description's DOM fits many times
XACRO_SECONDS = 30.0  # wall time: real descriptions expand in well under a second
_PROJECT_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def expand_xacro(path: str, args: tuple[tuple[str, str], ...], package_dirs: tuple[tuple[str, str], ...],
                 max_bytes: int) -> tuple[bytes, list[str]]:
    """``path`` expanded, with xacro's ``NAME=VALUE`` ``args``; returns (URDF text, xacro's own messages).

    Raises:
      MjcfError: xacro cannot expand it, a package it finds is missing, or the expansion passes the memory or time
        limit or ``max_bytes``; one line naming ``path``.
    """
    request = {"path": os.path.abspath(path), "name": path, "args": list(args), "package_dirs": list(package_dirs),
               "max_bytes": max_bytes}  # name: the file as the user gave it, for the messages
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (_PROJECT_ROOT, os.environ.get("PYTHONPATH")) if p))
    try:
        # run in the user's folder, as xacro in this process would: arguments may be relative paths
        done = subprocess.run([sys.executable, "-m", "mjcf.xacro_expand"], input=json.dumps(request).encode(),
                              capture_output=True, timeout=XACRO_SECONDS, env=env)
    except subprocess.TimeoutExpired:
        raise MjcfError(f"{path}: xacro did not finish expanding it within {XACRO_SECONDS:g} s; "
                        "check its macros and ${…} expressions") from None
    try:
        answer = json.loads(done.stdout)
    except ValueError:
        answer = {"error": f"{path}: xacro stopped without an answer (exit status {done.returncode}); most likely it "
                           f"needed more than the {XACRO_MEMORY_BYTES >> 20} MB memory limit"}
    if "error" in answer:
        raise MjcfError(answer["error"])
    return answer["xml"].encode(), answer["log"]


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text[:300] or type(e).__name__


def _arg_hint(e: BaseException) -> str:
    m = re.search(r"[Uu]ndefined substitution argument (\w+)|arg[^\w]+(\w+)[^\w]+is not defined", str(e))
    name = m and (m.group(1) or m.group(2))
    return f"; give it with --xacro-arg {name}=VALUE" if name else ""


def _out_of_memory(e: BaseException) -> bool:
    """xacro wraps what its expressions raise: look along the chain for a MemoryError."""
    while e is not None:
        if isinstance(e, MemoryError) or "MemoryError" in str(e):
            return True
        e = e.__cause__ or e.__context__
    return False


def _expand(request: dict) -> dict:
    """The child's work: the request's file expanded, or the one-line error."""
    import xacro
    import xacro.substitution_args as subst

    path, name = request["path"], request["name"]
    search = PackageSearch(os.path.dirname(path), tuple(tuple(p) for p in request["package_dirs"]))
    missing: list[str] = []

    def find(pkg: str) -> str:
        found = search.find(pkg)
        if found is None:
            missing.append(pkg)
            raise LookupError(pkg)
        return found

    subst._eval_find = find
    chatter = io.StringIO()  # xacro prints warnings and its include stack: they go back as log lines
    try:
        with contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter):
            xml = xacro.process_file(path, mappings=dict(request["args"])).toprettyxml(indent="  ")
    except Exception as e:  # xacro surfaces parse, name and evaluation errors as assorted types
        if missing:
            return {"error": search.not_found(name, f"$(find {missing[0]})", missing[0])}
        if _out_of_memory(e):
            return {"error": f"{name}: xacro needs more than {XACRO_MEMORY_BYTES >> 20} MB of memory to expand it; "
                             "check its ${…} expressions and macros"}
        kind = "" if isinstance(e, xacro.XacroException) else f"{type(e).__name__}: "
        return {"error": f"{name}: xacro cannot expand it ({kind}{_one_line(e)}){_arg_hint(e)}"}
    if len(xml) > request["max_bytes"]:
        return {"error": f"{name}: expands to {len(xml) / 1e6:.0f} MB, more than the {request['max_bytes'] / 1e6:g} MB "
                         "limit of a robot description"}
    return {"xml": xml, "log": [line.strip() for line in chatter.getvalue().splitlines() if line.strip()]}


def main() -> None:
    """The child: limit the address space first, then read the request on stdin and answer on stdout."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (XACRO_MEMORY_BYTES, XACRO_MEMORY_BYTES))
    request = json.loads(sys.stdin.buffer.read())
    try:
        answer = _expand(request)
    except MemoryError:
        answer = {"error": f"{request['name']}: xacro needs more than {XACRO_MEMORY_BYTES >> 20} MB of memory to "
                           "expand it"}
    sys.stdout.write(json.dumps(answer))


if __name__ == "__main__":
    main()
