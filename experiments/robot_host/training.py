"""One experiment of one robot (:class:`Training`): trainer, result files, checkpoints, the control
loop advanced one iteration at a time.

Both robot processes use it: the spawned node (:mod:`.process`, one run per process) and the
robot service (:mod:`.service`, runs one after another). What a process does besides running
(watching its stdin, answering ``dfrl_robot`` requests) comes in through a :class:`TrainingHost`,
called between iterations, while a sync robot waits for a share and while real-time pacing
waits.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from dfrl.experiments.robot_host.config import Mode, RobotConfig, boundaries
from dfrl.experiments.robot_host.checkpoint import (
    checkpoint_of,
    load_checkpoint,
    restore_trainer,
    save_checkpoint,
    save_learnt_atomically,
)
from dfrl.experiments.robot_host.evaluate import LiveEvaluator
from dfrl.experiments.robot_host.files import METRIC_FIELDS, SHARE_FIELDS, CsvLog
from dfrl.experiments.robot_host.lines import ProtocolLines
from dfrl.experiments.robot_host.share_notes import ShareNotes
from dfrl.experiments.robot_host.static_robot import StaticRobot, static_robot
from dfrl.experiments.robot_host.table import SharedLearner, SharedTable, shared_provider

__all__ = ["Training", "TrainingHost", "SleepHost", "SAMPLE_S"]

#: Wall seconds between two ``DFRL_SAMPLE`` lines at least (written with progress lines).
SAMPLE_S = 0.5


class TrainingHost(Protocol):
    """What the process does while its run waits."""

    def wait(self, seconds: float) -> None:
        """Spend at most ``seconds`` (0: a quick look) on the process's own work."""

    def should_stop(self) -> bool:
        """True once the run must end early."""


