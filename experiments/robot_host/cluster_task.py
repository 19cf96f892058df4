"""A robot placed on a cluster: the task a Dask worker runs for one robot of ``dfrl run
--cluster`` (:func:`serve_robot`).

The task starts the same ``dfrl robot`` service a hand-started robot host runs, as a child
process of the worker, on the worker's host::

    python -m dfrl robot --host 0.0.0.0 --port 0 --advertise WORKER_HOST \\
        --token-file dfrl.token --workdir dfrl-robot/ROBOT

(``dfrl.token`` in the worker's working folder, as on every robot host: the token never
travels through the cluster engine), waits for its ``dfrl robot listening on A:P`` line (at
most as many services of a worker start at once as its host has cores: :data:`STARTING`),
reports ``A:P`` to the driver in the run's variable ``dfrl-<run>-<robot>-address`` (and sets
the event ``dfrl-<run>-<robot>-listening``), and then
holds the cluster resources it was placed with until one of:

* the driver sets the run's event ``dfrl-<run>-stop`` (the run ended);
* the service exits (it failed: the driver sees the task end early);
* the driver stops renewing the run's lease ``dfrl-<run>-lease`` for ``lease_s`` (the driver
  died: the service is not left running forever).

The service is then told to stop (SIGTERM: it saves its files) and, after a grace period,
killed. The service dies with the worker too: it is started with the parent-death signal
SIGKILL (Linux), so a worker that is killed takes its robots with it, as a host that dies
does. A task started again elsewhere after its worker died (the engine retries tasks of lost
workers) finds the run's ``dfrl-<run>-<robot>-placed`` event set and returns at once: a robot
is placed once per run; the driver reports the loss like that of a robot host.

Imports the engine (``distributed``) only when it runs, on a worker.
"""

from __future__ import annotations

import ctypes
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

__all__ = ["ClusterTaskError", "serve_robot", "LISTENING", "TLS_FOLDER"]

#: A TLS run's node folder on every worker's host, beside ``dfrl.token`` (``ca.crt``,
#: ``node.crt``, ``node.key``, as ``dfrl certs node`` makes it).
TLS_FOLDER = "dfrl-tls"
#: The service's line that gives its address.
LISTENING = re.compile(r"dfrl robot listening on (\S+):(\d+)")
#: Seconds the service gets to say it listens, and to end once told to stop.
START_S = 120.0
STOP_S = 20.0
#: Seconds between two looks at the stop event, the service and the lease.
LOOK_S = 1.0
#: Services of this worker process that may be starting at once (a start is ~2 s of CPU:
#: more at once than the host has cores only makes every one of them late).
STARTING = threading.BoundedSemaphore(os.cpu_count() or 1)


class ClusterTaskError(RuntimeError):
    """A placed robot's service could not be started on its worker (the reason says where)."""


def _die_with_parent() -> None:
    """In the child, before exec: SIGKILL when the thread that started it ends (Linux
    ``PR_SET_PDEATHSIG``); the task's thread lives as long as the task."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass  # not Linux: the service outlives a killed worker until its run ends


def service_argv(host: str, token_file: Path, workdir: Path, tls: Path | None = None) -> list[str]:
    """The ``dfrl robot`` command the task runs (the same as a hand-started robot host's,
    on a port the OS chooses; with ``--tls`` when the run uses TLS)."""
    return [
        sys.executable,
        "-m",
        "dfrl",
        "robot",
        "--host",
        "0.0.0.0",
        "--port",
        "0",
        "--advertise",
        host,
        "--token-file",
        str(token_file),
        "--workdir",
        str(workdir),
        *(["--tls", str(tls)] if tls is not None else []),
    ]


def _await_listening(proc: subprocess.Popen, out: Path, where: str) -> tuple[str, int]:
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        text = out.read_text(encoding="utf-8", errors="replace") if out.is_file() else ""
        m = LISTENING.search(text)
        if m:
            return m.group(1), int(m.group(2))
        if proc.poll() is not None:
            err = out.with_suffix(".err")
            tail = (
                err.read_text(encoding="utf-8", errors="replace")[-1500:] if err.is_file() else ""
            )
            raise ClusterTaskError(
                f"{where}: dfrl robot exited with status {proc.returncode} "
                f"before it listened: {tail.strip()}"
            )
        time.sleep(0.1)
    raise ClusterTaskError(f"{where}: dfrl robot did not listen within {START_S:.0f} s")


def _end(proc: subprocess.Popen) -> int | None:
    """Stop the service (SIGTERM, then SIGKILL after :data:`STOP_S`); its exit status."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=STOP_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=STOP_S)
    return proc.returncode


