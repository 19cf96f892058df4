"""A hostile user of the same host gets no token (issue 16): a run's token is random and
strong, never on a command line (``/proc/PID/cmdline``, what ``ps`` shows every user), and
in one file of the results folder only, ``secret.token`` of mode 0600. Real runs, real
processes; each scan has a control that shows it finds a planted token."""

from __future__ import annotations

import json
import os
import re
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.launcher.remote import tokens_of
from dfrl.experiments.tokens import (
    SECRET_FILE,
    TOKEN_ENV,
    env_with_tokens,
    new_secret,
    pop_env_tokens,
    read_token_file,
    TokenError,
)
from dfrl.platform_pl import PLATFORM_DIR
from tests.experiments.driver.launcher.helpers import run_in_thread, small_config
from tests.platform.conftest import Proc, start_node
from tests.platform.wire_client import authenticate, connect_nonce
from dfrl.experiments.processes import find_swipl

SWIPL = find_swipl()
pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


# -- the scans ---------------------------------------------------------------------------------
def children_of(pid: int) -> dict[int, str]:
    """pid -> command line (NUL-separated arguments joined by spaces) of every process whose
    parent is ``pid``."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) != pid:
                continue
            found[int(entry.name)] = (
                (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            )
        except (OSError, IndexError, ValueError):
            continue  # gone in between
    return found


def cmdlines_with(token: str) -> list[int]:
    """Pids of every process of this host whose command line holds ``token``."""
    hits = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if token.encode() in (entry / "cmdline").read_bytes():
                    hits.append(int(entry.name))
            except OSError:
                continue
    return hits


def files_with(folder: Path, token: str) -> dict[Path, int]:
    """Every file under ``folder`` that holds ``token``, with its permission bits."""
    return {
        p: stat.S_IMODE(p.stat().st_mode)
        for p in folder.rglob("*")
        if p.is_file() and not p.is_symlink() and token.encode() in p.read_bytes()
    }


def entropy_bits(token: str) -> int:
    assert SWIPL
    done = subprocess.run(
        [
            SWIPL,
            "-q",
            "-g",
            f"use_module({str(PLATFORM_DIR / 'secrets.pl')!r}),"
            f"token_entropy_bits('{token}', B), write(B), nl",
            "-t",
            "halt",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    return int(done.stdout.strip())


# -- a real run ----------------------------------------------------------------------------
def _scan_running(out: Path) -> tuple[str, dict[int, str]]:
    """Wait until the run's agent is launched; return its token and the command lines of
    this process's children (the run's console node and robot processes) while it runs."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        nodes = out / "nodes.json"
        try:
            if nodes.is_file() and json.loads(nodes.read_text())["agents"]:
                break
        except (ValueError, KeyError):
            pass  # being written
        time.sleep(0.02)
    else:
        raise AssertionError("the run launched no agent in time")
    return tokens_of(out)[0], children_of(os.getpid())


def test_a_run_keeps_its_random_token_off_command_lines_and_in_one_0600_file(
    tmp_path: Path,
) -> None:
    # Prepare: two real runs of 2 robots each, with no token in their config
    cfg = small_config(2, iterations=1500, respite=500)
    assert cfg.token is None
    tokens, seen = [], []
    for k in (1, 2):
        out = tmp_path / f"run{k}"
        thread, box = run_in_thread(cfg, out)
        # Execute: look at every process of the run while it runs, then at its files
        token, children = _scan_running(out)
        mid_run_files = files_with(out, token)
        mid_run_cmdlines = cmdlines_with(token)
        thread.join(timeout=300)
        assert "exc" not in box, box
        assert box["res"].ok, box["res"]
        tokens.append(token)
        seen.append(children)
        # Assert: the scan saw the run's processes (console node, both robot processes) ...
        cmdlines = list(children.values())
        assert sum("dfrl_console.pl" in c for c in cmdlines) == 1, cmdlines
        robots = json.loads((out / "nodes.json").read_text())["nodes"]
        assert {n["pid"] for n in robots} <= set(children), (robots, children)
        # ... and none of them (no process of this host) had the token on its command line
        assert mid_run_cmdlines == [], {p: children.get(p) for p in mid_run_cmdlines}
        assert not any(token in c for c in cmdlines)
        # the only file holding it, during and after the run, is secret.token, mode 0600
        secret = out / SECRET_FILE
        assert mid_run_files == {secret: 0o600}, mid_run_files
        assert files_with(out, token) == {secret: 0o600}
        assert read_token_file(secret) == [token]
        # results name no token at all (not even as a key)
        for name in (
            "nodes.json",
            "config.json",
            "launch_fed_qlearning.json",
            "nodes/r1.json",
            "nodes/r2.json",
        ):
            assert "token" not in json.loads((out / name).read_text()), name
    # the default token is random and strong
    assert tokens[0] != tokens[1]
    for token in tokens:
        assert re.fullmatch(r"dfrl_[0-9a-f]{64}", token), token
        assert entropy_bits(token) >= 128


