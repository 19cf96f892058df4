"""``dfrl robot``: a long-lived robot process driven over the platform by a plain swipl client
(robot_client.pl, transport_request/4). Real processes and sockets."""

from __future__ import annotations

import base64
import csv
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.robot_host.checkpoint import load_checkpoint
from dfrl.experiments.processes import find_swipl

REPO = Path(__file__).resolve().parents[3]
CLIENT = Path(__file__).with_name("robot_client.pl")
TOKEN = "1111"

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Service:
    """A ``dfrl robot`` process on 127.0.0.1:port."""

    def __init__(self, workdir: Path, port: int) -> None:
        self.port = port
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "dfrl.experiments",
                "robot",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--token",
                TOKEN,
                "--workdir",
                str(workdir),
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=REPO,
        )
        line = self.proc.stdout.readline()
        assert line.strip() == f"dfrl robot listening on 127.0.0.1:{port}", (
            line + self.proc.stderr.read()
        )

    def ask(self, *requests: object, token: str = TOKEN) -> list[dict]:
        """Send requests (console JSON form) with the swipl client; its JSON answers."""
        text = "".join(json.dumps(r) + "\n" for r in requests)
        p = subprocess.run(
            ["swipl", str(CLIENT), "127.0.0.1", str(self.port), token],
            input=text,
            capture_output=True,
            text=True,
            timeout=120,
        )
        answers = [json.loads(line) for line in p.stdout.splitlines() if line.strip()]
        assert len(answers) == len(requests), p.stdout + p.stderr
        return answers

    def status(self) -> dict:
        return self.ask("status")[0]["ok"]

    def wait_state(self, state: str, timeout: float = 90.0) -> dict:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            st = self.status()
            if st["state"] == state:
                return st
            assert st["state"] != "failed", st
            time.sleep(0.3)
        raise AssertionError(f"not {state} within {timeout} s: {st}")

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        out, _ = self.proc.communicate(timeout=30)
        return out

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.communicate(timeout=30)


def configure(experiment: str, arena_json: object = None, **node: object) -> dict:
    node.setdefault("robot", "r1")
    node.setdefault("arena", "r2")
    return {"configure": json.dumps({"experiment": experiment, "robot": node, "arena": arena_json})}


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    svc = Service(tmp_path_factory.mktemp("robot") / "work", free_port())
    try:
        yield svc
    finally:
        svc.kill()


def test_refuses_unauthenticated_and_bad_requests_and_stays_up(service: Service) -> None:
    refused = service.ask("status", token="none")[0]
    assert refused["error"].startswith("permission_error(access,robot_service,")
    bad_key, bad_json, bad_state, unknown = service.ask(
        configure("x1", colour="red"),
        {"configure": "{not json"},
        "start",
        {"raw": "fetch(a, -1, 10)"},
    )
    assert "colour" in bad_key["message"] and "Bad robot configuration" in bad_key["message"]
    assert "not JSON" in bad_json["message"]
    assert bad_state["error"] == "permission_error(start,robot_state,idle)"
    assert unknown["error"].startswith("domain_error(dfrl_robot_request")
    st = service.status()
    assert (
        st["state"] == "idle"
        and st["robot"] is None
        and st["address"] == ["127.0.0.1", service.port]
    )


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def test_a_driver_cannot_make_the_host_load_a_learner(service: Service, tmp_path: Path) -> None:
    """A token holder's config naming a plug-in learner (a module to import, a file of the
    host's to execute) is refused before anything is imported (the file would leave a mark).
    The controls, configs without it that the service accepts, are the other tests'."""
    marker = tmp_path / "ran"
    evil = tmp_path / "evil.py"
    evil.write_text(f"open({str(marker)!r}, 'w').write('imported')\n")
    specs = {"a": f"{evil}:X", "b": "antigravity:X", "c": {"class": f"{evil}:X"}}
    answers = service.ask(
        *[configure(f"l{k}", algo="a", learners={"a": s}) for k, s in specs.items()]
    )
    for answer in answers:
        assert (
            "error" in answer
            and "a robot host loads no learner a driver names" in answer["message"]
        ), answer
    assert not marker.exists(), "the host imported a file a token holder named"
    assert service.proc.poll() is None


