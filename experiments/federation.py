"""Launch a federated experiment on loopback: robot node processes, the agents, the results.

``run(config, output_dir) -> Results`` starts one robot node process per robot
(:mod:`dfrl.experiments.robot_node`), waits for their addresses, writes ``nodes.json``, launches one
dFRL itinerary agent per learning algorithm (``platform_pl/agents/dfrl_launch.pl``; the agent
of an algorithm visits only the robots using it), follows the agents' round logs and the
nodes' progress lines, starts robots that join during the run, and at the end writes
``metrics.csv``, ``rounds.csv``, the plots and ``summary.md`` (see :mod:`dfrl.experiments.results`).

If a robot process crashes the launcher says so, goes on with the others (the agent skips a
stop it cannot reach) and still writes what was collected. Every child process is killed on
an exception or Ctrl-C; every wait has a timeout.
"""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, TextIO

from dfrl.experiments.results import (AgentLog, read_json, read_rounds_log, read_shares,
                                 write_json)
from dfrl.experiments.config import ExperimentConfig, JoinSpec, Mode, NodeConfig, RobotSpec
from dfrl.experiments.errors import ExperimentError

REPO_ROOT: Path = Path(__file__).resolve().parent.parent

@dataclass
class Results:
    """What :func:`run` produced."""

    output_dir: Path
    config: ExperimentConfig
    wall_time_s: float
    rounds: list[dict[str, Any]]
    crashed: dict[str, int]
    agents_finished: dict[str, int | None]
    iterations: dict[str, int]
    plots: list[Path]
    ok: bool
    interrupted: str | None = None


# -- children --------------------------------------------------------------------------------
def swipl_path() -> str:
    path = shutil.which("swipl")
    if path is None:
        raise ExperimentError("swipl is not installed (run scripts/setup.sh)")
    return path


def agents_dir() -> Path:
    from dfrl.platform_pl import AGENTS_DIR

    return AGENTS_DIR


class _Child:
    """A robot node process and what its stdout said."""

    def __init__(self, robot: RobotSpec, cfg: NodeConfig, out_dir: Path,
                 on_event: Callable[[str, list[str]], None]) -> None:
        self.robot = robot
        self.cfg = cfg
        cfg_path = out_dir / "nodes" / f"{robot.id}.json"
        write_json(cfg_path, cfg.to_dict())
        logs = out_dir / "logs"
        logs.mkdir(exist_ok=True)
        self.err_path = logs / f"{robot.id}.err"
        self._err = open(self.err_path, "w", encoding="utf-8")
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "dfrl.experiments.robot_node", "--config", str(cfg_path)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err, cwd=REPO_ROOT,
            env=env, text=True, bufsize=1, start_new_session=True)
        self.address: tuple[str, int] | None = None
        self.iteration = 0
        self.done = False
        self.shares = 0
        self.ready = threading.Event()
        self._on_event = on_event
        self._reader = threading.Thread(target=self._read, name=f"read-{robot.id}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "DFRL_NODE" and len(parts) == 4:
                self.address = (parts[2], int(parts[3]))
                self.ready.set()
            elif tag == "DFRL_PROGRESS" and len(parts) == 3:
                self.iteration = int(parts[2])
            elif tag == "DFRL_EVENT" and len(parts) == 4:
                self._on_event(self.robot.id, parts)
            elif tag == "DFRL_DONE" and len(parts) == 4:
                self.iteration = int(parts[2])
                self.shares = int(parts[3])
                self.done = True
        self.ready.set()

    def close_stdin(self) -> None:
        try:
            if self.proc.stdin is not None and not self.proc.stdin.closed:
                self.proc.stdin.close()
        except OSError:
            pass

    def kill(self) -> None:
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
            except (ProcessLookupError, PermissionError):
                pass
            try:
                self.proc.wait(timeout=3)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
                self.proc.wait(timeout=3)

    def finish(self) -> None:
        self._reader.join(timeout=2)
        self._err.close()

    def err_tail(self, lines: int = 8) -> str:
        try:
            text = self.err_path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError:
            return ""
        text = [t for t in text if not t.startswith("pybullet build time")]
        return "\n".join(text[-lines:])


def send_control(host: str, port: int, token: int, command: dict[str, Any],
                 timeout_s: float = 30.0) -> None:
    """Post a control command to the agent whose first stop is host:port.

    ``command``: ``{"join": {"host", "port", "robot"}}``, ``{"method": name, "program": file,
    "nodes": [[host, port], ...]}`` or ``{"stop": true}`` (see dfrl_control.pl).

    Raises
    ------
    ExperimentError
        The control script failed or timed out.
    """
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False, encoding="utf-8") as fh:
        json.dump(command, fh)
        cmd_file = fh.name
    try:
        proc = subprocess.run(
            [swipl_path(), "-q", str(agents_dir() / "dfrl_control.pl"), str(host), str(port),
             str(token), cmd_file], capture_output=True, text=True, timeout=timeout_s,
            cwd=REPO_ROOT)
    except subprocess.TimeoutExpired:
        raise ExperimentError(f"control command {command} timed out after {timeout_s} s") from None
    finally:
        os.unlink(cmd_file)
    if proc.returncode != 0:
        raise ExperimentError(f"control command {command} failed (exit {proc.returncode}): "
                              f"{(proc.stderr or proc.stdout).strip()}")