def test_a_configured_weak_token_still_runs_on_loopback(tmp_path: Path) -> None:
    cfg = small_config(2, iterations=100, respite=50, token=1111)
    out = tmp_path / "out"
    thread, box = run_in_thread(cfg, out)
    thread.join(timeout=300)
    assert "exc" not in box and box["res"].ok, box
    assert tokens_of(out) == [1111]
    assert stat.S_IMODE((out / SECRET_FILE).stat().st_mode) == 0o600
    assert "token" not in json.loads((out / "config.json").read_text())


def test_the_scans_find_a_planted_token(tmp_path: Path) -> None:
    """Controls: the same scans find the token when it is in a 0644 file or on a command
    line (so the assertions above can fail)."""
    token = new_secret()
    planted = tmp_path / "nodes.json"
    planted.write_text(json.dumps({"token": token}))
    planted.chmod(0o644)
    assert files_with(tmp_path, token) == {planted: 0o644}
    proc = subprocess.Popen([sys.executable, "-c", "import sys, time; time.sleep(60)", token])
    try:
        deadline = time.monotonic() + 10
        while proc.pid not in cmdlines_with(token) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.pid in cmdlines_with(token)
        assert token in children_of(os.getpid())[proc.pid]
    finally:
        proc.kill()
        proc.wait()


# -- nodes and their token sources --------------------------------------------------------------
def test_node_reads_its_token_from_the_environment_and_deletes_it(procs: list[Proc]) -> None:
    token = new_secret()
    p, port = start_node(procs, "--port", "0", "--interactive", env=env_with_tokens([token]))
    assert token not in Path(f"/proc/{p.popen.pid}/cmdline").read_text()
    s, nonce = connect_nonce(port)  # the node holds the token
    with s:
        assert authenticate(s, nonce, token).startswith("ok(authenticated)")
    s, nonce = connect_nonce(port)  # and only it: a wrong one is refused
    with s:
        assert not authenticate(s, nonce, new_secret()).startswith("ok(authenticated)")
    # a process the node starts does not inherit DFRL_TOKEN
    assert p.popen.stdin is not None
    p.popen.stdin.write(
        "(getenv('DFRL_TOKEN', _) -> writeln(env_kept) ; writeln(env_gone)), "
        "shell('env; echo ENV_END').\n"
    )
    p.popen.stdin.flush()
    p.wait_for("ENV_END")
    assert "env_gone" in p.output() and token not in p.output(), p.output()
    assert "Warning" not in p.output(), p.output()


def test_node_reads_a_token_file(procs: list[Proc], tmp_path: Path) -> None:
    token = new_secret()
    path = tmp_path / "node.token"
    path.write_text(token + "\n")
    path.chmod(0o600)
    p, port = start_node(procs, "--host", "0.0.0.0", "--port", "0", "--token-file", str(path))
    s, nonce = connect_nonce(port)
    with s:
        assert authenticate(s, nonce, token).startswith("ok(authenticated)")
    assert "Warning" not in p.output(), p.output()


def test_token_on_the_command_line_still_works_with_a_warning(procs: list[Proc]) -> None:
    token = new_secret()
    p, port = start_node(procs, "--port", "0", "--token", token)
    p.wait_for("other users of this host see it (ps)")
    s, nonce = connect_nonce(port)
    with s:
        assert authenticate(s, nonce, token).startswith("ok(authenticated)")


def test_node_without_token_warns_on_loopback_and_refuses_elsewhere(procs: list[Proc]) -> None:
    assert SWIPL
    p, _ = start_node(procs, "--port", "0", env=env_with_tokens([]))
    p.wait_for("has no token: it is OPEN")
    done = subprocess.run(
        [SWIPL, "-q", str(PLATFORM_DIR / "node_main.pl"), "--host", "0.0.0.0", "--port", "0"],
        capture_output=True,
        text=True,
        timeout=30,
        stdin=subprocess.DEVNULL,
        env=env_with_tokens([]),
    )
    assert done.returncode == 1, done
    assert "No permission to listen" in done.stderr and "0 bits of entropy" in done.stderr, (
        done.stderr
    )
    assert "listening" not in done.stdout


