"""The spawned robot process's life cycle (:class:`RobotProcess`) and its entry point."""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol, TextIO

from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.robot_host.config import Mode, RobotConfig
from dfrl.experiments.robot_host.lines import ProtocolLines, StdinWatch
from dfrl.experiments.robot_host.training import Training
from dfrl.experiments.tokens import TOKEN_ENV, pop_env_tokens

__all__ = [
    "RobotProcess",
    "ProcessProbe",
    "main",
    "load_agent_program",
    "NodeStartError",
    "start_node",
    "keep_agent_logs",
]


class ProcessProbe(Protocol):
    """A measurement a tool installs in a robot process it starts (``dfrl bench round --trace``
    runs :mod:`dfrl.experiments.tools.bench.traced_robot`, which passes one to :func:`main`).

    The robot process knows no benchmark: it calls :meth:`started` once its platform and the
    agent program are loaded (before the robot is built and the node listens), and
    :meth:`closing` before its bridge closes.
    """

    def started(self, bridge: Any, config: RobotConfig) -> None: ...

    def closing(self, bridge: Any, config: RobotConfig) -> None: ...


class NodeStartError(ExperimentError):
    """The robot's platform node did not start (address taken, a weak token off loopback, ...).

    ``str()`` is the platform's own message for the error (``platform_errors:message_text/2``);
    ``term`` the Prolog error term as data, ``weak_token`` true when a token was refused as too
    weak for the address.
    """

    def __init__(self, message: str, term: Any) -> None:
        super().__init__(message)
        self.term = term

    @property
    def address_in_use(self) -> bool:
        """The node's port is held by another socket (``socket_error(eaddrinuse, _)``)."""
        formal = getattr(self.term, "args", (None,))[0]
        return (
            getattr(formal, "name", None) == "socket_error"
            and str(getattr(formal, "args", ("",))[0]) == "eaddrinuse"
        )

    @property
    def weak_token(self) -> bool:
        context = getattr(self.term, "args", (None, None))[-1]
        reason = getattr(context, "args", (None, None))[-1]
        return getattr(reason, "name", None) == "weak_secret"


def start_node(bridge: Any, host: str, port: int, **options: Any) -> Any:
    """``bridge.start(host, port, **options)``; a Prolog error becomes a :class:`NodeStartError`
    that reads as the platform prints it (never a ``Term(...)`` repr)."""
    from dfrl.pybridge import PrologError, Var

    try:
        return bridge.start(host, port, **options)
    except PrologError as exc:
        try:
            sol = bridge.call("message_text", exc.term, Var("Text"), module="platform_errors")
            text = str(sol["Text"]) if sol else str(exc)
        except Exception:  # noqa: BLE001 - the raw error is still better than none
            text = str(exc)
        raise NodeStartError(text, exc.term) from exc


