"""Design studies and sweeps on a Ray cluster: one Ray task per design (rebuild, tune, race) or per sweep point
(its seeds' laps as one small batch), gathered in their order.

* **Same answer as a local run.** A design's result depends on its values, the base values and the seeds only
  (each task tunes with one thread, as a local worker does), never on the node or the order tasks finish in; a
  sweep point's laps are bit-identical to the same laps in the local sweep's one batch, as every lap is to running
  it alone.
* **No shared filesystem.** Each task builds its robot and track into its own node's verified cache
  (:mod:`lf_common.cache`); nothing but the design, the base values and the result crosses the network. The
  nodes need this package installed, at the driver's version (checked: a task on another version fails).
* **Nothing lost, nothing twice.** A task whose worker dies (killed, out of memory, a node lost) is retried by
  Ray up to ``RETRIES`` times; results are keyed by the design's index and taken once, so a retried design
  is counted once. A design that fails on its own merits is a result (``ok=False``), not retried.
* ``auto`` joins the cluster this machine belongs to (``ray start --head`` or a worker node); ``ray://HOST:PORT``
  goes through the Ray Client. Ray is an optional extra: ``pip install -e '.[cluster]'``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import subprocess
import sys
import time
from typing import Callable, Iterator, Sequence

from lf_common import VERSION
from lf_common.errors import LineFollowerError
from tuner.studies.design import DesignResult, run_design
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapResult

log = logging.getLogger(__name__)

RETRIES = 3  # attempts after a worker dies, per design
CONNECT_TIMEOUT_S = 60.0  # [s] to join the cluster
CLIENT_ATTEMPTS = 3  # Ray Client sessions tried when the server fails to start one (a busy head)
RAY_CLIENT_PORT = 10001  # Ray Client's default port (ray start --ray-client-server-port)
REACH_TIMEOUT_S = 10.0  # [s] for the head to accept a TCP connection before Ray Client is tried
POLL_S = 1.0  # [s] between progress checks


class ClusterError(LineFollowerError):
    """The cluster cannot be used: Ray missing, no cluster at the address, a version mismatch."""


def _version() -> str:
    return VERSION


def _task(design: dict, base: dict, laps: int, max_iter: int, version: str) -> DesignResult:
    if _version() != version:
        raise ClusterError(f"this node has line-follower-twin {_version()}, the driver {version}: install the same version")
    return run_design(design, base, laps, max_iter)


def connect(address: str):
    """Join the cluster at ``address`` (``auto`` or ``ray://HOST:PORT``); returns the ray module."""
    try:
        import ray
    except ImportError:
        raise ClusterError("--cluster needs Ray: pip install -e '.[cluster]'") from None
    if not (address == "auto" or address.startswith("ray://")):
        raise ClusterError(f"--cluster {address}: expected auto or ray://HOST:PORT")
    if ray.is_initialized():
        return ray
    if address.startswith("ray://"):
        _reachable(address)
    try:
        for attempt in range(CLIENT_ATTEMPTS):
            try:
                ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
                break
            except ConnectionError as e:
                # Ray Client's server starts a process of its own for each client; on a busy head that start can
                # time out ("Initialization failure from server"): the server is there, so try again
                if "Initialization failure" not in str(e) or attempt == CLIENT_ATTEMPTS - 1:
                    raise
                log.warning("--cluster %s: the Ray Client server could not start this client's session; trying again",
                            address)
                ray.shutdown()
    except ImportError:  # plain 'ray' has no Ray Client (grpcio): ray:// needs the client extra
        raise ClusterError(f"--cluster {address}: Ray Client is not installed: pip install -e '.[cluster]' "
                           "(it brings ray[client])") from None
    except (ConnectionError, RuntimeError, ValueError, TimeoutError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ClusterError(f"--cluster {address}: no Ray cluster there ({first}); start one with 'ray start --head'") from None
    return ray


def _reachable(address: str) -> None:
    """Fail at once when nothing listens at a ``ray://HOST[:PORT]`` address: Ray Client itself retries a refused
    connection for ~30 s (three attempts, 5 + 10 + 15 s) before it says so."""
    import socket
    import urllib.parse

    try:
        where = urllib.parse.urlsplit(address)
        host, port = where.hostname, where.port or RAY_CLIENT_PORT
    except ValueError as e:
        raise ClusterError(f"--cluster {address}: not a ray://HOST:PORT address ({e})") from None
    if not host:
        raise ClusterError(f"--cluster {address}: no host in it, expected ray://HOST:PORT")
    try:
        socket.create_connection((host, port), timeout=REACH_TIMEOUT_S).close()
    except OSError as e:
        raise ClusterError(f"--cluster {address}: no Ray cluster there ({e.strerror or type(e).__name__}); start one "
                           "with 'ray start --head'") from None


def _sweep_task(point: dict, seeds: list[int], base: dict, version: str) -> list[LapResult]:
    if _version() != version:
        raise ClusterError(f"this node has line-follower-twin {_version()}, the driver {version}: install the same version")
    twin = DigitalTwin(track=base["track"], track_metres_per_pixel=base.get("metres_per_pixel"))
    twin.update(base["values"])
    return run_laps(twin, [point] * len(seeds), seed=seeds, nthread=1, keep_traces=False)


def _gather(ray, remote, calls: Sequence[tuple], labels: Sequence[str], on_done: Callable | None) -> list:
    """Submit ``remote(*call)`` for every call; the results in call order (see the module docstring)."""
    refs = [remote.remote(*call) for call in calls]
    index = {ref: i for i, ref in enumerate(refs)}
    results: list = [None] * len(calls)
    pending = list(refs)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=POLL_S)
            for ref in ready:
                i = index[ref]
                try:
                    results[i] = ray.get(ref)
                except ray.exceptions.RayTaskError as e:  # an error the task raised itself: the node's fault
                    cause = e.cause if isinstance(getattr(e, "cause", None), LineFollowerError) else e
                    raise ClusterError(f"{labels[i]}: {str(cause).strip().splitlines()[-1]}") from None
                except ray.exceptions.RayError as e:  # retries used up (workers kept dying): say so, stop
                    raise ClusterError(f"{labels[i]}: lost after {RETRIES} retries ({type(e).__name__})") from None
                if on_done is not None:
                    on_done(results[i])
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    return results


def study_on_ray(designs: Sequence[dict], base: dict, laps: int, max_iter: int, address: str,
                 on_done: Callable[[DesignResult], None] | None = None) -> list[DesignResult]:
    """Every design as one Ray task; results in the order of ``designs`` (see the module docstring)."""
    ray = connect(address)
    remote = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=False)(_task)
    version = _version()
    return _gather(ray, remote, [(d, base, laps, max_iter, version) for d in designs],
                   [f"design {d}" for d in designs], on_done)


