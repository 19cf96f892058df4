"""The robots of a running experiment and how they fare: crashes, losses, stalls, their
progress for the live view, stopping them and gathering their files.

:class:`RobotRoster` owns that state; it reaches each robot only through the
:class:`~.robots.Robot` interface. Threading: the launcher's thread calls every method; other
threads (a test, a bench sampling memory) may call :meth:`RobotRoster.robots` and
:meth:`RobotRoster.iterations`. Every field is guarded by the roster's lock, which is never
held while a robot is asked anything (a robot may answer over the network).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from dfrl.experiments.driver.launcher.remote_robots import LOST_AFTER_S
from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robots import Robot, RobotStatus
from dfrl.experiments.errors import ExperimentError

#: Seconds without progress after which a running robot counts as stalled.
STALL_S = 15.0
#: Seconds all robots together get to end once told to stop.
SHUTDOWN_S = 15.0
#: Seconds the roster holds back calling robot hosts lost when it reaches none of them (the
#: config's ``partition_wait_s`` when the launcher makes the roster).
PARTITION_WAIT_S = 120.0


class RobotRoster:
    """The robots of one run (see the module doc).

    Parameters
    ----------
    out : Path
        The results folder.
    reporter : Reporter
    partition_wait_s : float
        How long robots on robot hosts that all stopped answering together are held back
        from being lost (see :meth:`partitioned`).
    """

    def __init__(
        self, out: Path, reporter: Reporter, partition_wait_s: float = PARTITION_WAIT_S
    ) -> None:
        self._partition_wait_s = partition_wait_s
        self._cut_since: float | None = None  # when the driver's partition began
        self._cut_robots = 0  # robot hosts it cut the driver from
        self._cut_expired = False  # its wait ran out
        self._healed_at: float | None = None  # when the last partition healed
        self._held_now: set[str] = set()  # robots held back from being lost
        self._out = out
        self._say = reporter.say
        self._event = reporter.event
        self._elapsed = reporter.elapsed
        self._lock = threading.Lock()
        self._robots: dict[str, Robot] = {}  # in the order they were added
        self._joined: set[str] = set()  # robots that joined the running experiment
        self._killed: set[str] = set()  # robots the launcher itself stopped
        self._crashed: dict[str, int] = {}  # robot -> exit code of its process
        self._lost: dict[str, str] = {}  # robot -> why (crashed, failed, gone)
        self._stalls: list[str] = []
        self._progress_at: dict[str, tuple[int, float]] = {}  # robot -> iteration, since
        self._stalled: dict[str, float] = {}  # robot -> stalled since
        self._sample_errors: dict[str, str] = {}  # robot -> the last one shown in the view
        self._gathered: dict[str, list[str]] = {}
        self._gather_errors: list[str] = []
        self._failed_joins: dict[str, str] = {}  # robot -> why it could not join
        self._resumed: dict[str, tuple[int, ...]] = {}  # robot -> checkpoint iterations

    # -- the robots ---------------------------------------------------------------------------
    def add(self, robot: Robot, joined: bool = False) -> None:
        """A robot (started) is part of the run from now on; ``joined``: it joined later."""
        with self._lock:
            self._robots[robot.spec.id] = robot
            if joined:
                self._joined.add(robot.spec.id)

    def failed_join(self, rid: str, why: str) -> None:
        """``rid`` was to join but did not start: it is no part of the run (not lost, not
        crashed: a failed join)."""
        with self._lock:
            self._robots.pop(rid, None)
            self._joined.discard(rid)
            self._failed_joins[rid] = why

    def failed_joins(self) -> dict[str, str]:
        """Robots that were to join and did not start -> why."""
        with self._lock:
            return dict(self._failed_joins)

    def robots(self) -> dict[str, Robot]:
        """The robots by id, in the order they were added (a copy)."""
        with self._lock:
            return dict(self._robots)

    def has(self, rid: str) -> bool:
        with self._lock:
            return rid in self._robots

    def joined(self, rid: str) -> bool:
        """``rid`` joined the running experiment."""
        with self._lock:
            return rid in self._joined

    def statuses(self) -> dict[str, RobotStatus]:
        """Every robot's status now."""
        return {rid: robot.status() for rid, robot in self.robots().items()}

    def iterations(self, algo: str | None = None) -> dict[str, int]:
        """Iterations per robot (of those learning with ``algo``, or all)."""
        return {
            rid: robot.status().iteration
            for rid, robot in self.robots().items()
            if algo is None or robot.spec.algo == algo
        }

    def all_exited(self) -> bool:
        """Every robot ended (robots held back by a driver partition have not)."""
        return not self.partitioned() and all(not s.running for s in self.statuses().values())

    def robots_done(self) -> bool:
        """Every robot ended or ran all its iterations."""
        return not self.partitioned() and all(
            not s.running or s.iteration >= r.config.iterations
            for r, s in ((r, r.status()) for r in self.robots().values())
        )

    # -- the driver's own partition -----------------------------------------------------------
    def partitioned(self) -> bool:
        """The driver takes itself to be cut off the network, or has just healed and some of
        its robot hosts were not asked again yet (see :meth:`check`): robots held back from
        being lost count as running."""
        with self._lock:
            return bool(self._held_now)

    def _held(self, statuses: dict[str, RobotStatus], now: float) -> set[str]:
        """Robots whose silence may be the driver's own partition (they are not called lost).

        A robot on a robot host (at least two of them in the run) is held while it is silent
        and no robot answered since it went silent: the driver reaches none of them. When
        every one of them is silent the driver says it is partitioned; when one answers again,
        that the partition healed, and the others silent since before are held until they are
        asked again (:data:`~.remote_robots.LOST_AFTER_S`). Nothing is held once the partition,
        or the robot's silence, lasted ``partition_wait_s``."""
        with self._lock:
            killed = set(self._killed)
        remote = {
            rid: s for rid, s in statuses.items() if s.answered_at is not None and rid not in killed
        }
        if len(remote) < 2:
            return set()
        silent = {rid: s.silent_since for rid, s in remote.items() if s.silent_since is not None}
        last = max(s.answered_at for s in remote.values() if s.answered_at is not None)
        held = {
            rid
            for rid, since in silent.items()
            if since is not None and last <= since and now - since <= self._partition_wait_s
        }
        with self._lock:
            began, healed = self._cut_since, self._healed_at
        if began is None and silent and len(silent) == len(remote):
            began = min(v for v in silent.values() if v is not None)
            with self._lock:
                self._cut_since, self._cut_robots = began, len(remote)
            self._say(
                f"DRIVER PARTITIONED: none of the {len(remote)} robot hosts answers "
                f"(silent {now - began:.0f} s); waiting up to "
                f"{self._partition_wait_s:.0f} s before calling them lost"
            )
            self._event(
                {"kind": "driver_partition", "state": "partitioned", "robots": sorted(remote)}
            )
        elif began is not None and len(silent) < len(remote):
            with self._lock:
                self._cut_since, self._healed_at, count = None, now, self._cut_robots
                expired, self._cut_expired = self._cut_expired, False
                if not expired:
                    self._stalls.append(
                        f"driver partitioned from all {count} robot hosts "
                        f"from {self._elapsed(began):.1f} s to "
                        f"{self._elapsed(now):.1f} s (waited; not counted "
                        "as lost)"
                    )
            self._say(
                f"driver partition healed: robot hosts answer again after {now - began:.0f} s"
            )
            self._event(
                {"kind": "driver_partition", "state": "healed", "seconds": round(now - began, 1)}
            )
            began, healed = None, now
        if healed is not None and now - healed < LOST_AFTER_S:
            held |= {rid for rid, since in silent.items() if since is not None and since < healed}
        if began is not None and now - began > self._partition_wait_s:
            with self._lock:
                expired, self._cut_expired = not self._cut_expired, True
                if expired:
                    self._stalls.append(
                        f"driver partitioned from all {self._cut_robots} "
                        f"robot hosts from {self._elapsed(began):.1f} s; "
                        f"after {self._partition_wait_s:.0f} s "
                        "(partition_wait_s) they count as lost"
                    )
            if expired:
                self._say(
                    f"driver partitioned for {now - began:.0f} s: the robot hosts that "
                    "do not answer count as lost from now on"
                )
            return set()
        return held

    # -- how they fare ------------------------------------------------------------------------
    def check(self) -> None:
        """Record (and say) every robot process that died with a non-zero exit code, every
        robot that failed or stopped answering (and came back), and stalls."""
        now = time.monotonic()
        robots = self.robots()
        statuses = {rid: robot.status() for rid, robot in robots.items()}
        held = self._held(statuses, now)
        with self._lock:
            self._held_now = held
        for rid, robot in robots.items():
            status = statuses[rid]
            if rid not in held:
                self._check_health(rid, robot, status)
            self._check_progress(rid, robot, status, now)

    def _check_health(self, rid: str, robot: Robot, status: RobotStatus) -> None:
        why, code = status.lost, status.exit_code
        with self._lock:
            resumed = status.resumed[len(self._resumed.get(rid, ())) :]
            if resumed:
                self._resumed[rid] = status.resumed
        for it in resumed:
            self._say(
                f"robot {rid}: its robot host was restarted; resumed from its checkpoint "
                f"at iteration {it}"
            )
            self._event({"kind": "robot_state", "robot": rid, "state": "learning"})
        with self._lock:
            new = why is not None and rid not in self._lost and rid not in self._killed
            back = why is None and rid in self._lost
            if new and why is not None:  # new: lost just now (why is not None)
                self._lost[rid] = why
                if code is not None:
                    self._crashed[rid] = code
            elif back:
                del self._lost[rid]
        if new and code is not None:
            self._event(
                {
                    "kind": "robot_state",
                    "robot": rid,
                    "state": "dead",
                    "reason": f"exit code {code}",
                }
            )
            self._say(
                f"ROBOT {rid} CRASHED (exit code {code}) at iteration "
                f"{status.iteration}; see {self._out / 'logs' / f'{rid}.err'}\n"
                f"{robot.log_tail()}"
            )
        elif new:
            self._say(f"ROBOT {rid} LOST at iteration {status.iteration}: {why}")
            self._event({"kind": "robot_state", "robot": rid, "state": "dead", "reason": why})
        elif back:
            self._say(f"robot {rid} answers again (iteration {status.iteration})")
            self._event({"kind": "robot_state", "robot": rid, "state": "learning"})

    def _check_progress(self, rid: str, robot: Robot, status: RobotStatus, now: float) -> None:
        """A running robot whose iteration has not moved for :data:`STALL_S` is stalled; the
        stall is recorded when it moves again (or at the end, :meth:`end_stalls`)."""
        said = None
        with self._lock:
            it, since = self._progress_at.get(rid, (-1, now))
            if status.iteration != it:
                if rid in self._stalled:
                    self._stall(rid, self._stalled.pop(rid), now, it)
                self._progress_at[rid] = (status.iteration, now)
            elif (
                status.running
                and not status.done
                and it < robot.config.iterations
                and now - since > STALL_S
                and rid not in self._stalled
            ):
                self._stalled[rid] = since
                said = f"robot {rid} stalled at iteration {it} for {now - since:.0f} s"
        if said:
            self._say(said)

    def _stall(self, rid: str, since: float, until: float, it: int) -> None:
        """Record a stall (caller holds the lock)."""
        self._stalls.append(
            f"{rid} made no progress at iteration {it} from "
            f"{self._elapsed(since):.1f} s to {self._elapsed(until):.1f} s"
        )

    def end_stalls(self) -> None:
        """Record the stalls still going on (the run is ending)."""
        now = time.monotonic()
        with self._lock:
            for rid, since in self._stalled.items():
                self._stall(rid, since, now, self._progress_at.get(rid, (-1, now))[0])
            self._stalled.clear()

    def show_progress(self) -> None:
        """What each robot reported since the last look, as events of the live view: every
        evaluation (``eval``), its newest sample as a ``pose`` and, for a robot on another host
        (its metrics file comes at the end), also as a ``progress`` event (iteration, sum of
        Q-values, cumulative reward, shares); a robot whose lines cannot be read, as an
        ``error`` once per reason. Spells in which a robot did not answer are recorded."""
        taken = [(rid, robot, robot.take_progress()) for rid, robot in self.robots().items()]
        for rid, robot, p in taken:
            for e in p.evals:
                self._event(
                    {
                        "kind": "eval",
                        "robot": rid,
                        "iteration": e.iteration,
                        "progress": e.progress,
                        "collisions_per_1000": e.collisions_per_1000,
                        "coverage": e.coverage,
                    }
                )
            s = p.sample
            if s is None:
                continue
            self._event(
                {
                    "kind": "pose",
                    "robot": rid,
                    "iteration": s.iteration,
                    "x": s.x,
                    "y": s.y,
                    "yaw": s.yaw,
                }
            )
            if robot.spec.robot_host is not None:
                self._event(
                    {
                        "kind": "progress",
                        "robot": rid,
                        "iteration": s.iteration,
                        "q_sum": s.q_sum,
                        "cumulative_reward": s.cumulative_reward,
                        "shares": robot.status().shares,
                    }
                )
        for rid, _, p in taken:
            with self._lock:
                for t0, t1, reason in p.outages:
                    self._stalls.append(
                        f"{rid} unreachable from {self._elapsed(t0):.1f} s to "
                        f"{self._elapsed(t1):.1f} s ({reason[:120]})"
                    )
                new = p.error is not None and self._sample_errors.get(rid) != p.error
                if new and p.error is not None:
                    self._sample_errors[rid] = p.error
            if new and p.error is not None:
                self._event(
                    {"kind": "error", "text": f"no live samples from {rid}: {p.error[:200]}"}
                )

    # -- the end ------------------------------------------------------------------------------
    def kill_all(self) -> None:
        """Stop every robot now (on an exception or a signal)."""
        for rid, robot in self.robots().items():
            if robot.status().running:
                with self._lock:
                    self._killed.add(rid)
            robot.stop(0.0)

    def shutdown(self) -> None:
        """Tell every robot to stop, give them :data:`SHUTDOWN_S` together, stop the ones
        left; then record what ended badly (:meth:`check`)."""
        robots = self.robots()
        for robot in robots.values():
            robot.request_stop()
        deadline = time.monotonic() + SHUTDOWN_S
        for rid, robot in robots.items():
            if robot.status().running and not robot.stop(deadline - time.monotonic()):
                self._say(f"robot {rid} did not exit; killing it")
                with self._lock:
                    self._killed.add(rid)
        self.check()

    def gather(self, out: Path) -> None:
        """Bring every robot's result files into ``out`` (a robot that cannot give them is a
        fault, said and recorded)."""
        for rid, robot in self.robots().items():
            try:
                names = robot.gather(out)
            except ExperimentError as exc:
                self._say(f"files of {rid} not gathered: {exc}")
                with self._lock:
                    if rid in self._lost:  # already counted: say it with the loss
                        self._lost[rid] += "; its result files could not be fetched"
                    else:  # answered till the end, then failed to give them
                        self._gather_errors.append(f"files of {rid} not gathered: {exc}")
                continue
            if names:
                with self._lock:
                    self._gathered[rid] = names

    # -- what the results say ----------------------------------------------------------------
    def crashed(self) -> dict[str, int]:
        with self._lock:
            return dict(self._crashed)

    def lost(self) -> dict[str, str]:
        with self._lock:
            return dict(self._lost)

    def finished(self) -> list[str]:
        """Robots that said they ran all their iterations."""
        return [rid for rid, robot in self.robots().items() if robot.status().done]

    def resumed(self) -> dict[str, list[int]]:
        """robot -> the checkpoint iterations it was resumed at after its host restarted."""
        with self._lock:
            return {rid: list(its) for rid, its in self._resumed.items()}

    def stalls(self) -> list[str]:
        with self._lock:
            return list(self._stalls)

    def gathered(self) -> dict[str, list[str]]:
        with self._lock:
            return {rid: list(names) for rid, names in self._gathered.items()}

    def gather_errors(self) -> list[str]:
        with self._lock:
            return list(self._gather_errors)