# -- the launcher ----------------------------------------------------------------------------
class Launcher:
    """Runs one experiment; see :func:`run`."""

    def __init__(self, config: ExperimentConfig, output_dir: str | Path,
                 progress: TextIO | None = sys.stderr) -> None:
        self.config = config
        self.out = Path(output_dir).resolve()
        self.progress = progress
        self.children: dict[str, _Child] = {}
        self.agent_at: dict[str, tuple[str, str, int]] = {}   # agent -> (robot, op, iteration)
        self.agents: dict[str, dict[str, Any]] = {}           # agent -> launch info
        self.logs: dict[str, AgentLog] = {}
        self.crashed: dict[str, int] = {}
        self.joined: set[str] = set()
        self.killed: set[str] = set()          # children the launcher itself stopped
        self.interrupted: str | None = None
        self._lock = threading.Lock()
        self._t0 = time.monotonic()
        self._printed_rounds: dict[str, int] = {}
        self._last_status = 0.0

    # -- output ------------------------------------------------------------------------------
    def say(self, text: str) -> None:
        if self.progress is not None:
            self.progress.write(text + "\n")
            self.progress.flush()

    def _on_event(self, robot: str, parts: list[str]) -> None:
        algo = self.children[robot].robot.algo if robot in self.children else None
        with self._lock:
            for name, info in self.agents.items():
                if info["algo"] == algo:
                    self.agent_at[name] = (robot, parts[2], int(parts[3]))

    def status_line(self) -> str:
        its = " ".join(f"{rid}:{c.iteration}" + ("!" if rid in self.crashed else "")
                       for rid, c in self.children.items())
        where = []
        for name in self.agents:
            log = self.logs.get(name)
            done = len(log.rounds) if log else 0
            at = self.agent_at.get(name)
            pos = f"{at[0]} ({at[1]})" if at else "-"
            state = "finished" if log and log.finished is not None else f"at {pos}"
            where.append(f"{name} {done}/{self.agents[name]['rounds']} rounds, {state}")
        return f"[{time.monotonic() - self._t0:6.1f} s] {its} | " + "; ".join(where)

    # -- steps ---------------------------------------------------------------------------------
    def _node_config(self, robot: RobotSpec, iterations: int) -> NodeConfig:
        c = self.config
        grace = 10.0 if c.mode is Mode.SYNC else c.timeout_s
        return NodeConfig(robot=robot.id, out_dir=str(self.out), arena=robot.arena, algo=robot.algo,
                          seed=self._seed(robot), iterations=iterations, respite=c.respite,
                          mode=c.mode, rtf=c.rtf, token=c.token, trainer=dict(c.trainer),
                          grace_s=grace, sync_timeout_s=max(60.0, c.timeout_s))

    def _seed(self, robot: RobotSpec) -> int:
        known = [r.id for r in self.config.robots] + [j.robot.id for j in self.config.joins]
        if robot.seed is not None or robot.id in known:
            return self.config.robot_seed(robot)
        return self.config.seed + len(known) + len(self.joined)   # a joiner asked for at runtime

    def _spawn(self, robot: RobotSpec, iterations: int) -> _Child:
        child = _Child(robot, self._node_config(robot, iterations), self.out, self._on_event)
        self.children[robot.id] = child
        return child

    def _await_ready(self, children: list[_Child], timeout_s: float = 120.0) -> None:
        deadline = time.monotonic() + timeout_s
        for child in children:
            if not child.ready.wait(max(0.0, deadline - time.monotonic())) or child.address is None:
                rc = child.proc.poll()
                raise ExperimentError(
                    f"robot {child.robot.id} did not start (exit code {rc}): {child.err_tail()}")

    def _write_nodes(self) -> None:
        nodes = [{"robot": rid, "algo": ch.robot.algo, "arena": ch.robot.arena,
                  "host": ch.address[0], "port": ch.address[1], "pid": ch.proc.pid,
                  "joined": rid in self.joined}
                 for rid, ch in self.children.items() if ch.address is not None]
        agents = [{"name": name, "algo": info["algo"], "method": info["method"],
                   "rounds": info["rounds"], "rounds_log": info["rounds_log"],
                   "itinerary": info["itinerary"]} for name, info in self.agents.items()]
        write_json(self.out / "nodes.json", {"token": self.config.token, "nodes": nodes,
                                             "agents": agents})

    def _rest_s(self) -> float:
        c = self.config
        if c.mode is Mode.SYNC:
            return 0.0
        if c.rest_s is not None:
            return float(c.rest_s)
        if c.rtf:
            return c.respite * 0.064 / c.rtf
        share = max(1.0, len(c.robots) / (os.cpu_count() or 1))
        return round(c.respite * 0.0005 * share, 3)

    def _launch_agents(self) -> None:
        c = self.config
        for algo in c.algorithms():
            stops = [{"host": ch.address[0], "port": ch.address[1], "robot": rid}
                     for rid, ch in self.children.items() if ch.robot.algo == algo]
            if not stops:
                continue      # only joiners use it: nobody to start with
            name = f"fed_{algo}"
            if c.mode is Mode.ASYNC:
                self._await_first_respite([self.children[s["robot"]] for s in stops])
            log_path = self.out / f"rounds_{name}.log"
            launch = {"name": name, "itinerary": stops, "method": c.method_for(algo),
                      "rounds": c.rounds, "rest_s": self._rest_s(), "rounds_log": str(log_path),
                      "token": c.token, "timeout_s": float(c.timeout_s)}
            launch_file = self.out / f"launch_{name}.json"
            write_json(launch_file, launch)
            self.agents[name] = {"algo": algo, "method": c.method_for(algo), "rounds": c.rounds,
                                 "rounds_log": str(log_path), "itinerary": stops}
            self._write_nodes()
            try:
                proc = subprocess.run([swipl_path(), "-q", str(agents_dir() / "dfrl_launch.pl"),
                                       str(launch_file)], capture_output=True, text=True,
                                      timeout=60, cwd=REPO_ROOT)
            except subprocess.TimeoutExpired:
                raise ExperimentError(f"launching agent {name} timed out") from None
            (self.out / "logs" / f"launch_{name}.out").write_text(proc.stdout + proc.stderr,
                                                                 encoding="utf-8")
            if proc.returncode != 0:
                raise ExperimentError(f"launching agent {name} failed (exit {proc.returncode}): "
                                      f"{(proc.stderr or proc.stdout).strip()}")
            self.say(f"agent {name} ({c.method_for(algo)}, {c.rounds} rounds) launched to "
                     f"{' -> '.join(s['robot'] for s in stops)}")

    def _await_first_respite(self, children: list[_Child]) -> None:
        """Async: launch the agent when its robots reach the first respite boundary, so that
        rounds fall near iterations respite, 2 x respite, ... (the agent rests in between)."""
        target = min(self.config.respite, self.config.iterations)
        deadline = time.monotonic() + self.config.timeout_s
        while time.monotonic() < deadline:
            self._check_children()
            if all(ch.iteration >= target or ch.proc.poll() is not None for ch in children):
                return
            time.sleep(0.02)

    def _poll_logs(self) -> None:
        for name, info in self.agents.items():
            log = read_rounds_log(info["rounds_log"], name)
            self.logs[name] = log
            shown = self._printed_rounds.get(name, 0)
            for rec in log.rounds[shown:]:
                its = " ".join(f"{rid}:{c.iteration}" for rid, c in self.children.items()
                               if c.robot.algo == info["algo"])
                self.say(f"{name} round {rec.round}/{info['rounds']} {rec.method} "
                         f"{rec.duration_ms:.0f} ms, {rec.hops} hops, visited "
                         f"{','.join(rec.visited)} | {its}")
            self._printed_rounds[name] = len(log.rounds)

    def _check_children(self) -> None:
        for rid, ch in self.children.items():
            rc = ch.proc.poll()
            if rc is not None and rc != 0 and rid not in self.crashed and rid not in self.killed:
                self.crashed[rid] = rc
                self.say(f"ROBOT {rid} CRASHED (exit code {rc}) at iteration {ch.iteration}; "
                         f"see {ch.err_path}\n{ch.err_tail()}")

    def _join_requests(self) -> list[tuple[JoinSpec, int | None]]:
        """Joins from the config whose round has come, and requests left by ``dfrl join``."""
        c = self.config
        due: list[tuple[JoinSpec, int | None]] = [(j, None) for j in c.joins]
        req_dir = self.out / "join_requests"
        if req_dir.is_dir():
            for f in sorted(req_dir.glob("*.json")):
                try:
                    d = read_json(f)
                    spec = JoinSpec(RobotSpec(**d["robot"]), after_round=0)
                except (ValueError, TypeError, KeyError) as exc:
                    self.say(f"ignoring join request {f.name}: {exc}")
                    f.unlink()
                    continue
                if spec.robot.id in self.children and spec.robot.id not in self.joined:
                    self.say(f"ignoring join request {f.name}: robot {spec.robot.id} exists")
                    f.unlink()
                    continue
                due.append((spec, d.get("iterations")))
        return due

    def _handle_joins(self) -> None:
        c = self.config
        for join, iterations in self._join_requests():
            rid = join.robot.id
            if rid in self.joined:
                continue
            agent = f"fed_{join.robot.algo}"
            log = self.logs.get(agent)
            if agent not in self.agents:
                self.say(f"robot {rid} cannot join: no agent for {join.robot.algo}")
                self.joined.add(rid)
                continue
            if log is None or len(log.rounds) < join.after_round or log.finished is not None:
                continue
            done = len(log.rounds)
            remaining = int(iterations) if iterations else max(1, c.iterations - done * c.respite)
            try:
                self._join(join, agent, remaining, done)
            except (ExperimentError, OSError, ValueError) as exc:
                self.say(f"robot {rid} could not join: {exc}")
            req = self.out / "join_requests" / f"{rid}.json"
            if req.exists():
                req.unlink()

    def _join(self, join: JoinSpec, agent: str, remaining: int, done: int) -> None:
        """Start a joining robot's node and tell the agent (it adds the stop next round)."""
        c = self.config
        rid = join.robot.id
        self.joined.add(rid)
        child = self._spawn(join.robot, remaining)
        self._await_ready([child])
        host, port = child.address
        stop = {"host": host, "port": port, "robot": rid}
        self.agents[agent]["itinerary"].append(stop)
        first = self.agents[agent]["itinerary"][0]
        send_control(first["host"], first["port"], c.token, {"join": stop})
        self._write_nodes()
        self.say(f"robot {rid} ({join.robot.arena}, {remaining} iterations) joins {agent} "
                 f"after round {done}")

    def _all_finished(self) -> bool:
        return all(self.logs.get(n) is not None and self.logs[n].finished is not None
                   for n in self.agents)

    def _robots_done(self) -> bool:
        return all(ch.proc.poll() is not None or ch.iteration >= ch.cfg.iterations
                   for ch in self.children.values())

    def _monitor(self) -> None:
        c = self.config
        deadline = self._t0 + c.timeout_s
        robots_done_at: float | None = None
        finished_at: float | None = None
        while True:
            time.sleep(0.1)
            self._poll_logs()
            self._check_children()
            self._handle_joins()
            now = time.monotonic()
            if self.progress is not None and now - self._last_status > 5.0:
                self._last_status = now
                self.say(self.status_line())
            if c.mode is Mode.SYNC and self.agents and self._all_finished():
                # no more shares will come: robots past their last boundary exit by
                # themselves; one still waiting (a late joiner) is told to stop
                finished_at = finished_at or now
                if (all(ch.proc.poll() is not None for ch in self.children.values())
                        or now - finished_at > 2.0):
                    return
            if all(ch.proc.poll() is not None for ch in self.children.values()):
                self._poll_logs()
                if self._all_finished():
                    return
                robots_done_at = robots_done_at or now
                if now - robots_done_at > 5.0:
                    self.say("all robot processes ended before the agents finished")
                    return
            elif self._robots_done():
                robots_done_at = robots_done_at or now
                if self._all_finished():
                    return
                if now - robots_done_at > (60.0 if c.mode is Mode.SYNC else
                                           max(30.0, 3 * c.rounds * self._rest_s())):
                    self.say("robots finished but the agents did not; stopping")
                    return
            if now > deadline:
                self.say(f"experiment timeout ({c.timeout_s} s): stopping")
                return

    def _shutdown(self) -> None:
        for ch in self.children.values():
            ch.close_stdin()
        deadline = time.monotonic() + 15.0
        for ch in self.children.values():
            try:
                ch.proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self.say(f"robot {ch.robot.id} did not exit; killing it")
                self.killed.add(ch.robot.id)
                ch.kill()
        for ch in self.children.values():
            ch.finish()
        self._check_children()

    def run(self) -> Results:
        """Run the experiment (SIGTERM and SIGINT stop it cleanly when called from the main
        thread: children are killed and the partial results written)."""
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
        c = self.config
        self.out.mkdir(parents=True, exist_ok=True)
        for stale in list(self.out.glob("rounds_*.log")) + list(self.out.glob("shares_*.csv")) + \
                list(self.out.glob("metrics_*.csv")) + list(self.out.glob("join_requests/*.json")):
            stale.unlink()
        write_json(self.out / "config.json", c.to_dict())
        self._t0 = time.monotonic()
        ok = True
        try:
            children = [self._spawn(r, c.iterations) for r in c.robots]
            self._await_ready(children)
            self._write_nodes()
            self.say(f"{len(children)} robot nodes up: " + ", ".join(
                f"{rid}@{ch.address[1]}" for rid, ch in self.children.items()))
            self._launch_agents()
            self._monitor()
        except BaseException as exc:
            ok = False
            self.interrupted = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            for ch in self.children.values():
                if ch.proc.poll() is None:
                    self.killed.add(ch.robot.id)
                ch.kill()
            raise
        finally:
            self._shutdown()
            wall = time.monotonic() - self._t0
            results = self._collect(wall, ok)
        return results

    def _collect(self, wall: float, ok: bool) -> Results:
        from dfrl.experiments import results as res

        self._poll_logs()
        robots = list(self.children)
        res.merge_metrics(self.out, robots)
        shares = {rid: read_shares(self.out / f"shares_{rid}.csv") for rid in robots}
        rows = res.write_rounds_csv(self.out / "rounds.csv", self.logs.values(), robots, shares)
        plots: list[Path] = []
        try:
            from dfrl.experiments.fed_plots import plot_experiment

            plots = plot_experiment(self.out, title=self.config.default_title())
        except Exception as exc:  # noqa: BLE001 - plots are optional, results are not
            self.say(f"plots failed: {exc!r}")
        finished = {n: (lg.finished if lg else None) for n, lg in self.logs.items()}
        iters = {rid: ch.iteration for rid, ch in self.children.items()}
        ok = ok and not self.crashed and all(v is not None for v in finished.values())
        result = Results(self.out, self.config, wall, rows, dict(self.crashed), finished, iters,
                         plots, ok, self.interrupted)
        write_summary(result)
        return result


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def node_warnings(out_dir: Path) -> list[str]:
    """``Warning:`` / ``ERROR:`` lines the nodes and agent launchers printed (logs/)."""
    found = []
    for f in sorted((Path(out_dir) / "logs").glob("*")):
        try:
            text = f.read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        found += [f"{f.stem}: {ln.strip()}" for ln in text.splitlines()
                  if ln.lstrip().startswith(("Warning:", "ERROR:"))]
    return found


