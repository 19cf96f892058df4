"""One robot node process of a federated experiment.

``python -m dfrl.experiments.robot_node --config NODE.json`` embeds SWI-Prolog (``pybridge``),
loads the platform and the dFRL agent program, starts a platform node on loopback, registers
its robot (a :class:`dfrl.robots.training.Trainer`) and prints one line::

    DFRL_NODE <robot> <host> <port>

Then it runs the control loop, one ``trainer.step()`` per iteration, and appends a row per
iteration to ``metrics_<robot>.csv`` in the results folder. Table requests of the visiting
agent are served according to the pacing mode (:class:`Mode`):

* ``async`` (default): ``serve_pending()`` once per step; robots never wait for the agent.
* ``sync``: at every respite boundary (iteration ``k * respite``, and the last iteration)
  the robot stops stepping and serves until one ``set_q_table`` has been applied; between
  boundaries it serves nothing, so the agent's reads block until the robot reaches the
  boundary. Same config and seed give the same curves.

Every applied ``set_q_table`` appends a row to ``shares_<robot>.csv``: the share index, the
iteration, the wall time and the sha256 of the table's float64 bytes right after the set.

Other lines on stdout, for the launcher's progress display::

    DFRL_PROGRESS <robot> <iteration>
    DFRL_EVENT <robot> get|set <iteration>
    DFRL_DONE <robot> <iterations> <shares>

The node stops early when stdin reaches end of file or reads a line ``stop`` (the launcher
closes it when the experiment ends); after the last iteration it keeps its platform up until
no agent is left on it (sync) or until stdin closes (async), at most ``grace_s`` seconds.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import select
import sys
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from dfrl.experiments.config import Mode, NodeConfig, boundaries

#: Wall-clock seconds of one control iteration at real-time factor 1 (the paper's 64 ms).
CONTROL_PERIOD_S: float = 0.064

METRIC_FIELDS: tuple[str, ...] = ("robot", "iteration", "q_sum", "cumulative_reward", "collisions")
SHARE_FIELDS: tuple[str, ...] = ("robot", "share_index", "iteration", "wall_time", "digest")


def table_digest(table: np.ndarray) -> str:
    """sha256 (hex) of a table's float64 bytes in row-major order."""
    arr = np.ascontiguousarray(table, dtype=np.float64)
    return hashlib.sha256(arr.tobytes()).hexdigest()


class _StdinWatch:
    """Non-blocking check whether the launcher closed our stdin (or asked us to stop)."""

    def __init__(self, stream: TextIO | None) -> None:
        self.fd = stream.fileno() if stream is not None and not stream.closed else None
        self.closed = self.fd is None
        self._buf = b""

    def poll(self) -> bool:
        """True once stdin reached EOF or a ``stop`` line arrived."""
        if self.closed:
            return True
        try:
            ready, _, _ = select.select([self.fd], [], [], 0)
        except (OSError, ValueError):
            self.closed = True
            return True
        if ready:
            data = os.read(self.fd, 4096)
            if not data:
                self.closed = True
            else:
                self._buf += data
                if b"stop" in self._buf:
                    self.closed = True
        return self.closed


class _SharedTable:
    """The provider registered with the bridge: the trainer's table, with share bookkeeping."""

    def __init__(self, node: "RobotProcess") -> None:
        self._p = node
        self.quiet = True

    @property
    def q_table(self) -> np.ndarray:
        if not self.quiet:
            self._p.on_get()
        return self._p.table()

    @property
    def visits(self) -> np.ndarray:
        return self._p.visits()

    def set_q_table(self, table: np.ndarray) -> None:
        self._p.apply_share(table)


