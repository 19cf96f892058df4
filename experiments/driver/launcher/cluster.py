"""Robots placed on a cluster engine (Dask distributed) instead of spawned here or started by
hand: ``dfrl run CONFIG --cluster ADDRESS`` (:func:`run_on_cluster`).

Every robot of the config without a ``robot_host`` becomes one task on the cluster
(:func:`dfrl.experiments.robot_host.cluster_task.serve_robot`), submitted with a resource
request (``{"CPU": cpus}``: workers offer it with ``dask worker --resources CPU=N``). The task
starts a ``dfrl robot`` service on its worker's host and reports its address; the robot's
entry then names that address as its ``robot_host``, and the run goes on exactly as with
hand-started robot hosts (:class:`~.remote_robots.RemoteRobot`): the agent moves among them
over the platform and their files come back over the platform at the end. The engine only
places the services and holds their resources; nothing of the run travels through it but the
services' addresses (the token stays in ``dfrl.token`` on every host).

:class:`ClusterPlacement` owns the engine's client. While the run goes on, its thread renews
the run's lease (the tasks end their services if the driver stops renewing it) and watches the
workers: a worker that leaves the cluster, or a task that ends before the run, is said on the
progress stream and recorded in ``cluster.json``; the robots on it stop answering and the run
counts them as lost, as robots of a host that died (``summary.md``, exit status 1).

Who may use the cluster (:func:`cluster_access`): a ``tls://`` scheduler is reached over
mutual TLS with the driver's cluster folder (``--cluster-tls DIR``: ``ca.crt``, ``cluster.crt``,
``cluster.key``, made by ``dfrl certs cluster``); the scheduler and the workers, started as the
README says, accept only certificates of that cluster CA, so a process without one can neither
list the workers nor run a task. A plaintext ``tcp://`` scheduler asks nobody for anything:
whoever reaches it runs code on every worker. It is accepted on loopback (tests, a local
cluster) and elsewhere only when the caller says ``insecure``.

Threading: the caller's thread calls every public method; the watch thread renews the lease
and records losses, guarded by the placement's lock.
"""

from __future__ import annotations

import ipaddress
import json
import sys
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.results.files import ClaimedFolder
from dfrl.experiments.driver.results.summary import Results
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tls_folder import (
    CA_CERT,
    CLUSTER_CERT,
    CLUSTER_KEY,
    CertError,
    check_cluster_dir,
)

#: The resource a robot's task asks for (workers offer it: ``--resources CPU=N``).
RESOURCE = "CPU"
#: Seconds to connect to the scheduler; seconds without a robot reporting its service's
#: address after which placing fails (placing many robots may take longer as a whole).
CONNECT_S = 20.0
PLACE_S = 120.0
#: Seconds without a new worker after which the workers there are taken as all there are.
SETTLE_S = 3.0
#: Seconds between two renewals of the lease (and looks at the workers); the tasks' lease.
WATCH_S = 1.0
LEASE_S = 60.0
#: Seconds the tasks get to end once released.
RELEASE_S = 40.0
#: The file of the results folder that records the placements.
CLUSTER_FILE = "cluster.json"


class ClusterAccessError(ExperimentError):
    """The scheduler's address and the cluster options do not make a safe connection (said
    before anything starts: a plaintext address off loopback without ``insecure``, a
    ``tls://`` address without a cluster folder, a folder that is not one)."""


@dataclass(frozen=True)
class ClusterAccess:
    """How the driver reaches the scheduler (:func:`cluster_access` checks and makes it).

    Attributes
    ----------
    address : str
        The scheduler, ``tls://HOST:PORT`` or ``tcp://HOST:PORT``.
    tls : Path or None
        The driver's cluster folder for a ``tls://`` address (None for ``tcp://``).
    """

    address: str
    tls: Path | None = None

    def security(self) -> Any:
        """The ``distributed.Security`` of the driver's client: its certificate and the
        cluster CA, encryption required (None for a ``tcp://`` address)."""
        if self.tls is None:
            return None
        from distributed import Security

        return Security(
            tls_ca_file=str(self.tls / CA_CERT),
            tls_client_cert=str(self.tls / CLUSTER_CERT),
            tls_client_key=str(self.tls / CLUSTER_KEY),
            require_encryption=True,
        )