def write_summary(r: Results) -> Path:
    """``summary.md``: what ran, what came out."""
    from dfrl.experiments.results import read_metrics

    c = r.config
    lines = [f"# {c.name}", "", c.default_title(), "",
             f"- wall time: {r.wall_time_s:.1f} s",
             f"- mode: {c.mode.value}, real-time factor: {c.rtf or 'none (flat out)'}",
             f"- seed: {c.seed}; iterations {c.iterations}, respite {c.respite}, "
             f"rounds planned {c.rounds}", ""]
    metrics_path = r.output_dir / "metrics.csv"
    curves = read_metrics(metrics_path) if metrics_path.is_file() else {}
    lines += ["| robot | arena | algo | iterations | final sum of Q | cumulative reward | collisions |",
              "|---|---|---|---|---|---|---|"]
    specs = {s.id: s for s in list(c.robots) + [j.robot for j in c.joins]}
    for rid, cur in curves.items():
        if len(cur) == 0:
            continue
        s = specs.get(rid)
        last = cur[-1]
        lines.append(f"| {rid} | {s.arena if s else '?'} | {s.algo if s else '?'} | "
                     f"{int(last['iteration'])} | {last['q_sum']:.2f} | "
                     f"{last['cumulative_reward']:.1f} | {int(last['collisions'])} |")
    lines.append("")
    n_rounds = len(r.rounds)
    equal = sum(1 for row in r.rounds if row["all_equal"])
    durations = sorted(float(row["duration_ms"]) for row in r.rounds)
    med = durations[len(durations) // 2] if durations else float("nan")
    lines += [f"- agent rounds logged: {n_rounds}; rounds after which every visited robot held "
              f"the same table: {equal}/{n_rounds}",
              f"- median round time: {med:.1f} ms",
              f"- methods used: {', '.join(sorted({row['method'] for row in r.rounds})) or '-'}",
              f"- agents finished: {r.agents_finished}"]
    warnings = node_warnings(r.output_dir)
    if warnings:
        lines.append(f"- {len(warnings)} warning(s) in logs/ (agent and nodes), first ones:")
        lines += [f"  - `{w[:200]}`" for w in warnings[:5]]
    if r.crashed:
        lines.append(f"- CRASHED robots (exit codes): {r.crashed}")
    if r.interrupted:
        lines.append(f"- INTERRUPTED ({r.interrupted}): partial results, robots stopped by "
                     "the launcher")
    lines += ["", "Plots: " + ", ".join(p.name for p in r.plots), ""]
    path = r.output_dir / "summary.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def run(config: ExperimentConfig, output_dir: str | Path,
        progress: TextIO | None = sys.stderr) -> Results:
    """Run a federated experiment on loopback and write its results folder.

    Parameters
    ----------
    config : ExperimentConfig
    output_dir : str or Path
        Results folder (created; previous per-robot files in it are replaced).
    progress : TextIO or None
        Where progress lines go (None: quiet).
    """
    return Launcher(config, output_dir, progress).run()


