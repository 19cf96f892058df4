"""Run one federated experiment, its robots spawned here or running on other hosts:
:func:`run` and the :class:`Launcher` behind it.

Threading: :meth:`Launcher.run` runs on the caller's thread, which owns the launcher's own
fields and every process of the run. Alongside it run the robot processes' reader threads
(hops, :class:`~.agent_roster.AgentRoster`), the remote robots' status poller and the console
node's readers; what they share lives in the rosters, each guarded by its lock. Another thread
may look at a running experiment through :meth:`Launcher.robots` and :meth:`Launcher.agent_at`.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
from dfrl.experiments.driver.launcher.agent_roster import AgentRoster
from dfrl.experiments.driver.launcher.agents import open_console
from dfrl.experiments.driver.launcher.joins import Joins
from dfrl.experiments.driver.launcher.monitor import monitor
from dfrl.experiments.driver.launcher.remote_hosts import console_host
from dfrl.experiments.driver.launcher.remote_robots import StatusPoller
from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robot_roster import RobotRoster
from dfrl.experiments.driver.launcher.robots import Robot, await_ready
from dfrl.experiments.driver.launcher.spawn import Site, launch_agents, start_robot, write_nodes
from dfrl.experiments.driver.results.ending import RunFacts, write_end_files
from dfrl.experiments.driver.results.files import ClaimedFolder, claim_output, write_json
from dfrl.experiments.driver.results.summary import Results
from dfrl.experiments.provenance import write_provenance
from dfrl.experiments.tls_folder import check_node_dir
from dfrl.experiments.tokens import SECRET_FILE, new_secret, write_secret_file


class Launcher:
    """Runs one experiment; see :func:`run`."""

    def __init__(
        self,
        config: ExperimentConfig,
        output_dir: str | Path | ClaimedFolder,
        progress: TextIO | None = sys.stderr,
        force: bool = False,
        tls: str | Path | None = None,
        placer: Callable[[str], str] | None = None,
    ) -> None:
        self._claimed = isinstance(output_dir, ClaimedFolder)
        path = output_dir.path if isinstance(output_dir, ClaimedFolder) else Path(output_dir)
        self._out = path.resolve()
        self._config = config
        self._force = force
        self._tls = Path(tls).resolve() if tls is not None else None
        self._placer = placer
        self._reporter = Reporter(self._out, progress)
        self._robots = RobotRoster(self._out, self._reporter, config.partition_wait_s)
        self._agents = AgentRoster(self._reporter)
        self._interrupted: str | None = None
        #: what the launcher is doing until the agents are launched (None afterwards): an
        #: error on the way is why the run never started
        self._stage: str | None = "starting the console node"
        self._start_error: str | None = None

    def robots(self) -> dict[str, Robot]:
        """The robots of the run so far, by id (callable from any thread)."""
        return self._robots.robots()

    def agent_at(self, agent: str) -> tuple[str, str, int] | None:
        """Where ``agent`` was last seen: (robot, ``get``/``set``, its iteration) (callable from
        any thread)."""
        return self._agents.at(agent)

    def run(self) -> Results:
        """Run the experiment. SIGTERM and SIGINT (when called from the main thread) stop it
        cleanly: the robots are told to stop (they save their tables; a robot that does not
        exit in time is killed and its last checkpoint kept as its table), the partial results
        are written, and the :class:`Results` come back with ``interrupted`` set.

        Raises
        ------
        ConfigError
            An arena is missing or does not parse, or robots on other hosts but no token
            (before anything is started).
        CertError
            The TLS folder lacks one of its files (before anything is started).
        FileExistsError
            The results folder is not empty and ``force`` is not set.
        """
        restore = []
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                restore.append((sig, signal.signal(sig, _interrupt)))
        try:
            return self._run()
        finally:
            for sig, handler in restore:
                signal.signal(sig, handler)

    def _prepare(self) -> ExperimentConfig:
        """Check everything that can be checked before anything starts, claim the results
        folder (unless the caller did) and write the token and the config into it; return the
        config with its token. The config run and written (``config.json``) is the resolved
        one (:meth:`ExperimentConfig.resolved`: every seed and trainer setting written out),
        so that ``dfrl run RESULTS/config.json`` runs the same experiment again."""
        c = self._config
        c.check()
        c = c.resolved()
        if c.token is None and c.remote_robots():
            where = c.remote_robots()[0].robot_host
            raise ConfigError(
                [
                    f"token: robots on other hosts ({where}) "
                    "prove the token their dfrl robot was started with: name it "
                    "in the config (without one a run makes a random token)"
                ]
            )
        if self._tls is not None:
            check_node_dir(self._tls)
        if not self._claimed:
            claim_output(self._out, self._force)
        token = c.token
        if token is None:  # a strong token of this run only
            token = new_secret()
            c = c.with_token(token)
        # the one file of the folder that holds the token (mode 0600): for dfrl join/inject
        write_secret_file(self._out / SECRET_FILE, [token])
        write_json(self._out / "config.json", c.public_dict())
        write_provenance(self._out)  # versions, commit, host, command line
        return c

    def _run(self) -> Results:
        c = self._config = self._prepare()
        t0 = self._reporter.start_clock()
        experiment_id = f"{c.name}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
        ok = True
        console = poller = None
        say = self._reporter.say
        try:
            host = console_host(c)
            assert c.token is not None, "_prepare() gave the run a token"
            console = open_console(
                c.token, self._out / "logs" / "console.err", host=host, tls=self._tls
            )
            poller = StatusPoller().start()
            site = Site(c, self._out, console, host, self._tls, experiment_id, poller)
            for spec in c.robots:
                self._stage = f"starting robot {spec.id}" + (
                    f" on its robot host {spec.robot_host}" if spec.robot_host else ""
                )
                self._robots.add(start_robot(site, spec, c.iterations, self._agents))
            robots = self._robots.robots()
            self._stage = "waiting for the robots to come up"
            await_ready(list(robots.values()))
            write_nodes(site, self._robots, self._agents)
            say(
                f"{len(robots)} robot processes up: "
                + ", ".join(
                    f"{rid}@{s.address[1]}"
                    for rid, s in self._robots.statuses().items()
                    if s.address is not None
                )
            )
            self._stage = "launching the agents"
            launch_agents(site, self._robots, self._agents, self._reporter)
            self._stage = None
            monitor(
                c,
                self._robots,
                self._agents,
                Joins(site, self._robots, self._agents, self._reporter, self._placer),
                self._reporter,
            )
        except KeyboardInterrupt as exc:
            ok = False
            self._interrupted = str(exc) or "KeyboardInterrupt"
            say(f"interrupted ({self._interrupted}): stopping the robots, they save their tables")
        except BaseException as exc:
            ok = False
            self._interrupted = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            if self._stage is not None:
                why = " ".join(str(exc).split())
                said = "accepts none of this run's tokens" in why  # the console's words
                refused = not said and "permission" in why.lower() and "token" in why.lower()
                self._start_error = (
                    f"{self._stage} failed"
                    + (": the robot host refused the run's token" if refused else "")
                    + f": {why}"
                )
            self._robots.kill_all()
            raise
        finally:
            self._robots.end_stalls()
            try:
                self._robots.shutdown()
            except BaseException:
                self._robots.kill_all()
                raise
            if poller is not None:
                poller.close()
            self._robots.gather(self._out)
            if console is not None:
                console.close()
            results = self._collect(time.monotonic() - t0, ok)
        return results

    def _collect(self, wall: float, ok: bool) -> Results:
        """Read the agents' logs one last time and write the end-of-run files
        (:func:`~dfrl.experiments.driver.results.ending.write_end_files`, which ``dfrl collect``
        also uses), with the lines the robots kept that the console did not get."""
        self._agents.read_logs(self._robots, kept_in=self._out)
        self._robots.show_progress()  # lines the robots wrote after the last look
        r = self._robots
        facts = RunFacts(
            wall,
            ok,
            self._interrupted,
            r.crashed(),
            r.iterations(),
            r.lost(),
            r.stalls(),
            r.gather_errors(),
            r.gathered(),
            r.failed_joins(),
            resumed=r.resumed(),
            finished=r.finished(),
            start_error=self._start_error,
        )
        return write_end_files(
            self._out,
            self._config,
            list(r.robots()),
            self._agents.logs(),
            {a.name: a.rounds for a in self._agents.infos()},
            facts,
            self._reporter.say,
        )


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def run(
    config: ExperimentConfig,
    output_dir: str | Path | ClaimedFolder,
    progress: TextIO | None = sys.stderr,
    force: bool = False,
    tls: str | Path | None = None,
    placer: Callable[[str], str] | None = None,
) -> Results:
    """Run a federated experiment on loopback and write its results folder.

    Keeps the run's token (the config's, or a new random one) in ``secret.token`` (mode
    0600, the only file of the folder that holds it; ``dfrl join`` and ``dfrl inject`` read
    it) and hands it to every process it starts through its environment, never its command
    line. Starts one robot process per robot, waits for their addresses, writes
    ``nodes.json``, launches one dFRL itinerary agent per learning algorithm (the agent of an
    algorithm visits only the robots using it), follows the agents' round logs and the nodes'
    progress lines, starts robots that join during the run, and at the end writes
    ``metrics.csv``, ``rounds.csv``, the plots and ``summary.md``. A robot that crashes is
    reported and the others go on; every child is killed on an exception or Ctrl-C.

    Parameters
    ----------
    config : ExperimentConfig
    output_dir : str, Path or ClaimedFolder
        Results folder: created, or empty (a non-empty one is refused unless ``force``, which
        empties it first: two runs never mix their files). A :class:`ClaimedFolder` (what
        ``dfrl run`` passes) was claimed by the caller already and is used as it is.
    progress : TextIO or None
        Where progress lines go (None: quiet).
    force : bool
    tls : str, Path or None
        A node's TLS folder (``ca.crt``, ``node.crt``, ``node.key``; ``dfrl certs node``): the
        console node and every robot process spawned here speak mutual TLS with it (one
        credential for all local processes); remote robots must run ``dfrl robot --tls``
        with a certificate of the same CA. None (default): plaintext.
    placer : callable or None
        Where a robot that joins without a ``robot_host`` runs: ``placer(robot)`` starts its
        service elsewhere and returns its ``host:port`` (``dfrl run --cluster`` places it on
        the cluster); None: a robot process spawned here.
    """
    return Launcher(config, output_dir, progress, force, tls, placer).run()