class _StdinHost:
    """The spawned node's :class:`TrainingHost`: its stdin says when to stop."""

    def __init__(self, watch: StdinWatch) -> None:
        self.watch = watch

    def wait(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def should_stop(self) -> bool:
        return self.watch.poll()


class RobotProcess:
    """One spawned robot process (see :mod:`dfrl.experiments.robot_host`).

    Parameters
    ----------
    config : RobotConfig
    stdout : TextIO
        Where the protocol lines go.
    stdin : TextIO or None
        Watched for EOF / ``stop`` (not when it is at end of file from the start).
    probes : sequence of ProcessProbe
        Measurements a tool installs (none in a run).
    """

    def __init__(
        self,
        config: RobotConfig,
        stdout: TextIO = sys.stdout,
        stdin: TextIO | None = sys.stdin,
        probes: Sequence[ProcessProbe] = (),
    ) -> None:
        self.config = config
        self.lines = ProtocolLines(stdout, config.robot, config.events)
        self.stdin = StdinWatch(stdin)
        self.out_dir = Path(config.out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.bridge: Any = None
        self.run_: Training | None = None
        self.probes = tuple(probes)

    @property
    def iteration(self) -> int:
        """Iterations done so far."""
        return self.run_.iteration if self.run_ is not None else 0

    @property
    def shares(self) -> int:
        """Shares applied so far."""
        return self.run_.shares if self.run_ is not None else 0

    # -- life cycle ----------------------------------------------------------------------------
    def start(self) -> tuple[str, int]:
        """Start the platform node, build the robot (or the static robot its config asks for)
        and register it with the bridge; return the address."""
        from dfrl.pybridge import Atom, Bridge

        c = self.config
        self.bridge = Bridge()
        self.bridge.load_platform()
        load_agent_program(self.bridge, f"robot {c.robot}")
        for probe in self.probes:
            probe.started(self.bridge, c)
        self.run_ = Training(c, self.bridge, self.lines, host=_StdinHost(self.stdin), poll_every=50)
        self.run_.open()
        self.run_.register()
        options: dict[str, Any] = {"idle_timeout": 5.0}
        if c.token is not None:  # none: an open node (node_start/3 warns on loopback)
            options["tokens"] = [Atom(c.token) if isinstance(c.token, str) else c.token]
        if c.tls is not None:
            options["tls"] = str(Path(c.tls).resolve())
        if c.clone_limit is not None:
            options["clone_limit"] = c.clone_limit
        name = start_node(self.bridge, c.host, 0, **options)
        keep_agent_logs(self.bridge, name, self.out_dir / "agent_logs" / c.robot)
        host, port = self.bridge.address(name)
        self.lines.node(str(host), int(port))
        return str(host), int(port)

    def run(self) -> int:
        """The control loop; returns the exit code."""
        run = self.run_
        if run is None:
            raise RuntimeError(f"robot {self.config.robot}: run() before start()")
        if not run.simulated:
            while not self.stdin.poll():
                self.bridge.serve_pending(timeout=0.05)
            return 0
        while run.step():
            pass
        run.finish()
        if not run.stopped:
            self._linger()
        self.lines.done(self.iteration, self.shares)
        return 0

    def _agents_here(self) -> bool:
        try:
            return bool(self.bridge.list_agents())
        except Exception as exc:  # noqa: BLE001 - a failing listing must not keep us alive
            print(f"robot {self.config.robot}: listing agents failed: {exc}", file=sys.stderr)
            return False

    def _linger(self) -> None:
        """After the last iteration: serve until the agent left (sync) or stdin closes."""
        deadline = time.monotonic() + self.config.grace_s
        sync = self.config.mode is Mode.SYNC
        while time.monotonic() < deadline:
            self.bridge.serve_pending(timeout=0.05)
            if self.stdin.poll():
                break
            if sync and not self._agents_here():
                break

    def close(self) -> None:
        """Close files, the platform and the simulation."""
        if self.run_ is not None:
            self.run_.close()
        if self.bridge is not None:
            for probe in self.probes:
                probe.closing(self.bridge, self.config)
            self.bridge.close()


def load_agent_program(node: Any, who: str) -> None:
    """Load the dFRL agent program into the node's Tartarus code store (warn if missing)."""
    from dfrl.platform_pl import DFRL_AGENT_DIR

    agent_file = DFRL_AGENT_DIR / "dfrl_agent.pl"
    if agent_file.is_file():
        node.assert_file_to_tartarus(str(agent_file))
    else:
        print(f"{who}: warning: {agent_file} not found", file=sys.stderr)


def keep_agent_logs(bridge: Any, node: Any, folder: Path) -> Path:
    """Make the round-log outbox of ``node`` keep every line an agent logs there in
    ``folder`` (``folder/rounds_<agent>.log``, see ``platform_pl/dfrl_agent/log_outbox.pl``):
    on this host, whatever the console's host can reach. Returns ``folder``."""
    from dfrl.platform_pl import DFRL_AGENT_DIR
    from dfrl.pybridge import Atom, Term

    bridge.call("use_module", Atom(str(DFRL_AGENT_DIR / "log_outbox.pl")))
    bridge.call("outbox_configure", node, [Term("keep_dir", str(folder))], module="log_outbox")
    return folder


def main(argv: list[str] | None = None, probes: Sequence[ProcessProbe] = ()) -> int:
    """Entry point: ``python -m dfrl.experiments.robot_host --config NODE.json``; ``probes``
    are the measurements of a tool that runs the robot process its own way.

    The node's token comes from the environment (``DFRL_TOKEN``, deleted from it once read so
    that no child inherits it; :mod:`dfrl.experiments.tokens`), or else from the config file;
    never from the command line.
    """
    parser = argparse.ArgumentParser(
        prog="python -m dfrl.experiments.robot_host",
        description=f"one robot process of a federated experiment (its token in ${TOKEN_ENV})",
    )
    parser.add_argument("--config", type=Path, required=True, help="node config (JSON)")
    args = parser.parse_args(argv)
    tokens = pop_env_tokens()
    try:
        data = json.loads(args.config.read_text(encoding="utf-8"))
        if tokens and isinstance(data, dict):
            data["token"] = tokens[0]
        config = RobotConfig.from_dict(data)
    except (OSError, ValueError, TypeError) as exc:
        print(f"robot process: bad config {args.config}: {exc}", file=sys.stderr)
        return 2
    proc = RobotProcess(config, probes=probes)
    try:
        proc.start()
        return proc.run()
    except KeyboardInterrupt:
        return 130
    finally:
        proc.close()
