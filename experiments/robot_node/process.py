"""The robot node's life cycle and control loop (:class:`RobotProcess`) and its entry point."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.config import Mode, NodeConfig, boundaries
from dfrl.experiments.robot_node.files import METRIC_FIELDS, SHARE_FIELDS, CsvLog
from dfrl.experiments.robot_node.lines import ProtocolLines, StdinWatch
from dfrl.experiments.robot_node.table import NodeTable

__all__ = ["RobotProcess", "main"]


class RobotProcess:
    """One robot node (see :mod:`dfrl.experiments.robot_node`).

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
        self.lines = ProtocolLines(stdout, config.robot, config.events)
        self.stdin = StdinWatch(stdin)
        self.out_dir = Path(config.out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.trainer: Any = None
        self.table: NodeTable | None = None
        self.node: Any = None
        self.period = 0.0
        self._metrics: CsvLog | None = None
        self._shares: CsvLog | None = None

    @property
    def iteration(self) -> int:
        """Iterations done so far."""
        return self.table.iteration if self.table is not None else 0

    @property
    def shares(self) -> int:
        """Shares applied so far."""
        return self.table.shares if self.table is not None else 0

    # -- life cycle ----------------------------------------------------------------------------
    def start(self) -> tuple[str, int]:
        """Build the robot (or the benchmark's static table), start the platform node,
        register the table with its shape; return the address."""
        from dfrl.platform_pl import AGENTS_DIR
        from dfrl.pybridge import RobotNode, StaticTable

        c = self.config
        if c.bench_table is not None:
            shape = (int(c.bench_table[0]), int(c.bench_table[1]))
            base: Any = StaticTable(shape, c.seed)
        else:
            from dfrl.robots.training import Trainer

            self.trainer = base = Trainer(c.trainer_config())
            shape = (self.trainer.n_states, len(self.trainer.action_names))
            if c.rtf:
                self.period = self.trainer.config.sim.control_dt / c.rtf
            self._metrics = CsvLog(self.out_dir / f"metrics_{c.robot}.csv", METRIC_FIELDS)
        self._shares = CsvLog(self.out_dir / f"shares_{c.robot}.csv", SHARE_FIELDS)
        self.table = NodeTable(base, c.robot, self._shares, self.lines)
        self.node = RobotNode()
        self.node.load_platform()
        agent_file = AGENTS_DIR / "dfrl_agent.pl"
        if agent_file.is_file():
            self.node.assert_file_to_tartarus(str(agent_file))
        else:
            print(f"robot_node {c.robot}: warning: {agent_file} not found", file=sys.stderr)
        name = self.node.start(c.host, 0, token=int(c.token), idle_timeout=5.0)
        host, port = self.node.address(name)
        self.node.register_robot(c.robot, self.table, shape=shape, algorithm=c.algo)
        self.lines.node(str(host), int(port))
        return str(host), int(port)

    def run(self) -> int:
        """The control loop; returns the exit code."""
        c = self.config
        if self.trainer is None:
            while not self.stdin.poll():
                self.node.serve_pending(timeout=0.05)
            return 0
        stops = set(boundaries(c.iterations, c.respite)) if c.mode is Mode.SYNC else set()
        next_tick = time.perf_counter()
        stopped = False
        robot = c.robot
        for _ in range(c.iterations):
            m = self.trainer.step()
            self.table.iteration = m.iteration
            self._metrics.row((robot, m.iteration, repr(m.q_sum), repr(m.cumulative_reward),
                               m.collisions))
            if c.progress_every and m.iteration % c.progress_every == 0:
                self.lines.progress(m.iteration)
            if m.iteration in stops:
                self._metrics.flush()
                if not self._wait_for_share():
                    stopped = True
                    break
            elif c.mode is Mode.ASYNC:
                self.node.serve_pending()
            if m.iteration % 50 == 0 and self.stdin.poll():
                stopped = True
                break
            if self.period:
                next_tick += self.period
                delay = next_tick - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                else:
                    next_tick = time.perf_counter()
        self._metrics.flush()
        self.trainer.save_table(self.out_dir / "tables" / robot)
        self.lines.progress(self.iteration)
        if not stopped:
            self._linger()
        self.lines.done(self.iteration, self.shares)
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
        except Exception as exc:  # noqa: BLE001 - a failing listing must not keep us alive
            print(f"robot_node {self.config.robot}: listing agents failed: {exc}", file=sys.stderr)
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
        for log in (self._metrics, self._shares):
            if log is not None:
                log.close()
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