def serve_robot(
    run_key: str,
    robot: str,
    token_file: str = "dfrl.token",
    workdir: str = "dfrl-robot",
    lease_s: float = 60.0,
    tls: bool = False,
) -> dict[str, Any]:
    """Run one robot's ``dfrl robot`` service on this worker for one run (see the module doc).

    Parameters
    ----------
    run_key : str
        The run's key (names its event, variables and lease).
    robot : str
        The robot id (its service's files go to ``workdir/robot/<experiment>/``).
    token_file : str
        The token file on the worker's host (relative: to the worker's working folder).
    workdir : str
        The robot services' folder on the worker's host.
    lease_s : float
        Seconds without a renewal of the driver's lease after which the task ends.
    tls : bool
        The run uses TLS: the service starts with the node folder :data:`TLS_FOLDER` of the
        worker's working folder.

    Returns
    -------
    dict
        ``robot``, ``worker`` (the worker's address), ``address`` (``[host, port]`` of the
        service, None if not started), ``ended`` (why the task ended), ``exit`` (the service's
        exit status).

    Raises
    ------
    ClusterTaskError
        No token file, no TLS folder in a TLS run, or the service did not start (its
        stderr's tail given).
    """
    from distributed import Event, Variable, get_worker
    from distributed.comm import get_address_host

    worker = get_worker().address
    host = get_address_host(worker)
    where = f"robot {robot} on cluster worker {worker}"
    prefix = f"dfrl-{run_key}"
    placed = Event(f"{prefix}-{robot}-placed")
    if placed.is_set():
        return {
            "robot": robot,
            "worker": worker,
            "address": None,
            "exit": None,
            "ended": "not started again: its first placement was lost with its worker",
        }
    placed.set()
    token = Path(token_file).resolve()
    if not token.is_file():
        raise ClusterTaskError(
            f"{where}: no token file {token} (copy the run's token file "
            f"into the folder the worker was started from)"
        )
    tls_dir = Path(TLS_FOLDER).resolve() if tls else None
    if tls_dir is not None and not all(
        (tls_dir / f).is_file() for f in ("ca.crt", "node.crt", "node.key")
    ):
        raise ClusterTaskError(
            f"{where}: the run uses TLS but {tls_dir} is not a node TLS "
            f"folder (ca.crt, node.crt, node.key: copy the folder "
            f"'dfrl certs node' made for this host there)"
        )
    folder = (Path(workdir) / robot).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"service-{run_key}.out"  # per run: two runs may place one robot id
    with STARTING:
        if Event(f"{prefix}-stop").is_set():  # the run ended while we waited
            return {
                "robot": robot,
                "worker": worker,
                "address": None,
                "exit": None,
                "ended": "not started: the run ended before",
            }
        with (
            open(out, "w", encoding="utf-8") as out_fh,
            open(out.with_suffix(".err"), "w", encoding="utf-8") as err_fh,
        ):
            proc = subprocess.Popen(
                service_argv(host, token, folder, tls_dir),
                stdin=subprocess.DEVNULL,
                stdout=out_fh,
                stderr=err_fh,
                cwd=folder,
                preexec_fn=_die_with_parent if os.name == "posix" else None,
            )
        try:
            address = _await_listening(proc, out, where)
        except BaseException:
            _end(proc)
            raise
    try:
        Variable(f"{prefix}-{robot}-address").set([address[0], address[1], worker])
        Event(f"{prefix}-{robot}-listening").set()  # waiting on an event logs no timeouts
        ended = _hold(proc, Event(f"{prefix}-stop"), Variable(f"{prefix}-lease"), lease_s)
    finally:
        code = _end(proc)
    return {
        "robot": robot,
        "worker": worker,
        "address": list(address),
        "ended": ended,
        "exit": code,
    }


def _hold(proc: subprocess.Popen, stop: Any, lease: Any, lease_s: float) -> str:
    """Wait for the stop event, the service's exit or the lease's expiry; why it ended."""
    last: Any = None
    renewed = time.monotonic()
    while True:
        if stop.wait(timeout=LOOK_S):
            return "released by the driver"
        if proc.poll() is not None:
            return f"the robot service exited with status {proc.returncode}"
        try:
            beat = lease.get(timeout=LOOK_S)
        except TimeoutError:
            beat = last
        now = time.monotonic()
        if beat != last:
            last, renewed = beat, now
        elif now - renewed > lease_s:
            return f"the driver did not renew its lease for {lease_s:.0f} s"