def cluster_access(
    address: str, tls: str | Path | None = None, insecure: bool = False
) -> ClusterAccess:
    """Check that ``address`` with the cluster folder ``tls`` makes a safe connection.

    Parameters
    ----------
    address : str
        The scheduler: ``tls://HOST:PORT``, or ``tcp://HOST:PORT`` (plaintext; also an address
        without a scheme, as Dask reads it), or ``inproc://...`` (a scheduler in this
        process, as a test's ``LocalCluster(processes=False)``).
    tls : path or None
        The driver's cluster folder (``ca.crt``, ``cluster.crt``, ``cluster.key``); needed
        with ``tls://``, refused with ``tcp://``.
    insecure : bool
        Accept a plaintext ``tcp://`` address off loopback.

    Raises
    ------
    ClusterAccessError
        A scheme other than ``tls`` or ``tcp``; ``tls://`` without a cluster folder or with a
        folder missing a file; ``tcp://`` with a cluster folder; ``tcp://`` off loopback
        without ``insecure`` (anyone who reaches such a scheduler runs code on its workers).
    """
    scheme, _, rest = address.partition("://") if "://" in address else ("tcp", "", address)
    if scheme == "inproc":  # a scheduler in this process: no network at all
        return ClusterAccess(address)
    if scheme not in ("tls", "tcp"):
        raise ClusterAccessError(
            f"--cluster {address}: use a tls:// address (or tcp:// on loopback), not {scheme}://"
        )
    if scheme == "tls":
        if tls is None:
            raise ClusterAccessError(
                f"--cluster {address} needs --cluster-tls DIR: the driver's cluster certificate "
                f"folder (make it with 'dfrl certs cluster driver CA_DIR --out DIR')"
            )
        try:
            return ClusterAccess(address, check_cluster_dir(tls).resolve())
        except CertError as exc:
            raise ClusterAccessError(f"--cluster-tls: {exc}") from None
    if tls is not None:
        raise ClusterAccessError(
            f"--cluster-tls is for a tls:// scheduler; {address} is plaintext (write tls://{rest})"
        )
    if not (_on_loopback(rest) or insecure):
        raise ClusterAccessError(
            f"--cluster {address} is plaintext TCP off loopback: the scheduler asks no "
            f"certificate, so anyone who reaches it can run code on every worker (and read "
            f"dfrl.token there); start the cluster with TLS as the README says ('Running on a "
            f"cluster') and use --cluster tls://{rest} --cluster-tls DIR, or say --insecure "
            f"if the network is yours alone"
        )
    return ClusterAccess(address)


def _on_loopback(host_port: str) -> bool:
    """True if the host of ``HOST:PORT`` (``[V6]:PORT`` too) is ``localhost`` or a loopback
    address."""
    host = (
        host_port.rsplit(":", 1)[0]
        if host_port.count(":") == 1 or host_port.startswith("[")
        else host_port
    )
    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class Placement:
    """Where one robot runs: its service's address and the worker that holds its task."""

    robot: str
    host: str
    port: int
    worker: str