def nodes_of(results_dir: str | Path) -> dict[str, Any]:
    """The ``nodes.json`` of a (running) experiment."""
    path = Path(results_dir) / "nodes.json"
    if not path.is_file():
        raise ExperimentError(f"{path} not found: is an experiment running there?")
    return read_json(path)


def inject_method(results_dir: str | Path, program: str | Path, method: str,
                  agent: str | None = None) -> list[str]:
    """Load ``program`` into every node of the running experiment and switch the agent(s) to
    ``method`` from their next round. Returns the agents told."""
    info = nodes_of(results_dir)
    prog = Path(program).resolve()
    if not prog.is_file():
        raise ExperimentError(f"program {prog} not found")
    told = []
    for a in info["agents"]:
        if agent is not None and a["name"] != agent:
            continue
        nodes = [[s["host"], s["port"]] for s in a["itinerary"]]
        first = a["itinerary"][0]
        send_control(first["host"], first["port"], info["token"],
                     {"method": method, "program": str(prog), "nodes": nodes})
        told.append(a["name"])
    if not told:
        raise ExperimentError(f"no agent {agent!r} in {results_dir}")
    return told


def join_robot(results_dir: str | Path, robot: str, arena: str, algo: str = "qlearning",
               iterations: int | None = None, seed: int | None = None,
               timeout_s: float = 60.0) -> dict[str, Any]:
    """Ask the launcher of a running experiment to start a robot and add it to the agent of
    its algorithm (from the agent's next round). Returns the new node's ``nodes.json`` entry.

    The launcher owns every process of an experiment: this leaves a request in
    ``RESULTS_DIR/join_requests/`` and waits until ``nodes.json`` lists the robot.
    """
    info = nodes_of(results_dir)
    if any(n["robot"] == robot for n in info["nodes"]):
        raise ExperimentError(f"robot {robot} is already part of the experiment")
    spec = RobotSpec(robot, arena, algo, seed)
    req = {"robot": dataclasses.asdict(spec), "iterations": iterations}
    write_json(Path(results_dir) / "join_requests" / f"{robot}.json", req)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.2)
        for n in nodes_of(results_dir)["nodes"]:
            if n["robot"] == robot:
                return n
    raise ExperimentError(f"the launcher did not start robot {robot} within {timeout_s} s "
                          "(is the experiment still running?)")