def sweep_on_ray(points: Sequence[dict], seeds: Sequence[int], base: dict, address: str,
                 on_done: Callable[[list[LapResult]], None] | None = None) -> list[LapResult]:
    """Every sweep point's laps (one per seed) as one Ray task; the laps in the order the local sweep runs them
    (point by point, seed by seed). ``base``: the track (built in: nodes share no files) and every address's value."""
    ray = connect(address)
    remote = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=False)(_sweep_task)
    version = _version()
    per_point = _gather(ray, remote, [(p, list(seeds), base, version) for p in points],
                        [f"sweep point {p}" for p in points], on_done)
    return [lap for laps in per_point for lap in laps]


def wait_for_cluster(ray, cpus: int, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Block until the cluster shows ``cpus`` CPUs (nodes join asynchronously)."""
    deadline = time.monotonic() + timeout_s
    while ray.cluster_resources().get("CPU", 0) < cpus:
        if time.monotonic() > deadline:
            raise ClusterError(f"the cluster has {ray.cluster_resources().get('CPU', 0):g} CPUs, not {cpus}, after {timeout_s:g} s")
        time.sleep(0.2)


def ray_executable() -> str:
    """The ``ray`` command beside this Python (a venv's ``bin/``), else on PATH."""
    here = os.path.join(os.path.dirname(sys.executable), "ray")
    found = here if os.path.exists(here) else shutil.which("ray")
    if not found:
        raise ClusterError("no 'ray' command beside this Python or on PATH: pip install -e '.[cluster]'")
    return found


@contextlib.contextmanager
def local_head(cpus: int, temp_dir: str, client_port: int | None = None) -> Iterator[str]:
    """A Ray head on this machine with ``cpus`` CPUs (``ray start --head``), which ``auto`` then joins; stopped
    (``ray stop --force``) afterwards. With ``client_port`` it also serves Ray Client there, and yields its address
    ``ray://127.0.0.1:PORT`` (else ``auto``). For tests and benchmarks: a real cluster is started by its operator."""
    exe = ray_executable()
    client = ["--ray-client-server-port", str(client_port)] if client_port else []
    r = subprocess.run([exe, "start", "--head", "--num-cpus", str(cpus), "--include-dashboard", "false", "--port", "0",
                        "--temp-dir", temp_dir, *client], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "RAY_USAGE_STATS_ENABLED": "0"})
    if r.returncode != 0:
        raise ClusterError(f"ray start --head failed: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode}")
    try:
        yield f"ray://127.0.0.1:{client_port}" if client_port else "auto"
    finally:
        subprocess.run([exe, "stop", "--force"], capture_output=True, timeout=120)