class SleepHost:
    """A host with nothing else to do (sleeps; never stops a run)."""

    def wait(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def should_stop(self) -> bool:
        return False


class Training:
    """One robot's experiment in a robot process with an open :class:`dfrl.pybridge.Bridge`.

    Parameters
    ----------
    config : RobotConfig
        Its ``out_dir`` is the experiment's folder.
    bridge : Bridge
        The process's bridge; :meth:`register` registers the robot with it.
    lines : ProtocolLines
    host : TrainingHost
    resume : bool
        Start from ``out_dir/checkpoint/<robot>.npy`` (metrics rows after its iteration and
        shares rows after its share count are dropped from the files).
    poll_every : int
        Iterations between two ``host.should_stop()`` checks.
    warn : callable
        Where warnings go (default: stderr).
    static_source : callable
        The seam :meth:`open` takes a static robot from: given the config, the static robot
        it asks for, or None for a learning robot (default:
        :func:`~dfrl.experiments.robot_host.static_robot.static_robot`, which reads the keys
        a benchmark sets).

    Attributes
    ----------
    stopped : bool
        The run ended before its last iteration (told to stop).
    finished : bool
        :meth:`finish` ran.
    """

    def __init__(
        self,
        config: RobotConfig,
        bridge: Any,
        lines: ProtocolLines,
        *,
        host: TrainingHost | None = None,
        resume: bool = False,
        poll_every: int = 1,
        warn: Callable[[str], None] | None = None,
        static_source: Callable[[RobotConfig], StaticRobot | None] = static_robot,
    ) -> None:
        self.config = config
        self.bridge = bridge
        self.lines = lines
        self.host: TrainingHost = host or SleepHost()
        self.resume = resume
        self.poll_every = max(1, int(poll_every))
        self.warn = warn or (lambda text: print(text, file=sys.stderr, flush=True))
        self.static_source = static_source
        self.out_dir = Path(config.out_dir)
        self.checkpoint_dir = self.out_dir / "checkpoint"
        self.trainer: Any = None
        self.table: SharedTable | None = None
        self.period = 0.0
        self.stopped = False
        self.finished = False
        self._stops: set[int] = set()
        self._next_tick = 0.0
        self._metrics: CsvLog | None = None
        self._shares: CsvLog | None = None
        self._evals: LiveEvaluator | None = None
        self._notes: ShareNotes | None = None
        self._registered = False
        self._static: StaticRobot | None = None
        self.shape: tuple[int, int] | None = None
        self._sampled_at = -SAMPLE_S

    # -- state ---------------------------------------------------------------------------------
    @property
    def iteration(self) -> int:
        """Iterations done so far."""
        return self.table.iteration if self.table is not None else 0

    @property
    def shares(self) -> int:
        """Shares applied so far."""
        return self.table.shares if self.table is not None else 0

    @property
    def simulated(self) -> bool:
        """False for a static robot (no trainer; :mod:`.static_robot`)."""
        return self.trainer is not None

    @property
    def function(self) -> bool:
        """The robot learns with a function learner (``linear``, ``dqn``): parameters, no
        Q-table."""
        return self.trainer is not None and self.trainer.learner_kind == "function"

    @property
    def done(self) -> bool:
        """No iteration left (or stopped)."""
        return self.stopped or self.trainer is None or self.iteration >= self.config.iterations

    # -- life cycle ----------------------------------------------------------------------------
    def open(self) -> tuple[int, int] | None:
        """Build the robot (a learning robot, or the static robot its config asks for), open
        its files and wrap what it serves in a :class:`SharedTable`; return the table's shape
        (None: parameters only, no table). Agents reach it once :meth:`register` offered it.

        Raises
        ------
        FileNotFoundError
            ``resume`` without a checkpoint.
        ValueError
            A checkpoint that does not fit this robot.
        """
        c = self.config
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._static = self.static_source(c)
        if self._static is not None:
            base: Any = self._static.base
            shape, shares = self._static.shape, 0
            self._shares = shares_log = CsvLog(self.out_dir / f"shares_{c.robot}.csv", SHARE_FIELDS)
        else:
            base, shape, shares, shares_log = self._open_trainer()
        on_share = self.on_share if self.trainer is not None else None
        # distillation residuals and FedAvg weights (a learning robot's, not a static one's)
        self._notes = ShareNotes(self.out_dir, c.robot) if self.trainer is not None else None
        self.table = shared_provider(
            base, c.robot, shares_log, self.lines, on_share, shares, self._notes
        )
        if self.trainer is not None:
            self.table.iteration = self.trainer.iteration
        self.shape = shape
        self._next_tick = time.perf_counter()
        return shape

    def _open_trainer(self) -> tuple[Any, tuple[int, int], int, CsvLog]:
        """Build the learning robot (from its checkpoint when resuming) and open its files;
        return the base it serves (a function learner: the grid view of its Q-function too,
        ``robots/grid_view.py``), the table's shape, the shares applied before and the shares
        file."""
        from dfrl.robots.training import Trainer

        c = self.config
        cp = load_checkpoint(self.checkpoint_dir, c.robot) if self.resume else None
        self.trainer = Trainer(c.trainer_config())
        base: Any = self.trainer
        shape = (self.trainer.n_states, len(self.trainer.action_names))
        shares = 0
        if cp is not None:
            restore_trainer(self.trainer, cp)
            shares = cp.shares
        if c.rtf:
            self.period = self.trainer.config.sim.control_dt / c.rtf
        upto, upto_share = self.trainer.iteration, shares
        keep_m = (lambda r: int(r["iteration"]) <= upto) if cp is not None else None
        keep_s = (lambda r: int(r["share_index"]) <= upto_share) if cp is not None else None
        self._metrics = CsvLog(self.out_dir / f"metrics_{c.robot}.csv", METRIC_FIELDS, keep_m)
        self._shares = shares_log = CsvLog(
            self.out_dir / f"shares_{c.robot}.csv", SHARE_FIELDS, keep_s
        )
        self._stops = set(boundaries(c.iterations, c.respite)) if c.mode is Mode.SYNC else set()
        if c.eval_every:
            self._evals = LiveEvaluator(
                self.trainer.config,
                c.robot,
                c.seed,
                c.eval_every,
                c.eval_steps,
                self.out_dir,
                self.lines,
                upto if cp is not None else None,
            )
        if self.function:
            from dfrl.robots.grid_view import GridView

            base = GridView(self.trainer)
        return base, shape, shares, shares_log

    def register(self) -> None:
        """Offer the robot to agents: register what :meth:`open` built with the bridge (its
        Q-table, of a function learner the grid view of its Q-function, for an agent of a grid
        federation; and its parameters, if its base has them); once, after :meth:`open`.
        :meth:`close` unregisters it."""
        if self.table is None:
            raise RuntimeError(f"robot {self.config.robot}: Training.open() first")
        self.bridge.register_robot(
            self.config.robot, self.table, shape=self.shape, algo=self.config.algo
        )
        self._registered = True

    def _opened(self) -> tuple[SharedTable, CsvLog]:
        """The table and the metrics file of a learning robot, made by :meth:`open`."""
        if self.table is None or self._metrics is None:
            raise RuntimeError(f"robot {self.config.robot}: Training.open() first")
        return self.table, self._metrics

    def begin(self) -> None:
        """Restart the pacing clock (call when the first iteration is about to run)."""
        self._next_tick = time.perf_counter()

    def flush(self) -> None:
        """Flush the CSV files."""
        for log in (self._metrics, self._shares):
            if log is not None:
                log.flush()

    def step(self) -> bool:
        """One iteration: step, record, serve (async) or wait for a share (sync boundary),
        evaluate the greedy policy when due, pace; True while iterations are left."""
        if self.done:
            return False
        c = self.config
        m = self.trainer.step()
        it = m.iteration
        table, metrics = self._opened()
        table.iteration = it
        metrics.row((c.robot, it, repr(m.q_sum), repr(m.cumulative_reward), m.collisions))
        if c.progress_every and it % c.progress_every == 0:
            self.lines.progress(it)
            if time.monotonic() - self._sampled_at >= SAMPLE_S:
                self.sample(m.q_sum, m.cumulative_reward)
        if it in self._stops:
            metrics.flush()
            if not self._wait_for_share():
                self.stopped = True
        elif c.mode is Mode.ASYNC:
            self.bridge.serve_pending()
        if self._evals is not None and not self.stopped and self._evals.due(it):
            if self.function:  # after this boundary's share
                self._evals.evaluate(it, params=self.trainer.params)
            else:
                self._evals.evaluate(it, self.trainer.q_table)
        if not self.stopped and it % self.poll_every == 0:
            self.host.wait(0.0)
            if self.host.should_stop():
                self.stopped = True
        if self.done:
            return False
        if self.period:
            self._next_tick += self.period
            delay = self._next_tick - time.perf_counter()
            if delay > 0:
                self._pause(delay)
            else:
                self._next_tick = time.perf_counter()
        return True

    def sample(self, q_sum: float | None = None, cumulative_reward: float | None = None) -> None:
        """Write a ``DFRL_SAMPLE`` line now: the pose, the sum of Q-values (a function learner:
        the sum of its parameters, as its metrics' ``q_sum``) and the cumulative reward at this
        iteration."""
        if self.trainer is None:
            return
        self._sampled_at = time.monotonic()
        if q_sum is not None:
            q = q_sum
        else:
            q = float((self.trainer.params if self.function else self.trainer.q_table).sum())
        cr = self.trainer.cumulative_reward if cumulative_reward is None else cumulative_reward
        self.lines.sample(self.iteration, self.trainer.pose, q, cr)

    def _pause(self, seconds: float) -> None:
        until = time.perf_counter() + seconds
        while (left := until - time.perf_counter()) > 0:
            self.host.wait(left)

    def _wait_for_share(self) -> bool:
        """Serve until one set_q_table has been applied; False if told to stop."""
        before = self.shares
        deadline = time.monotonic() + self.config.sync_timeout_s
        while self.shares == before:
            # one request at a time: the agent's read for the next round may already be
            # queued right behind this round's write, and must wait for the next boundary
            self.bridge.serve_pending(max_requests=1, timeout=0.05)
            if self.shares != before:
                break
            self.host.wait(0.0)
            if self.host.should_stop():
                return False
            if time.monotonic() > deadline:
                self.warn(
                    f"robot {self.config.robot}: no share within "
                    f"{self.config.sync_timeout_s} s at iteration {self.iteration}; "
                    "going on"
                )
                break
        return True

    def on_share(self) -> None:
        """After an applied share: the table's history snapshot, then the checkpoint."""
        self.save_history()
        self.checkpoint()

    def save_history(self) -> None:
        """Write the table just shared as ``tables/history/<robot>_it<N>.npy`` (N: the
        robot's iteration), for the greedy evaluations a study runs afterwards; a function
        learner's parameter vector as ``params/history/<robot>_it<N>.npy``."""
        if self.trainer is None:
            return
        d = self.out_dir / ("params" if self.function else "tables") / "history"
        d.mkdir(parents=True, exist_ok=True)
        tmp = d / f".{self.config.robot}_it{self.iteration}.npy.tmp"
        with open(tmp, "wb") as fh:
            np.save(fh, self.trainer.params if self.function else self.trainer.q_table)
        os.replace(tmp, d / f"{self.config.robot}_it{self.iteration}.npy")

    def checkpoint(self) -> None:
        """Write the checkpoint now (atomically; see :mod:`.checkpoint`), after syncing the
        CSV files, so that they hold at least every row up to it."""
        if self.trainer is None:
            return
        for log in (self._metrics, self._shares, self._evals):
            if log is not None:
                log.sync()
        save_checkpoint(
            self.checkpoint_dir,
            self.config.robot,
            checkpoint_of(self.trainer, self.shares),
            meta={"iterations": self.config.iterations},
        )

    def finish(self) -> None:
        """After the last iteration (or a stop): flush the metrics, save the tables
        (``tables/<robot>.npy`` + ``.json`` + ``.visits.npy``; a function learner:
        ``params/<robot>.npy`` + ``.json``) and the checkpoint."""
        if self.finished or self.trainer is None:
            self.finished = True
            return
        self.finished = True
        table, metrics = self._opened()
        metrics.flush()
        self.save_tables()
        table.on_share = self.save_tables  # a late share updates the saved tables
        self.lines.progress(self.iteration)
        self.sample()

    def save_tables(self) -> None:
        """Save the table (or parameter) files and the checkpoint (also after a share that came
        late)."""
        if self.trainer is not None:
            save_learnt_atomically(self.trainer, self.out_dir, self.config.robot)
            self.checkpoint()

    def close(self) -> None:
        """Unregister the robot, close the files and the simulation (idempotent). A static
        robot's parameters are saved first, as ``params/<robot>.npy`` (what the agents left
        it)."""
        if self._static is not None and self._registered:
            self._static.save_held(
                self.out_dir,
                self.config.robot,
                self.table.params if isinstance(self.table, SharedLearner) else None,
            )
        if self._registered:
            self._registered = False
            try:
                self.bridge.unregister_robot(self.config.robot)
            except Exception as exc:  # noqa: BLE001 - a closing node must still close files
                self.warn(f"robot {self.config.robot}: unregistering failed: {exc}")
        for log in (self._metrics, self._shares, self._evals, self._notes):
            if log is not None:
                log.close()
        if self.trainer is not None:
            self.trainer.close()
            self.trainer = None
