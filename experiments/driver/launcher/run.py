"""Run one federated experiment, its robots spawned here or running on other hosts:
:func:`run` and the :class:`Launcher` behind it."""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.tls_folder import check_node_dir
from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
from dfrl.experiments.driver.launcher.children import await_ready
from dfrl.experiments.driver.launcher.agents import open_console
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.driver.launcher.monitor import monitor, poll_logs
from dfrl.experiments.driver.launcher.remote_robots import StatusPoller, console_host
from dfrl.experiments.driver.launcher.shutdown import kill_all, shutdown
from dfrl.experiments.driver.launcher.spawn import launch_agents, spawn, write_nodes
from dfrl.experiments.driver.launcher.state import RunState
from dfrl.experiments.driver.results.faults import assess
from dfrl.experiments.science.report.plots import plot_experiment
from dfrl.experiments.driver.results.files import claim_output, write_json
from dfrl.experiments.driver.results.tables import keep_checkpoints
from dfrl.experiments.driver.results.evaluations import merge_evaluations
from dfrl.experiments.driver.results.metrics import merge_metrics
from dfrl.experiments.driver.results.rounds import read_shares, write_rounds_csv
from dfrl.experiments.driver.results.summary import Results, write_summary
from dfrl.experiments.tokens import SECRET_FILE, new_secret, write_secret_file