class ClusterPlacement:
    """The robots of one run on a Dask cluster (see the module doc).

    Parameters
    ----------
    access : ClusterAccess or str
        The scheduler and the driver's certificate (:func:`cluster_access`); a string is
        checked by it without a folder (``tcp://`` on loopback only).
    cpus : float
        Amount of :data:`RESOURCE` each robot asks for.
    say : callable
        Where notices go (one line each).
    tls : bool
        The run uses TLS: each service starts with its worker's node TLS folder
        (:data:`~dfrl.experiments.robot_host.cluster_task.TLS_FOLDER`).
    """

    def __init__(
        self,
        access: ClusterAccess | str,
        cpus: float = 1.0,
        say: Callable[[str], None] = lambda line: None,
        tls: bool = False,
    ) -> None:
        if cpus <= 0:
            raise ExperimentError(f"--cluster-cpus must be > 0, got {cpus}")
        self.access = access if isinstance(access, ClusterAccess) else cluster_access(access)
        self.address = self.access.address
        self.cpus = float(cpus)
        self.run_key = uuid.uuid4().hex[:12]
        self.tls = tls
        self._say = say
        self._client: Any = None
        self._futures: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._placed: dict[str, Placement] = {}  # guarded by _lock, and so on below
        self._losses: list[str] = []
        self._said: set[str] = set()
        self._ended: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lease: Any = None

    # -- connecting and placing ----------------------------------------------------------------
    def open(self) -> ClusterPlacement:
        """Connect to the scheduler.

        Raises
        ------
        ExperimentError
            The engine is not installed or the scheduler does not answer.
        """
        try:
            from distributed import Client
        except ImportError:
            raise ExperimentError(
                "--cluster needs Dask distributed: pip install "
                "'dfrl[cluster]' (or distributed) on this host and on every "
                "worker"
            ) from None
        try:
            self._client = Client(
                self.address,
                timeout=CONNECT_S,
                set_as_default=False,
                security=self.access.security(),
            )
        except (OSError, TimeoutError, ValueError) as exc:
            raise ExperimentError(f"cluster {self.address}: cannot connect: {exc}") from None
        return self

    def offered(self) -> dict[str, float]:
        """The amount of :data:`RESOURCE` each worker offers (worker address -> amount)."""
        workers = self._client.scheduler_info(n_workers=-1)["workers"]
        return {
            w: float(info.get("resources", {}).get(RESOURCE, 0.0)) for w, info in workers.items()
        }

    def place(self, robots: Sequence[str]) -> dict[str, Placement]:
        """Submit one task per robot and wait until each reports its service's address.

        Raises
        ------
        ExperimentError
            The workers offer too little of the resource for every robot at once (after
            waiting up to :data:`CONNECT_S` for workers that are still registering), a task
            failed (its reason given), or no robot reported for :data:`PLACE_S`.
        """
        from distributed import Event, Variable

        from dfrl.experiments.robot_host.cluster_task import serve_robot

        # wait for workers still registering: until no new one came for SETTLE_S
        deadline = time.monotonic() + CONNECT_S
        seen: set[str] = set()
        changed = time.monotonic()
        while True:
            offered = self.offered()
            used: dict[str, float] = {}
            for p in self.placements().values():
                used[p.worker] = used.get(p.worker, 0.0) + self.cpus
            fits = sum(int((a - used.get(w, 0.0)) // self.cpus) for w, a in offered.items())
            now = time.monotonic()
            if set(offered) != seen:
                seen, changed = set(offered), now
            if fits >= len(robots) or now > deadline or (seen and now - changed > SETTLE_S):
                break
            time.sleep(0.5)
        if fits < len(robots):
            raise ExperimentError(
                f"cluster {self.address}: {len(robots)} robots need {self.cpus:g} {RESOURCE} "
                f"each, but its {len(offered)} workers fit only {fits} more at once "
                f"({RESOURCE} offered: "
                f"{', '.join(f'{w} {a:g}' for w, a in offered.items()) or 'none'}); "
                f"start workers with --resources {RESOURCE}=N"
            )
        if self._lease is None:
            self._lease = Variable(f"dfrl-{self.run_key}-lease", client=self._client)
            self._lease.set(0)  # before any task looks at it
        for rid in robots:
            self._futures[rid] = self._client.submit(
                serve_robot,
                self.run_key,
                rid,
                lease_s=LEASE_S,
                tls=self.tls,
                key=f"dfrl-{self.run_key}-{rid}",
                resources={RESOURCE: self.cpus},
                pure=False,
                retries=0,
            )
        if self._thread is None:
            self._start_watch()
        waiting = {
            rid: Event(f"dfrl-{self.run_key}-{rid}-listening", client=self._client)
            for rid in robots
        }
        moved = time.monotonic()  # the last time a robot reported
        while waiting:
            for rid, listening in list(waiting.items()):
                if not listening.wait(timeout=0.05):
                    if self._futures[rid].done():
                        raise ExperimentError(
                            f"robot {rid} was not placed: {self._why(self._futures[rid])}"
                        )
                    continue
                host, port, worker = Variable(
                    f"dfrl-{self.run_key}-{rid}-address", client=self._client
                ).get(timeout=10)
                with self._lock:
                    self._placed[rid] = Placement(rid, str(host), int(port), str(worker))
                del waiting[rid]
                moved = time.monotonic()
            if waiting and time.monotonic() - moved > PLACE_S:
                raise ExperimentError(
                    f"robots {', '.join(waiting)} were not placed on cluster "
                    f"{self.address}: none reported for {PLACE_S:.0f} s"
                )
            time.sleep(0.2)
        return self.placements()

    def place_joiner(self, robot: str) -> str:
        """Place one robot that joins the run; its service's ``host:port`` (its
        ``robot_host``).

        Raises
        ------
        ExperimentError
            As :meth:`place` (a cluster that is full says so at once).
        """
        p = self.place([robot])[robot]
        self._say(f"cluster {self.address}: placed {robot}@{p.host}:{p.port} (it joins)")
        return f"{p.host}:{p.port}"

    @staticmethod
    def _why(future: Any) -> str:
        exc = future.exception() if future.status == "error" else None
        if exc is not None:
            return f"{type(exc).__name__}: {exc}"
        return (
            str(future.result().get("ended"))
            if future.status == "finished"
            else f"its task is {future.status}"
        )

    def placements(self) -> dict[str, Placement]:
        with self._lock:
            return dict(self._placed)

    def losses(self) -> list[str]:
        """Workers that left and tasks that ended during the run, one line each."""
        with self._lock:
            return list(self._losses)

    # -- while the run goes on -----------------------------------------------------------------
    def _start_watch(self) -> None:
        self._thread = threading.Thread(target=self._watch, name="cluster-watch", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        beat = 0
        while not self._stop.wait(WATCH_S):
            beat += 1
            try:
                self._lease.set(beat)
                workers = set(self._client.scheduler_info(n_workers=-1)["workers"])
            except Exception as exc:  # noqa: BLE001 - the scheduler's fault is reported
                self._lose("scheduler", f"cluster {self.address} did not answer: {exc}")
                continue
            for rid, p in self.placements().items():
                if p.worker not in workers:
                    self._lose(
                        rid,
                        f"cluster worker {p.worker} left the cluster; robot {rid} "
                        f"({p.host}:{p.port}) went with it",
                    )
                elif self._futures[rid].done() and not self._stop.is_set():
                    self._lose(
                        rid,
                        f"the cluster task of robot {rid} ended on {p.worker}: "
                        f"{self._why(self._futures[rid])}",
                    )

    def _lose(self, key: str, line: str) -> None:
        with self._lock:
            if key in self._said:
                return
            self._said.add(key)
            self._losses.append(line)
        self._say(f"CLUSTER: {line}")

    # -- the end -------------------------------------------------------------------------------
    def release(self) -> dict[str, Any]:
        """End every task (their services stop and save their files), stop watching, close the
        client; return what each task said (robot -> its result, or why it has none)."""
        from distributed import Event

        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10 * WATCH_S)
        if self._client is None:
            return {}
        ended: dict[str, Any] = {}
        try:
            if self._futures:
                Event(f"dfrl-{self.run_key}-stop", client=self._client).set()
                # a lost robot's task may wait for a free worker again: not for it
                alive = [f for rid, f in self._futures.items() if rid not in self._said]
                deadline = time.monotonic() + RELEASE_S
                while time.monotonic() < deadline and not all(f.done() for f in alive):
                    time.sleep(0.1)
                for rid, future in self._futures.items():
                    ended[rid] = (
                        future.result()
                        if future.status == "finished"
                        else {"robot": rid, "ended": self._why(future)}
                    )
                self._client.cancel(list(self._futures.values()))
        except Exception as exc:  # noqa: BLE001 - a cluster that is gone is reported
            ended.setdefault("error", f"{type(exc).__name__}: {exc}")
        finally:
            self._client.close(timeout=10)
            self._client = None
        self._ended = ended
        return ended

    def record(self) -> dict[str, Any]:
        """What ``cluster.json`` holds: the scheduler, the resource request, the placements,
        the losses and how each task ended."""
        return {
            "scheduler": self.address,
            "cluster_tls": str(self.access.tls) if self.access.tls is not None else None,
            "resources": {RESOURCE: self.cpus},
            "placements": {rid: p.__dict__ for rid, p in self.placements().items()},
            "losses": self.losses(),
            "tasks": self._ended,
        }


def placed_config(config: ExperimentConfig, placed: dict[str, Placement]) -> ExperimentConfig:
    """``config`` with every placed robot's ``robot_host`` the address of its service."""
    robots = tuple(
        replace(r, robot_host=f"{placed[r.id].host}:{placed[r.id].port}") if r.id in placed else r
        for r in config.robots
    )
    return config.replace(robots=robots)


def run_on_cluster(
    config: ExperimentConfig,
    output_dir: str | Path | ClaimedFolder,
    address: str,
    cpus: float = 1.0,
    progress: TextIO | None = sys.stderr,
    force: bool = False,
    tls: str | Path | None = None,
    cluster_tls: str | Path | None = None,
    insecure: bool = False,
) -> Results:
    """Run ``config`` with every robot that names no ``robot_host`` placed on the Dask cluster
    at ``address`` (see the module doc); the results folder gets ``cluster.json`` and
    ``summary.md`` a section "Cluster". ``tls`` is the platform's node folder (the run over
    mutual TLS), ``cluster_tls`` the driver's cluster folder (a ``tls://`` scheduler),
    ``insecure`` accepts a plaintext ``tcp://`` scheduler off loopback.

    Raises
    ------
    ClusterAccessError
        As :func:`cluster_access` (before anything else).
    ExperimentError
        No token (the workers' services prove the one in their ``dfrl.token``), the engine is
        missing, the cluster cannot be reached or cannot hold every robot, a robot could not
        be placed (nothing of the run started then).
    """
    from dfrl.experiments.driver.launcher.experiment import run

    access = cluster_access(address, cluster_tls, insecure)
    if config.token is None:
        raise ExperimentError(
            "--cluster: the robots' services prove the token of dfrl.token "
            "on their workers: give the same one (--token-file dfrl.token)"
        )

    def say(line: str) -> None:
        if progress is not None:
            print(line, file=progress, flush=True)

    local = [r.id for r in config.robots if r.robot_host is None]
    t0 = time.monotonic()
    placement = ClusterPlacement(access, cpus, say, tls=tls is not None).open()
    try:
        placed = placement.place(local)
        say(
            f"cluster {address}: placed "
            + ", ".join(f"{p.robot}@{p.host}:{p.port}" for p in placed.values())
            + f" in {time.monotonic() - t0:.1f} s"
        )
        results = run(
            placed_config(config, placed),
            output_dir,
            progress,
            force,
            tls=tls,
            placer=placement.place_joiner,
        )
    finally:
        t1 = time.monotonic()
        placement.release()
        say(f"cluster {address}: released the robots' tasks in {time.monotonic() - t1:.1f} s")
    out = results.output_dir
    (out / CLUSTER_FILE).write_text(
        json.dumps(placement.record(), indent=2) + "\n", encoding="utf-8"
    )
    with open(out / "summary.md", "a", encoding="utf-8") as fh:
        fh.write(
            f"\n## Cluster\n\n{len(placed)} robots placed on the Dask cluster {address} "
            f"({RESOURCE} {cpus:g} each); `{CLUSTER_FILE}` says where.\n"
        )
        for line in placement.losses() or ["no worker left the cluster during the run"]:
            fh.write(f"- {line}\n")
    return results