class _StaticTable:
    """A table without a robot (benchmarks)."""

    def __init__(self, shape: tuple[int, int], seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.q = rng.standard_normal(shape)
        self.v = rng.integers(0, 100, shape, dtype=np.int64)

    def set_q_table(self, table: np.ndarray) -> None:
        self.q = np.array(table, dtype=np.float64)


class RobotProcess:
    """The control loop of one robot node (see the module docstring).

    Parameters
    ----------
    config : NodeConfig
    stdout : TextIO
        Where the protocol lines go.
    stdin : TextIO or None
        Watched for EOF / ``stop``.
    """

    def __init__(self, config: NodeConfig, stdout: TextIO = sys.stdout,
                 stdin: TextIO | None = sys.stdin) -> None:
        self.config = config
        self.out = stdout
        self.stdin = _StdinWatch(stdin)
        self.out_dir = Path(config.out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.trainer = None
        self.static: _StaticTable | None = None
        self.node = None
        self.iteration = 0
        self.shares = 0
        self._metrics_fh = None
        self._metrics: Any = None
        self._shares_fh = None
        self._shares: Any = None

    # -- provider callbacks ------------------------------------------------------------------
    def table(self) -> np.ndarray:
        return self.static.q if self.static is not None else self.trainer.q_table

    def visits(self) -> np.ndarray:
        return self.static.v if self.static is not None else self.trainer.visits

    def on_get(self) -> None:
        self._event("get")

    def apply_share(self, table: np.ndarray) -> None:
        if self.static is not None:
            self.static.set_q_table(table)
        else:
            self.trainer.set_q_table(table)
        self.shares += 1
        if self._shares is not None:
            self._shares.writerow([self.config.robot, self.shares, self.iteration,
                                   repr(time.time()), table_digest(self.table())])
            self._shares_fh.flush()
        self._event("set")

    def _event(self, what: str) -> None:
        if self.config.events:
            self._say(f"DFRL_EVENT {self.config.robot} {what} {self.iteration}")

    def _say(self, line: str) -> None:
        self.out.write(line + "\n")
        self.out.flush()

    # -- life cycle ----------------------------------------------------------------------------
    def start(self) -> tuple[str, int]:
        """Build the robot, start the platform node, register the robot; return the address."""
        from dfrl.platform_pl import AGENTS_DIR
        from dfrl.pybridge import RobotNode

        c = self.config
        if c.bench_table is not None:
            s, a = c.bench_table
            self.static = _StaticTable((int(s), int(a)), c.seed)
        else:
            from dfrl.robots.training import Trainer

            self.trainer = Trainer(c.trainer_config())
        self.node = RobotNode()
        self.node.load_platform()
        agent_file = AGENTS_DIR / "dfrl_agent.pl"
        if agent_file.is_file():
            self.node.assert_file_to_tartarus(str(agent_file))
        else:
            print(f"robot_node {c.robot}: warning: {agent_file} not found", file=sys.stderr)
        name = self.node.start(c.host, 0, token=int(c.token), idle_timeout=5.0)
        host, port = self.node.address(name)
        provider = _SharedTable(self)
        self.node.register_robot(c.robot, provider, algorithm=c.algo)
        provider.quiet = False
        if self.static is None:
            self._metrics_fh = open(self.out_dir / f"metrics_{c.robot}.csv", "w", newline="",
                                    encoding="utf-8")
            self._metrics = csv.writer(self._metrics_fh)
            self._metrics.writerow(METRIC_FIELDS)
        self._shares_fh = open(self.out_dir / f"shares_{c.robot}.csv", "w", newline="",
                               encoding="utf-8")
        self._shares = csv.writer(self._shares_fh)
        self._shares.writerow(SHARE_FIELDS)
        self._shares_fh.flush()
        self._say(f"DFRL_NODE {c.robot} {host} {port}")
        return str(host), int(port)

    def run(self) -> int:
        """The control loop; returns the exit code."""
        c = self.config
        if self.static is not None:
            while not self.stdin.poll():
                self.node.serve_pending(timeout=0.05)
            return 0
        stops = set(boundaries(c.iterations, c.respite)) if c.mode is Mode.SYNC else set()
        period = CONTROL_PERIOD_S / c.rtf if c.rtf else 0.0
        next_tick = time.perf_counter()
        stopped = False
        robot = c.robot
        for _ in range(c.iterations):
            m = self.trainer.step()
            self.iteration = m.iteration
            self._metrics.writerow((robot, m.iteration, repr(m.q_sum), repr(m.cumulative_reward),
                                    m.collisions))
            if c.progress_every and m.iteration % c.progress_every == 0:
                self._say(f"DFRL_PROGRESS {robot} {m.iteration}")
            if m.iteration in stops:
                self._metrics_fh.flush()
                if not self._wait_for_share():
                    stopped = True
                    break
            elif c.mode is Mode.ASYNC:
                self.node.serve_pending()
            if m.iteration % 50 == 0 and self.stdin.poll():
                stopped = True
                break
            if period:
                next_tick += period
                delay = next_tick - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                else:
                    next_tick = time.perf_counter()
        self._metrics_fh.flush()
        if self.static is None:
            self.trainer.save_table(self.out_dir / "tables" / robot)
        self._say(f"DFRL_PROGRESS {robot} {self.iteration}")
        if not stopped:
            self._linger()
        self._say(f"DFRL_DONE {robot} {self.iteration} {self.shares}")
        return 0

    def _wait_for_share(self) -> bool:
        """Serve until one set_q_table has been applied; False if told to stop."""
        before = self.shares
        deadline = time.monotonic() + self.config.sync_timeout_s
        while self.shares == before:
            # one request at a time: the agent's read for the next round may already be
            # queued right behind this round's write, and must wait for the next boundary
            self.node.serve_pending(max_requests=1, timeout=0.05)
            if self.shares != before:
                break
            if self.stdin.poll():
                return False
            if time.monotonic() > deadline:
                print(f"robot_node {self.config.robot}: no share within "
                      f"{self.config.sync_timeout_s} s at iteration {self.iteration}; going on",
                      file=sys.stderr)
                break
        return True

    def _agents_here(self) -> bool:
        try:
            return bool(self.node.list_agents())
        except Exception:  # noqa: BLE001 - a failing listing must not keep us alive
            return False

    def _linger(self) -> None:
        """After the last iteration: serve until the agent left (sync) or stdin closes."""
        deadline = time.monotonic() + self.config.grace_s
        sync = self.config.mode is Mode.SYNC
        while time.monotonic() < deadline:
            self.node.serve_pending(timeout=0.05)
            if self.stdin.poll():
                break
            if sync and not self._agents_here():
                break

    def close(self) -> None:
        """Close files, the platform and the simulation."""
        for fh in (self._metrics_fh, self._shares_fh):
            if fh is not None and not fh.closed:
                fh.close()
        if self.node is not None:
            self.node.close()
        if self.trainer is not None:
            self.trainer.close()


def main(argv: list[str] | None = None) -> int:
    """Entry point: ``python -m dfrl.experiments.robot_node --config NODE.json``."""
    parser = argparse.ArgumentParser(prog="python -m dfrl.experiments.robot_node",
                                     description="one robot node of a federated experiment")
    parser.add_argument("--config", type=Path, required=True, help="node config (JSON)")
    args = parser.parse_args(argv)
    try:
        config = NodeConfig.from_dict(json.loads(args.config.read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError) as exc:
        print(f"robot_node: bad config {args.config}: {exc}", file=sys.stderr)
        return 2
    proc = RobotProcess(config)
    try:
        proc.start()
        return proc.run()
    except KeyboardInterrupt:
        return 130
    finally:
        proc.close()


if __name__ == "__main__":
    sys.exit(main())
