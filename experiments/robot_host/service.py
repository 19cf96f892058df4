"""The robot process as a long-lived service: ``dfrl robot`` (contract K5).

``DFRL_TOKEN=T dfrl robot --host H --port P [--advertise A] [--workdir DIR]`` (or
``--token-file FILE``) starts one process
that embeds a platform node bound to H:P, prints ``dfrl robot listening on A:P`` and then
waits to be configured over the platform. It serves experiments one after another; its
lifetime does not depend on stdin; SIGTERM and SIGINT stop it cleanly (the current iteration
is finished, the files flushed, the platform closed, exit status 0).

Peers that proved the node's token send ``dfrl_robot(Request)`` (``pybridge/robot_service.pl``
checks them and queues them for this process's main thread, which answers them between two
control steps and while idle): ``status``, ``configure(Json)``, ``start``, ``stop``, ``files``,
``fetch(Name, Offset, Max)``. States: ``idle`` -> ``configured`` -> ``running`` ->
``finished`` (or ``failed``); ``configure`` is allowed in ``idle``, ``finished`` and
``failed`` and replaces the last experiment, whose files stay in ``WORKDIR/<its id>/``.
"""

from __future__ import annotations

import base64
import json
import signal
import socket
import sys
from collections.abc import Sequence
from enum import Enum
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.robot_host.config import Mode
from dfrl.experiments.robot_host.lines import ProtocolLines
from dfrl.experiments.robot_host.process import keep_agent_logs, load_agent_program, start_node
from dfrl.experiments.robot_host.service_config import config_error, parse_configure
from dfrl.experiments.robot_host.training import Training
from dfrl.experiments.tokens import Token
from dfrl.pybridge.serving import RequestError
from dfrl.pybridge.terms import Atom, Term, Var

__all__ = ["State", "RobotService", "MAX_CHUNK"]

#: Largest ``fetch`` chunk (bytes).
MAX_CHUNK = 1 << 20
#: Folders of an experiment that are the service's own, not results (``files`` leaves them out).
PRIVATE_DIRS = ("checkpoint", "service")


class State(str, Enum):
    """Where the service is (``status``'s ``state``)."""

    IDLE = "idle"
    CONFIGURED = "configured"
    RUNNING = "running"
    FINISHED = "finished"
    FAILED = "failed"


def _state_error(action: str, state: State) -> RequestError:
    return RequestError(
        Term("permission_error", Atom(action), Atom("robot_state"), Atom(state.value))
    )