def _dfrl(*args: str) -> list[str]:
    return [sys.executable, "-m", "dfrl", *args]


@pytest.mark.parametrize("command", ["node", "robot"])
def test_dfrl_node_and_robot_take_the_token_from_a_file_or_the_environment(
    command: str, procs: list[Proc], tmp_path: Path
) -> None:
    token = new_secret()
    path = tmp_path / "t.token"
    path.write_text(token + "\n")
    base = [command, "--host", "127.0.0.1", "--port", "0"]
    if command == "robot":
        base += ["--workdir", str(tmp_path / "work")]
    # a token file others may read is refused
    path.chmod(0o644)
    done = subprocess.run(
        _dfrl(*base, "--token-file", str(path)),
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert done.returncode == 2 and "chmod 600" in done.stderr, done.stderr
    # from a 0600 file, and from DFRL_TOKEN: off every command line, no warning
    path.chmod(0o600)
    for args, env in (([*base, "--token-file", str(path)], None), (base, env_with_tokens([token]))):
        p = Proc(_dfrl(*args), env=env)
        procs.append(p)
        port = int(p.wait_for(f"dfrl {command} listening on", timeout=60).rsplit(":", 1)[1])
        cmdline = Path(f"/proc/{p.popen.pid}/cmdline").read_bytes()
        assert token.encode() not in cmdline and p.popen.pid not in cmdlines_with(token)
        s, nonce = connect_nonce(port)
        with s:
            assert authenticate(s, nonce, token).startswith("ok(authenticated)")
        assert "Warning" not in p.output() and "warning" not in p.output(), p.output()
    # --token: accepted with a warning
    p = Proc(_dfrl(*base, "--token", token))
    procs.append(p)
    p.wait_for(f"dfrl {command} listening on", timeout=60)
    assert "other users of this host see it (ps)" in p.output()


def test_dfrl_robot_needs_a_token() -> None:
    done = subprocess.run(
        _dfrl("robot", "--host", "127.0.0.1", "--port", "0"),
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
        env=env_with_tokens([]),
    )
    assert done.returncode == 2 and "no token" in done.stderr, done.stderr


def test_token_formats(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(TOKEN_ENV, "1111\n dfrl_ab \n\n")
    assert pop_env_tokens() == [1111, "dfrl_ab"]
    assert TOKEN_ENV not in os.environ
    assert env_with_tokens([7, "x_y"], {})[TOKEN_ENV] == "7\nx_y\n"
    with pytest.raises(TokenError, match="white space"):
        env_with_tokens(["a b"])
    empty = tmp_path / "empty"
    empty.write_text("\n")
    empty.chmod(0o600)
    with pytest.raises(TokenError, match="no token"):
        read_token_file(empty)
    with pytest.raises(TokenError, match="not found"):
        tokens_of_missing(tmp_path)


def tokens_of_missing(folder: Path) -> None:
    from dfrl.experiments.tokens import run_tokens

    run_tokens(folder)


def test_a_node_store_keeps_tokens_from_other_users(tmp_path: Path) -> None:
    """A node started with store(Dir) keeps its agents' records (tokens included) in Dir: every
    record file is 0600 and its folder 0700, so no other user reads a token there. The scan
    finds the token in the records (control: the token really is on disk)."""
    token = new_secret()
    store = tmp_path / "store"
    script = tmp_path / "stored.pl"
    script.write_text(f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic keeper/3, notes/2.
    keeper(guid, _, _).
    main :- node_start(localhost:0, _, [token({token!r}), store({str(store)!r})]),
            assertz(notes(guid, 1)),
            create_mobile_agent(k1, keeper, [{token!r}]),
            add_payload(k1, [(notes, 2)]),
            sleep(0.5), format("STORED~n"), flush_output.
    """)
    done = subprocess.run(
        [find_swipl() or "swipl", "-q", "-g", "main", "-t", "halt", str(script)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "STORED" in done.stdout, done
    holding = files_with(store, token)
    assert holding, sorted(p.name for p in store.rglob("*"))  # control
    for path in holding:
        assert stat.S_IMODE(path.stat().st_mode) & 0o077 == 0, (path, oct(path.stat().st_mode))
        d = path.parent  # and the folder the records are in
        assert stat.S_IMODE(d.stat().st_mode) & 0o077 == 0, (d, oct(d.stat().st_mode))