def test_arenas_are_names_of_its_own_never_paths(service: Service, tmp_path: Path) -> None:
    """A token holder names arenas, never files of the host: /etc/passwd, /dev/zero, ``../``,
    a missing path and a link out of the service's arena folder get one message that does not
    depend on the file (no oracle), the service stays up and small; the service's own
    ``arenas/NAME.json`` and a built-in name are accepted (the controls)."""
    workdir = Path(service.proc.args[service.proc.args.index("--workdir") + 1])
    own = workdir / "arenas"
    own.mkdir(parents=True, exist_ok=True)
    (own / "mine.json").write_text((REPO / "arenas" / "r3.json").read_text())
    (own / "out.json").symlink_to("/etc/passwd")
    secret = tmp_path / "secret.json"  # a valid arena outside the folder
    secret.write_text((REPO / "arenas" / "r3.json").read_text())
    rss0 = _rss_kib(service.proc.pid)
    names = [
        "/etc/passwd",
        "/dev/zero",
        "../arenas/mine",
        "../../../../etc/passwd",
        str(tmp_path / "missing.json"),
        str(secret),
        "out",
        "mine.json",
        "r1/../r2",
        "/proc/self/environ",
    ]
    answers = service.ask(*[configure(f"a{i}", arena=n) for i, n in enumerate(names)])
    messages = []
    for name, answer in zip(names, answers):
        assert "error" in answer and "unknown arena" in answer["message"], (name, answer)
        message = answer["message"].replace(repr(name[:64]), "NAME")
        # a suggestion depends on the name typed and the host's own names only
        near = re.search(r" \(did you mean '([^']+)'\?\)", message)
        assert near is None or near.group(1) in ("mine", "out", "r1", "r2"), message
        messages.append(message if near is None else message.replace(near.group(0), ""))
    assert len(set(messages)) == 1, messages  # nothing about the file itself
    assert "mine" in messages[0] and "r1" in messages[0] and "passwd" not in messages[0]
    assert service.proc.poll() is None
    assert _rss_kib(service.proc.pid) - rss0 < 50_000, "the service grew reading an arena"
    assert service.status()["state"] in ("idle", "finished", "failed")
    # controls: its own arena file and a built-in name configure a run
    for experiment, name in (("a_own", "mine"), ("a_builtin", "R2")):
        assert service.ask(configure(experiment, arena=name, iterations=10), "start") == [
            {"ok": True},
            {"ok": True},
        ], name
        assert service.wait_state("finished")["experiment"] == experiment
    tables = {
        e: json.loads((workdir / e / "tables" / "r1.json").read_text())
        for e in ("a_own", "a_builtin")
    }
    assert tables["a_own"]["arena"] == "R3" or tables["a_own"]["arena"].lower() == "r3"
    assert tables["a_builtin"]["arena"].lower() == "r2"


def _fetch_all(service: Service, files: list[list]) -> dict[str, bytes]:
    """Every file in chunks of 4096 bytes (one client run)."""
    requests, names = [], []
    for name, size in files:
        for offset in range(0, max(size, 1), 4096):
            requests.append({"fetch": {"name": name, "offset": offset, "max": 4096}})
            names.append(name)
    got: dict[str, bytes] = {name: b"" for name, _ in files}
    for name, answer in zip(names, service.ask(*requests)):
        chunk = answer["ok"]
        got[name] += base64.b64decode(chunk["data"])
    return got


def test_runs_experiments_in_a_row_and_serves_their_files(service: Service, tmp_path: Path) -> None:
    workdir = Path(service.proc.args[service.proc.args.index("--workdir") + 1])
    arena = json.loads((REPO / "arenas" / "r3.json").read_text())
    ok = service.ask(configure("e1", arena_json=arena, iterations=150, respite=50), "start")
    assert ok == [{"ok": True}, {"ok": True}]
    st = service.wait_state("finished")
    assert (st["experiment"], st["iteration"], st["iterations"]) == ("e1", 150, 150)
    files = service.ask("files")[0]["ok"]
    names = [n for n, _ in files]
    for want in (
        "metrics_r1.csv",
        "shares_r1.csv",
        "tables/r1.npy",
        "tables/r1.json",
        "logs/r1.out",
    ):
        assert want in names, names
    assert not any(n.startswith(("checkpoint/", "service/")) for n in names)
    got = _fetch_all(service, files)
    for name, size in files:
        disk = (workdir / "e1" / name).read_bytes()
        assert got[name] == disk and len(disk) == size, name
    assert json.loads(got["tables/r1.json"])["arena"] == arena["name"]
    past_end = service.ask(
        {"fetch": {"name": "metrics_r1.csv", "offset": 10**6, "max": 10}},
        {"fetch": {"name": "../e1/metrics_r1.csv", "offset": 0, "max": 10}},
    )
    assert past_end[0]["ok"] == {"data": "", "eof": True}
    assert past_end[1]["error"].startswith("existence_error(result_file")

    assert service.ask(configure("e2", robot="r4", arena="r1", iterations=60), "start") == [
        {"ok": True},
        {"ok": True},
    ]
    st = service.wait_state("finished")
    assert (st["experiment"], st["robot"], st["iteration"]) == ("e2", "r4", 60)
    with open(workdir / "e2" / "metrics_r4.csv", newline="") as fh:
        assert [int(r["iteration"]) for r in csv.DictReader(fh)] == list(range(1, 61))
    assert (workdir / "e1" / "metrics_r1.csv").is_file()  # the first one's files stay
    # each configure made the node forget the leases and writes of the experiment before
    for err in (workdir / "e1" / "logs" / "r1.err", workdir / "e2" / "logs" / "r4.err"):
        assert "kept the leases" not in err.read_text(), err.read_text()