class Launcher:
    """Runs one experiment; see :func:`run`."""

    def __init__(self, config: ExperimentConfig, output_dir: str | Path,
                 progress: TextIO | None = sys.stderr, force: bool = False,
                 tls: str | Path | None = None) -> None:
        self.state = RunState(config, Path(output_dir).resolve(), progress)
        self.state.tls = Path(tls).resolve() if tls is not None else None
        self.force = force

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

    def _run(self) -> Results:
        st = self.state
        c = st.config
        c.check()
        if c.token is None and c.remote_robots():
            raise ConfigError([f"token: robots on other hosts ({c.remote_robots()[0].robot_host}) "
                               "prove the token their dfrl robot was started with: name it "
                               "in the config (without one a run makes a random token)"])
        if st.tls is not None:
            check_node_dir(st.tls)
        claim_output(st.out, self.force)
        if c.token is None:                 # a strong token of this run only
            c = st.config = c.with_token(new_secret())
        # the one file of the folder that holds the token (mode 0600): for dfrl join/inject
        write_secret_file(st.out / SECRET_FILE, [c.token])
        write_json(st.out / "config.json", c.public_dict())
        st.t0 = time.monotonic()
        st.experiment_id = f"{c.name}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
        ok = True
        try:
            st.console_host = console_host(c)
            st.console = open_console(c.token, st.out / "logs" / "console.err",
                                      host=st.console_host, tls=st.tls)
            children = [spawn(st, r, c.iterations) for r in c.robots]
            st.poller = StatusPoller(st.remote()).start()
            await_ready([ch for ch in children if ch.robot.robot_host is None])
            write_nodes(st)
            st.say(f"{len(children)} robot nodes up: " + ", ".join(
                f"{rid}@{ch.address[1]}" for rid, ch in st.children.items()))
            launch_agents(st)
            monitor(st)
        except KeyboardInterrupt as exc:
            ok = False
            st.interrupted = str(exc) or "KeyboardInterrupt"
            st.say(f"interrupted ({st.interrupted}): stopping the robots, they save their tables")
        except BaseException as exc:
            ok = False
            st.interrupted = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            kill_all(st)
            raise
        finally:
            st.end_stalls()
            try:
                shutdown(st)
            except BaseException:
                kill_all(st)
                raise
            if st.poller is not None:
                st.poller.close()
            self._gather()
            if st.console is not None:
                st.console.close()
            results = self._collect(time.monotonic() - st.t0, ok)
        return results

    def _gather(self) -> None:
        """Copy every remote robot's result files into the results folder, over the
        platform (a robot that cannot give them is a fault, said and recorded)."""
        st = self.state
        for ch in st.remote():
            if ch.robot.id not in st.lost:
                ch.poll_samples()           # its last lines, for the view's last events
            try:
                st.gathered[ch.robot.id] = ch.gather(st.out)
            except ExperimentError as exc:
                rid = ch.robot.id
                st.say(f"files of {rid} not gathered: {exc}")
                if rid in st.lost:          # already counted: say it with the loss
                    st.lost[rid] += "; its result files could not be fetched"
                else:                       # answered till the end, then failed to give them
                    st.gather_errors.append(f"files of {rid} not gathered: {exc}")

    def _collect(self, wall: float, ok: bool) -> Results:
        st = self.state
        poll_logs(st)
        st.view_samples()                   # lines the robots wrote after the last look
        robots = list(st.children)
        st.from_checkpoint = keep_checkpoints(st.out, robots)
        for rid in st.from_checkpoint:
            st.say(f"table of {rid} kept from its last checkpoint (tables/{rid}.npy)")
        merge_metrics(st.out, robots)
        merge_evaluations(st.out, robots)
        shares = {rid: read_shares(st.out / f"shares_{rid}.csv") for rid in robots}
        rows = write_rounds_csv(st.out / "rounds.csv", st.logs.values(), robots, shares)
        plots: list[Path] = []
        plot_error = None
        try:
            plots = plot_experiment(st.out, title=st.config.default_title())
        except ImportError as exc:
            plot_error = f"not drawn: {exc.name or 'matplotlib'} is not installed " \
                         "(pip install 'dfrl[plot]')"
        except Exception as exc:  # noqa: BLE001 - plots are optional, results are not
            plot_error = f"failed: {exc!r}"
        if plot_error:
            st.say(f"plots {plot_error}")
        finished = {n: lg.finished for n, lg in st.logs.items()}
        problems = {n: [f"round {a.round} aborted: {a.error}" for a in lg.aborted]
                    + [f"unreadable line: {u}" for u in lg.unreadable]
                    for n, lg in st.logs.items()}
        for name, lines in problems.items():
            for line in lines:
                st.say(f"{name}: {line}")
        iters = {rid: ch.iteration for rid, ch in st.children.items()}
        faults = assess(st.config, [(lg, st.agents[n].rounds) for n, lg in st.logs.items()],
                        st.lost, st.stalls, st.gather_errors)
        ok = ok and all(v is not None for v in finished.values()) and faults.complete(st.config)
        result = Results(st.out, st.config, wall, rows, dict(st.crashed), finished, iters,
                         plots, ok, st.interrupted, problems, plot_error, faults,
                         dict(st.gathered), list(st.from_checkpoint))
        write_summary(result)
        return result


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def run(config: ExperimentConfig, output_dir: str | Path,
        progress: TextIO | None = sys.stderr, force: bool = False,
        tls: str | Path | None = None) -> Results:
    """Run a federated experiment on loopback and write its results folder.

    Keeps the run's token (the config's, or a new random one) in ``secret.token`` (mode
    0600, the only file of the folder that holds it; ``dfrl join`` and ``dfrl inject`` read
    it) and hands it to every process it starts through its environment, never its command
    line. Starts one robot node process per robot, waits for their addresses, writes
    ``nodes.json``, launches one dFRL itinerary agent per learning algorithm (the agent of an
    algorithm visits only the robots using it), follows the agents' round logs and the nodes'
    progress lines, starts robots that join during the run, and at the end writes
    ``metrics.csv``, ``rounds.csv``, the plots and ``summary.md``. A robot that crashes is
    reported and the others go on; every child is killed on an exception or Ctrl-C.

    Parameters
    ----------
    config : ExperimentConfig
    output_dir : str or Path
        Results folder: created, or empty (a non-empty one is refused unless ``force``, which
        empties it first: two runs never mix their files).
    progress : TextIO or None
        Where progress lines go (None: quiet).
    force : bool
    tls : str, Path or None
        A node's TLS folder (``ca.crt``, ``node.crt``, ``node.key``; ``dfrl certs node``): the
        console node and every robot node spawned here speak mutual TLS with it (one
        credential for all local processes); remote robots must run ``dfrl robot --tls``
        with a certificate of the same CA. None (default): plaintext.
    """
    return Launcher(config, output_dir, progress, force, tls).run()
