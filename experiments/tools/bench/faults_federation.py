"""A small federation across simulated hosts, for the fault benchmark (``dfrl bench faults``).

:class:`Federation` starts, inside a :class:`~dfrl.experiments.tools.netns.Lab`, one
``dfrl robot`` service per robot host (the command of experiments/README.md "Running across
machines", each in its own folder with the token file) and the driver (``dfrl run CONFIG
--token-file dfrl.token --out out``) in a namespace of its own. It offers the faults a case
needs (kill -9 a host, start it again, cut its link) and what a case waits on (the rounds the
driver has logged, the shares a robot host has written). Every wait is bounded; the lab kills
every process and removes every namespace when it closes.

No shared disk: the lab gives each host a private tmpfs over the run's folder ``work``
(:class:`~dfrl.experiments.tools.netns.Lab` ``private``), so that host ``hI`` sees only
``work/hI`` and the driver only ``work/driver``; this process reads and writes a host's
files through :meth:`Federation.view` (the host's mount namespace, never a shared folder) and
copies every host's folder out at the end (:meth:`Federation.copy_out`) for the judging.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from dfrl.experiments.driver.launcher.spawn import TREE_ROUNDS_PER_S
from dfrl.experiments.driver.results.agent_log import RoundRecord, read_rounds_log
from dfrl.experiments.tokens import new_secret, write_secret_file
from dfrl.experiments.tools.netns import Lab

AGENT = "fed_qlearning"
ARENAS = ("r1", "r4", "r2", "r3", "r5")
PORT = 7001
LISTENING = "dfrl robot listening on"
LINK_LISTENING = "delay_link listening on"


class FaultBenchError(RuntimeError):
    """The benchmark could not do what a case asked (a host did not start, a wait ran out)."""


@dataclass(frozen=True)
class Plan:
    """The experiment a fault is tried on: ``hosts`` robot hosts, sync rounds every
    ``respite`` of ``iterations`` iterations at ``rtf`` x real time."""

    hosts: int = 4
    iterations: int = 1200
    respite: int = 100
    rtf: float = 4.0
    seed: int = 1
    timeout_s: float = 240.0
    #: the agent's itinerary: ``chain`` or ``tree`` (fan-out ``fanout``)
    itinerary: str = "chain"
    fanout: int = 2
    #: milliseconds every chunk into a robot host is held, each way (0: none; see delay_link)
    delay_ms: float = 0.0

    @property
    def rounds(self) -> int:
        return -(-self.iterations // self.respite)


def dfrl_argv(*words: str) -> list[str]:
    """``dfrl WORDS...`` with this interpreter."""
    return [sys.executable, "-m", "dfrl", *words]


def wait_until(
    cond: Callable[[], object], timeout_s: float, what: str, poll_s: float = 0.05
) -> object:
    """``cond()``'s first true value within ``timeout_s`` seconds, else FaultBenchError."""
    deadline = time.monotonic() + timeout_s
    while True:
        got = cond()
        if got:
            return got
        if time.monotonic() >= deadline:
            raise FaultBenchError(f"timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(poll_s)


class Federation:
    """Robot hosts ``h1..hN`` (robot ``rI`` on ``hI``) and host ``driver`` in ``lab``; files
    under ``work``. ``actions`` records what was done and when (seconds since the driver
    started, ``t0``)."""

    def __init__(self, lab: Lab, work: Path, plan: Plan, name: str) -> None:
        self.lab, self.work, self.plan, self.name = lab, work, plan, name
        self.robots = [f"r{i}" for i in range(1, plan.hosts + 1)]
        self.token = new_secret()
        self.procs: dict[str, subprocess.Popen] = {}
        self.driver: subprocess.Popen | None = None
        self.t0 = time.time()
        self.actions: list[dict] = []
        self.out = work / "driver" / "out"

    # -- hosts -----------------------------------------------------------------------------
    @staticmethod
    def host_of(robot: str) -> str:
        return "h" + robot[1:]

    def view(self, host: str, path: Path) -> Path:
        """Where this process reads and writes host ``host``'s ``path`` (its own disk)."""
        return self.lab[host].view(path)

    def copy_out(self) -> list[str]:
        """Copy every host's folder (``work/<host>`` as that host sees it) to this process's
        ``work/<host>``, and what a host wrote elsewhere under ``work`` (a path of another
        host's, say the driver's ``out``) to ``work/<host>/_foreign/``; the hosts whose
        folder could not be read, with why."""
        problems = []
        for h in self.lab.hosts:
            for src, dst in [(self.view(h, self.work / h), self.work / h)] + [
                (self.view(h, self.work / rel), self.work / h / "_foreign" / rel)
                for rel in self.foreign_files().get(h, [])
            ]:
                try:
                    if src.is_dir():
                        shutil.copytree(src, dst, dirs_exist_ok=True, ignore_dangling_symlinks=True)
                    elif src.is_file():
                        dst.parent.mkdir(parents=True, exist_ok=True)
                        shutil.copy2(src, dst)
                except (OSError, shutil.Error) as exc:
                    problems.append(f"{h}: {exc}"[:300])
        return problems

    def foreign_files(self, most: int = 50) -> dict[str, list[str]]:
        """Per host, the files (at most ``most``, relative to ``work``) it has under ``work``
        outside its own folder ``work/<host>``: on hosts that share no disk, what a process
        there wrote to a path meant for another host (none expected)."""
        found: dict[str, list[str]] = {}
        for h in self.lab.hosts:
            root = self.view(h, self.work)
            try:
                tops = [e for e in root.iterdir() if e.name != h]
            except OSError:
                continue
            for top in tops:
                for f in [top] if top.is_file() else sorted(top.rglob("*")):
                    if f.is_file() and len(found.setdefault(h, [])) < most:
                        found[h].append(str(f.relative_to(root)))
        return {h: fs for h, fs in found.items() if fs}

    def start_robot_hosts(self, timeout_s: float = 120.0) -> None:
        """Start every robot host's service (in parallel) and wait until each listens."""
        offsets = {r: self._start(r) for r in self.robots}
        for r, offset in offsets.items():
            self._wait_listening(r, offset, timeout_s)

    def restart(self, robot: str, timeout_s: float = 120.0) -> None:
        """Start ``robot``'s host service again, the same command in the same folder."""
        self._wait_listening(robot, self._start(robot), timeout_s)
        self.mark(f"{self.host_of(robot)} ({robot}) restarted and listening")

    def _start(self, robot: str) -> int:
        h = self.host_of(robot)
        cwd = self.work / h
        mine = self.view(h, cwd)
        if not mine.exists():
            mine.mkdir(parents=True)
            write_secret_file(mine / "dfrl.token", [self.token])
        log = mine / "robot.log"
        offset = log.stat().st_size if log.exists() else 0
        bind = "0.0.0.0"
        if self.plan.delay_ms > 0:
            # the robot behind a slow link: it binds loopback, the link listens on the
            # host's address (and dies with the host's other processes on a kill)
            bind = "127.0.0.1"
            self._start_link(h, cwd, mine)
        argv = dfrl_argv(
            "robot",
            "--host",
            bind,
            "--port",
            str(PORT),
            "--token-file",
            "dfrl.token",
            "--advertise",
            self.lab[h].address,
            "--workdir",
            "dfrl-robot",
        )
        if self.plan.itinerary == "tree":
            # a tree's copies are clones: admit as many as a tree run's driver asks for
            argv += ["--clone-limit", str(self.plan.fanout * TREE_ROUNDS_PER_S * 60)]
        with open(log, "ab") as fh:
            self.procs[robot] = self.lab[h].popen(
                argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=fh, stderr=subprocess.STDOUT
            )
        return offset

    def _start_link(self, h: str, cwd: Path, mine: Path) -> None:
        argv = [
            sys.executable,
            "-m",
            "dfrl.experiments.tools.bench.delay_link",
            f"{self.lab[h].address}:{PORT}",
            f"127.0.0.1:{PORT}",
            f"{self.plan.delay_ms:g}",
        ]
        log = mine / "link.log"
        with open(log, "ab") as fh:
            offset = fh.tell()
            proc = self.lab[h].popen(
                argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=fh, stderr=subprocess.STDOUT
            )

        def listening() -> bool:
            if proc.poll() is not None:
                raise FaultBenchError(
                    f"the delayed link of {h} exited {proc.returncode}: "
                    f"{log.read_bytes()[offset:][-800:].decode(errors='replace')}"
                )
            return LINK_LISTENING in log.read_bytes()[offset:].decode(errors="replace")

        wait_until(listening, 30.0, f"{h}'s delayed link to listen")

    def _wait_listening(self, robot: str, offset: int, timeout_s: float) -> None:
        h = self.host_of(robot)
        log = self.view(h, self.work / h / "robot.log")
        proc = self.procs[robot]

        def listening() -> bool:
            if proc.poll() is not None:
                raise FaultBenchError(
                    f"dfrl robot of {robot} exited {proc.returncode}: "
                    f"{log.read_bytes()[offset:][-1500:].decode(errors='replace')}"
                )
            return LISTENING in log.read_bytes()[offset:].decode(errors="replace")

        wait_until(listening, timeout_s, f"{robot}'s host to listen")

    def kill_host(self, robot: str) -> float:
        """kill -9 every process of ``robot``'s host; the time of the kill (time.time())."""
        t = time.time()
        n = self.lab.kill(self.host_of(robot))
        self.procs[robot].wait(timeout=10)
        self.mark(f"kill -9 of the {n} processes of {self.host_of(robot)} ({robot})", t)
        return t

    def cut(self, robot: str) -> float:
        t = time.time()
        self.lab.cut(self.host_of(robot))
        self.mark(f"link of {self.host_of(robot)} ({robot}) cut", t)
        return t

    def cut_host(self, host: str) -> float:
        """Cut host ``host``'s link (``driver`` or ``hI``)."""
        t = time.time()
        self.lab.cut(host)
        self.mark(f"link of {host} cut", t)
        return t

    def mend_host(self, host: str) -> float:
        t = time.time()
        self.lab.mend(host)
        self.mark(f"link of {host} mended", t)
        return t

    def mend(self, robot: str) -> float:
        t = time.time()
        self.lab.mend(self.host_of(robot))
        self.mark(f"link of {self.host_of(robot)} ({robot}) mended", t)
        return t

    # -- the driver ------------------------------------------------------------------------
    def config(self) -> dict:
        return {
            "name": self.name,
            "iterations": self.plan.iterations,
            "respite": self.plan.respite,
            "mode": "sync",
            "rtf": self.plan.rtf,
            "seed": self.plan.seed,
            "timeout_s": self.plan.timeout_s,
            "itinerary": self.plan.itinerary,
            "fanout": self.plan.fanout,
            "robots": [
                {
                    "id": r,
                    "arena": ARENAS[i % len(ARENAS)],
                    "robot_host": f"{self.lab[self.host_of(r)].address}:{PORT}",
                }
                for i, r in enumerate(self.robots)
            ],
        }

    def start_driver(self) -> None:
        drv = self.work / "driver"
        mine = self.view("driver", drv)
        mine.mkdir(parents=True, exist_ok=True)
        write_secret_file(mine / "dfrl.token", [self.token])
        (mine / "faults.json").write_text(json.dumps(self.config(), indent=1), encoding="utf-8")
        self.t0 = time.time()
        with open(mine / "driver.out", "wb") as out, open(mine / "driver.err", "wb") as err:
            self.driver = self.lab["driver"].popen(
                dfrl_argv("run", "faults.json", "--token-file", "dfrl.token", "--out", "out"),
                cwd=drv,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=err,
            )
        self.mark("driver started")

    def kill_driver(self) -> float:
        """kill -9 every process of the driver's host."""
        t = time.time()
        n = self.lab.kill("driver")
        assert self.driver is not None
        self.driver.wait(timeout=10)
        self.mark(f"kill -9 of the {n} processes of the driver's host", t)
        return t

    def wait_driver(self) -> int:
        """The driver's exit status (it ends by itself within the config's ``timeout_s``;
        killed 60 s after that)."""
        assert self.driver is not None
        try:
            rc = self.driver.wait(timeout=self.plan.timeout_s + 60)
        except subprocess.TimeoutExpired:
            self.lab.kill("driver")
            rc = self.driver.wait(timeout=10)
            self.mark(f"driver did not end within timeout_s + 60 s: killed (exit {rc})")
        self.mark(f"driver exited {rc}")
        return rc

    def driver_tail(self, chars: int = 1500) -> str:
        p = self.view("driver", self.work / "driver" / "driver.err")
        return p.read_text(encoding="utf-8", errors="replace")[-chars:] if p.exists() else ""

    def dfrl_on_driver(self, *words: str, timeout_s: float = 180.0) -> subprocess.CompletedProcess:
        """``dfrl WORDS...`` run in the driver's host, from its folder (bounded)."""
        return self.lab["driver"].run(
            dfrl_argv(*words),
            cwd=self.work / "driver",
            timeout=timeout_s,
            capture_output=True,
            text=True,
        )

    # -- what a case waits on --------------------------------------------------------------
    def logged_rounds(self) -> list[RoundRecord]:
        """The rounds the driver has logged so far (its live round log)."""
        return list(
            read_rounds_log(self.view("driver", self.out / f"rounds_{AGENT}.log"), AGENT).rounds
        )

    def wait_rounds(self, n: int, timeout_s: float = 120.0) -> RoundRecord:
        """Wait until ``n`` rounds are logged (the driver still running); the last one."""

        def enough() -> RoundRecord | None:
            if self.driver is not None and self.driver.poll() is not None:
                raise FaultBenchError(
                    f"the driver exited {self.driver.returncode} before "
                    f"round {n}: {self.driver_tail()}"
                )
            rs = self.logged_rounds()
            return rs[-1] if len(rs) >= n else None

        return wait_until(enough, timeout_s, f"round {n} in the driver's log")  # type: ignore[return-value]

    def shares_file(self, robot: str) -> Path | None:
        """``robot``'s shares file on its host (the experiment's folder there is
        ``NAME-<time>-<pid>``), as this process reads it; None before it exists."""
        h = self.host_of(robot)
        found = sorted(
            self.view(h, self.work / h / "dfrl-robot").glob(f"{self.name}-*/shares_{robot}.csv")
        )
        return found[-1] if found else None

    def shares(self, robot: str) -> int:
        """Tables ``robot``'s host has applied so far (rows of its shares file)."""
        p = self.shares_file(robot)
        if p is None or not p.is_file():
            return 0
        return max(0, sum(1 for ln in p.read_text(errors="replace").splitlines() if ln) - 1)

    def mark(self, what: str, t: float | None = None) -> None:
        t = time.time() if t is None else t
        self.actions.append({"at_s": round(t - self.t0, 2), "what": what})