def test_stop_ends_a_run_early(service: Service) -> None:
    assert service.ask(configure("e3", iterations=100000, rtf=2.0), "start") == [
        {"ok": True},
        {"ok": True},
    ]
    time.sleep(1.0)
    assert service.ask("stop")[0] == {"ok": True}
    st = service.status()
    assert st["state"] == "finished" and 0 < st["iteration"] < 100000


def test_sigterm_mid_run_exits_0_with_files_flushed(tmp_path: Path) -> None:
    svc = Service(tmp_path / "work", free_port())
    try:
        svc.ask(configure("t", iterations=100000, rtf=5.0), "start")
        time.sleep(1.5)
        t0 = time.monotonic()
        out = svc.stop()
        assert svc.proc.returncode == 0, svc.proc.stderr.read()
        assert time.monotonic() - t0 < 15
        assert "stopped by a signal" in out
        with open(tmp_path / "work" / "t" / "metrics_r1.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        assert rows and [int(r["iteration"]) for r in rows] == list(range(1, len(rows) + 1))
        assert (tmp_path / "work" / "t" / "tables" / "r1.npy").is_file()
    finally:
        svc.kill()


def test_killed_robot_resumes_from_its_last_checkpoint(tmp_path: Path) -> None:
    """kill -9 mid-run after a share; a new process with the same workdir resumes from the
    checkpoint of that share: its iteration, its table, and files without duplicate rows."""
    work, port = tmp_path / "work", free_port()
    svc = Service(work, port)
    try:
        svc.ask(
            configure("k", iterations=600, rtf=5.0), "start", {"share": {"robot": "r1", "round": 3}}
        )
        deadline = time.monotonic() + 60
        while svc.status()["shares"] < 1:
            assert time.monotonic() < deadline
            time.sleep(0.2)
        cp = load_checkpoint(work / "k" / "checkpoint", "r1")
        while svc.status()["iteration"] < cp.iteration + 30:
            assert time.monotonic() < deadline
            time.sleep(0.2)
        os.kill(svc.proc.pid, signal.SIGKILL)
        svc.kill()
    finally:
        svc.kill()
    with open(work / "k" / "shares_r1.csv", newline="") as fh:
        share = list(csv.DictReader(fh))[0]
    assert (share["round"], share["agent"], share["epoch"]) == ("3", "sharer", "0")
    assert int(share["iteration"]) == cp.iteration and cp.shares == 1
    from dfrl.experiments.robot_host import table_digest

    assert table_digest(cp.q) == share["digest"]

    svc = Service(work, port)
    try:
        ans = svc.ask(configure("k", iterations=600, resume=True), "status")
        assert ans[0] == {"ok": True}, ans
        st = ans[1]["ok"]
        assert (st["state"], st["iteration"], st["shares"]) == ("configured", cp.iteration, 1)
        assert svc.ask("stop")[0] == {"ok": True}  # tables saved as resumed
        assert np.array_equal(np.load(work / "k" / "tables" / "r1.npy"), cp.q)
        assert svc.ask(configure("k", iterations=cp.iteration + 40, resume=True), "start")[1] == {
            "ok": True
        }
        st = svc.wait_state("finished")
        assert st["iteration"] == cp.iteration + 40
        with open(work / "k" / "metrics_r1.csv", newline="") as fh:
            its = [int(r["iteration"]) for r in csv.DictReader(fh)]
        assert its == list(range(1, cp.iteration + 41))
        assert svc.ask(configure("none", resume=True))[0]["message"].startswith(
            "Bad robot configuration: no checkpoint"
        )
    finally:
        svc.stop()