class RobotService:
    """One ``dfrl robot`` process.

    Parameters
    ----------
    host, port
        Address to bind (``0.0.0.0`` and host names allowed; port 0: the OS chooses).
    token : int, str or a sequence of them
        The token(s) peers (and arriving agents) must prove (one at least).
    advertise : str, optional
        Host others reach this node at (default: the bound host; ``0.0.0.0`` becomes the host
        name).
    workdir : Path
        Experiments' files go to ``workdir/<experiment id>/``.
    out : TextIO
        Where the listening line and state notices are printed.
    insecure : bool
        Accept a weak token off loopback without TLS.
    tls : Path, optional
        A node TLS folder (``dfrl certs node``): every connection is mutual TLS.
    trust : sequence of str
        With ``tls``: certificate names whose code is installed without the sandbox check
        (node option ``trusted_peers``).
    bounds : dict, optional
        Node options bounding agents and frames (``agent_cpu_limit``, ``max_agents``, ...;
        :data:`dfrl.experiments.cli.node.BOUND_FLAGS`), a positive number or ``"infinite"``.

    Raises
    ------
    ValueError
        ``trust`` without ``tls``.
    """

    def __init__(
        self,
        host: str,
        port: int,
        token: Token | Sequence[Token],
        advertise: str | None = None,
        workdir: Path = Path("dfrl-robot"),
        out: TextIO = sys.stdout,
        insecure: bool = False,
        tls: Path | None = None,
        trust: Sequence[str] = (),
        bounds: dict[str, int | float | str] | None = None,
    ) -> None:
        if trust and tls is None:
            raise ValueError("trusting peers by name needs tls (a TLS certificate name)")
        self.bind = (host, int(port))
        self.trust = tuple(trust)
        self.insecure = insecure
        self.bounds = dict(bounds or {})
        self.tls = Path(tls).resolve() if tls is not None else None
        self.tokens: list[Token] = [token] if isinstance(token, (int, str)) else list(token)
        if not self.tokens:
            raise ValueError("a robot service needs a token")
        self.advertise = advertise
        self.workdir = Path(workdir).resolve()
        self.out = out
        self.bridge: Any = None
        self.node_name: Any = None
        self.address: tuple[str, int] = (host, int(port))
        self.state = State.IDLE
        self.run: Training | None = None
        self.experiment: str | None = None
        self.error: str | None = None
        self._signalled = False
        self._logs: list[Any] = []

    # -- life cycle ----------------------------------------------------------------------------
    def start(self) -> tuple[str, int]:
        """Start the platform node; print ``dfrl robot listening on A:P``; return (A, P)."""
        from dfrl.pybridge import Bridge

        self.workdir.mkdir(parents=True, exist_ok=True)
        self.bridge = Bridge()
        self.bridge.load_platform()
        load_agent_program(self.bridge, "dfrl robot")
        self.bridge.enable_service()
        host, port = self.bind
        adv = self.advertise
        options: dict[str, Any] = {
            "tokens": [Atom(t) if isinstance(t, str) else t for t in self.tokens],
            "idle_timeout": 30.0,
        }
        if self.insecure:
            options["insecure"] = True
        if self.tls is not None:
            options["tls"] = str(self.tls)
        if self.trust:
            options["trusted_peers"] = [Atom(name) for name in self.trust]
        for name, value in self.bounds.items():
            options[name] = Atom(value) if isinstance(value, str) else value
        if adv and port:
            options["advertise"] = Term(":", Atom(adv), port)
        self.node_name = start_node(self.bridge, host, port, **options)
        bound_host, bound_port = self.bridge.address(self.node_name)
        adv_host = adv or str(bound_host)
        if adv_host in ("0.0.0.0", "::", ""):
            adv_host = socket.gethostname()
        self.address = (adv_host, int(bound_port))
        self.say(f"dfrl robot listening on {adv_host}:{bound_port}")
        return self.address

    def install_signals(self) -> None:
        """SIGTERM and SIGINT end :meth:`serve_forever` cleanly."""

        def stop(signum: int, _frame: Any) -> None:
            self._signalled = True

        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)

    def serve_forever(self) -> int:
        """Serve until signalled; return the exit status (0)."""
        while not self._signalled:
            if self.state is State.RUNNING:
                try:
                    more = self.training.step()
                except Exception as exc:  # noqa: BLE001 - a failed run is reported, not fatal
                    self._fail(exc)
                    continue
                if not more and self.state is State.RUNNING:
                    self._end_run(self._how_it_ended())
            else:
                self.bridge.serve_service(self.handle, timeout=0.025)
                if self._serves_tables():
                    self.bridge.serve_pending(timeout=0.025)
        if self.state is State.RUNNING:
            self._end_run("stopped by a signal")
        return 0

    def _how_it_ended(self) -> str:
        """A step that returned because of a signal ended the run by that signal."""
        if self._signalled:
            return "stopped by a signal"
        return "stopped" if self.training.stopped else "finished"

    def _serves_tables(self) -> bool:
        if self.run is None:
            return False
        if self.state is State.FINISHED:
            return True  # an agent's last visit after our last step
        return self.state is State.CONFIGURED and self.run.config.mode is Mode.ASYNC

    def close(self) -> None:
        """Close the current run and the platform."""
        self._close_run()
        if self.bridge is not None:
            self.bridge.close()
            self.bridge = None

    @property
    def training(self) -> Training:
        """The run of the configured experiment (there is one from CONFIGURED on)."""
        if self.run is None:
            raise RuntimeError(f"dfrl robot: no experiment configured (state {self.state})")
        return self.run

    def say(self, line: str) -> None:
        """Print one line on the service's output."""
        self.out.write(line + "\n")
        self.out.flush()

    # -- TrainingHost -----------------------------------------------------------------------
    def wait(self, seconds: float) -> None:
        """While a run waits: answer service requests (at most ``seconds``)."""
        self.bridge.serve_service(self.handle, timeout=max(0.0, seconds))

    def should_stop(self) -> bool:
        """A run ends early once the process is signalled or told to stop."""
        return self._signalled or self.state is not State.RUNNING

    # -- requests ------------------------------------------------------------------------------
    def handle(self, op: Any) -> Any:
        """The reply term to one ``dfrl_robot`` request (already checked by Prolog)."""
        if op == "status":
            return Term("ok", Term("json", json.dumps(self.status())))
        if op == "start":
            return self._start()
        if op == "stop":
            return self._stop()
        if op == "files":
            return Term("ok", [Term("file", name, size) for name, size in self.files()])
        if isinstance(op, Term) and op.name == "configure" and op.arity == 1:
            return self._configure(op.args[0])
        if isinstance(op, Term) and op.name == "fetch" and op.arity == 3:
            data, eof = self.fetch(str(op.args[0]), int(op.args[1]), int(op.args[2]))
            return Term(
                "ok",
                Term(
                    "chunk",
                    base64.b64encode(data).decode("ascii"),
                    Atom("true" if eof else "false"),
                ),
            )
        raise RequestError(Term("domain_error", Atom("dfrl_robot_request"), op))

    def status(self) -> dict[str, Any]:
        """What ``status`` answers."""
        run = self.run
        node_id = self.bridge.node_value(self.node_name, "id") if self.bridge is not None else None
        return {
            "robot": run.config.robot if run is not None else None,
            "state": self.state.value,
            "experiment": self.experiment,
            "iteration": run.iteration if run is not None else 0,
            "iterations": run.config.iterations if run is not None else 0,
            "shares": run.shares if run is not None else 0,
            "error": self.error,
            "address": [self.address[0], self.address[1]],
            "node_id": None if node_id is None else str(node_id),
            "clone_limit": self._clone_limit(),
        }

    def _clone_limit(self) -> int | str | None:
        """The node's clone limit (clones admitted a minute; ``infinite``): a tree run's driver
        checks it is enough before it starts."""
        if self.bridge is None:
            return None
        sol = self.bridge.prolog.call(
            "node_option", self.node_name, Atom("clone_limit"), Var("V"), module="node"
        )
        value = None if sol is None else sol["V"]
        return value if isinstance(value, int) or value is None else str(value)

    def _start(self) -> Any:
        if self.state is not State.CONFIGURED:
            raise _state_error("start", self.state)
        self.state = State.RUNNING
        self.training.begin()
        self.say(f"dfrl robot: experiment {self.experiment} running")
        return Term("ok", Atom("true"))

    def _stop(self) -> Any:
        if self.state in (State.RUNNING, State.CONFIGURED):
            self.training.stopped = True
            self._end_run("stopped")
        return Term("ok", Atom("true"))

    def _end_run(self, how: str) -> None:
        try:
            self.training.finish()
        except Exception as exc:  # noqa: BLE001 - reported as the run's failure
            self._fail(exc)
            return
        self.state = State.FINISHED
        self.training.lines.done(self.training.iteration, self.training.shares)
        self.say(
            f"dfrl robot: experiment {self.experiment} {how} at iteration "
            f"{self.training.iteration} ({self.training.shares} shares)"
        )

    def _fail(self, exc: BaseException) -> None:
        self.state = State.FAILED
        self.error = f"{type(exc).__name__}: {exc}"
        if self.run is not None:
            self.run.warn(f"dfrl robot: experiment {self.experiment} failed: {self.error}")
            self.run.stopped = True
            try:
                self.run.flush()
            except (OSError, ValueError) as flush_exc:
                self.run.warn(f"dfrl robot: flushing the files failed: {flush_exc}")
        self.say(f"dfrl robot: experiment {self.experiment} failed: {self.error}")

    def _configure(self, text: Any) -> Any:
        if self.state not in (State.IDLE, State.FINISHED, State.FAILED):
            raise _state_error("configure", self.state)
        experiment, config, resume = parse_configure(str(text), self.tokens, self.workdir)
        self._close_run()
        self.experiment, self.error, self.state = experiment, None, State.IDLE
        out = Path(config.out_dir)
        (out / "logs").mkdir(parents=True, exist_ok=True)
        keep_agent_logs(self.bridge, self.node_name, out / "agent_logs" / config.robot)
        lines_fh = open(out / "logs" / f"{config.robot}.out", "a", encoding="utf-8")
        err_fh = open(out / "logs" / f"{config.robot}.err", "a", encoding="utf-8")
        self._logs = [lines_fh, err_fh]

        def warn(message: str) -> None:
            err_fh.write(message + "\n")
            err_fh.flush()
            print(message, file=sys.stderr, flush=True)

        run = Training(
            config,
            self.bridge,
            ProtocolLines(lines_fh, config.robot, config.events),
            host=self,
            resume=resume,
            poll_every=1,
            warn=warn,
        )
        try:
            run.open()
            run.register()
        except Exception as exc:  # noqa: BLE001 - a bad configure leaves the service up
            run.close()
            self._close_logs()
            self.experiment = None
            if isinstance(exc, FileNotFoundError) and resume:
                raise config_error(f"no checkpoint to resume from: {exc.filename}") from None
            raise config_error(f"{type(exc).__name__}: {exc}") from None
        self.run, self.state = run, State.CONFIGURED
        self._forget_leases(warn)
        self.say(
            f"dfrl robot: experiment {experiment} configured (robot {config.robot}, "
            f"{config.iterations} iterations"
            f"{', resumed at ' + str(run.iteration) if resume else ''})"
        )
        return Term("ok", Atom("true"))

    def _forget_leases(self, warn: Any) -> None:
        """The node forgets the epochs, writes and checkpoints of the agents of the experiment
        before (lease_book:lease_forget/1): the next experiment's agent may bear the same name
        and starts again at epoch 1 and round 1, which the robot's fencing would refuse."""
        try:
            self.bridge.prolog.call("lease_forget", self.node_name, module="lease_book")
        except Exception as exc:  # noqa: BLE001 - the run goes on; the warning says what failed
            warn(f"dfrl robot: the node kept the leases of the experiment before: {exc}")

    def files(self) -> list[tuple[str, int]]:
        """(name relative to the experiment's folder, size) of its result files, sorted."""
        if self.experiment is None:
            return []
        base = self.workdir / self.experiment
        for fh in self._logs:
            fh.flush()
        if self.run is not None:
            self.run.flush()
        found = []
        for p in sorted(base.rglob("*")):
            rel = p.relative_to(base)
            if not p.is_file() or rel.parts[0] in PRIVATE_DIRS or p.name.startswith("."):
                continue
            found.append((rel.as_posix(), p.stat().st_size))
        return found

    def fetch(self, name: str, offset: int, size: int) -> tuple[bytes, bool]:
        """At most ``size`` bytes of result file ``name`` from ``offset``; and whether they
        reach its end."""
        listed = dict(self.files())
        if name not in listed or self.experiment is None:
            raise RequestError(Term("existence_error", Atom("result_file"), name))
        with open(self.workdir / self.experiment / name, "rb") as fh:
            fh.seek(offset)
            data = fh.read(min(size, MAX_CHUNK))
            eof = fh.tell() >= listed[name] and len(fh.read(1)) == 0
        return data, eof

    def _close_run(self) -> None:
        if self.run is not None:
            self.run.close()
            self.run = None
        self._close_logs()

    def _close_logs(self) -> None:
        for fh in self._logs:
            fh.close()
        self._logs = []
