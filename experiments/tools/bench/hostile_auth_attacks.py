"""The authenticated attackers of ``dfrl bench hostile``: peers that hold the target's token.

A robot host of a federation holds the token of every node it talks to, so a compromised or
malicious one can send agents and programs, post, and send frames after authenticating. The
agent and program attackers are ``swipl hostile_auth_node.pl`` processes (:class:`AuthAttacker`,
started at ``nice -n 19``); the frame attackers are threads of the benchmark's nice'd attacker
process (:class:`AuthFrames`, run by :mod:`hostile_child`).

``escapes``    agents and programs trying side doors of the sandbox (see
               ``hostile_auth_node.pl``, ``escape/4``; also programs defining system hooks and
               one whose initialization loops, ``stopped`` by the bounds): each is refused or
               accepted, and ran or
               not (its marker file exists, it carried home what it looked for, or the target's
               ``double_quotes`` flag changed): :func:`escape_results`;
``loop``, ``memory``, ``clone``, ``assert``, ``log``, ``post``, ``sleep``, ``idle``
               waves of agents that spin, build a huge list, clone themselves twice at every
               stop, assert facts, print lines, post to themselves, sleep an hour in their
               handler (holding a run slot) or stay idle on the target;
``authframes`` text frames near the target's ``max_frame_size`` and a flood of small requests,
               on authenticated connections.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import re
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

from dfrl.experiments import processes
from dfrl.experiments.tools.bench.hostile_attacks import MAGIC, HEADER, frame_header

AUTH_SCRIPT = Path(__file__).resolve().parent / "hostile_auth_node.pl"
AGENT_ATTACKS = (
    "loop",
    "memory",
    "clone",
    "assert",
    "log",
    "post",
    "catom",
    "gmp",
    "sleep",
    "idle",
)
AUTH_ATTACKS = ("escapes", *AGENT_ATTACKS, "authframes")


class AuthAttacker:
    """One ``hostile_auth_node.pl`` process at ``nice -n 19``: its JSON lines are collected.

    ``options`` become ``--key=value`` arguments (``marker_dir``, ``per_wave``, ``wave_s``,
    ``size``, ``duration_s``, ``wait_s``, ``tls``).
    """

    def __init__(self, attack: str, token: int, port: int, options: dict[str, Any]) -> None:
        if attack not in ("escapes", *AGENT_ATTACKS):
            raise ValueError(f"unknown authenticated attack {attack!r}")
        self.attack = attack
        self.argv = [
            "nice",
            "-n",
            "19",
            processes.swipl(),
            "-q",
            str(AUTH_SCRIPT),
            attack,
            str(token),
            str(port),
        ]
        self.argv += [f"--{k.replace('_', '-')}={v}" for k, v in options.items()]
        self.records: list[dict[str, Any]] = []
        self.stderr: list[str] = []
        self.proc: subprocess.Popen[str] | None = None
        self.reader: threading.Thread | None = None

    def start(self) -> None:
        self.proc = processes.start(
            self.argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        threading.Thread(target=self._read_err, daemon=True).start()

    def _read(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("{"):
                try:
                    self.records.append(json.loads(line))
                except json.JSONDecodeError:
                    self.stderr.append(f"bad line: {line[:200]}")

    def _read_err(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for line in self.proc.stderr:
            if len(self.stderr) < 50:
                self.stderr.append(line.rstrip())

    def stop(self, timeout_s: float = 90.0) -> dict[str, Any]:
        """Close its stdin, wait for its summary; the records it printed."""
        assert self.proc is not None and self.reader is not None
        try:
            if self.proc.stdin:
                self.proc.stdin.close()
        except OSError:
            pass
        processes.wait_or_stop(self.proc, timeout_s)
        self.reader.join(10)
        summary = next((r for r in self.records if r.get("event") == "summary"), None)
        if summary is None:
            raise RuntimeError(
                f"attacker {self.attack} ended without a summary "
                f"(exit {self.proc.returncode}): {' | '.join(self.stderr)[-2000:]}"
            )
        refusals = [r["error"] for r in self.records if r.get("event") == "sent"]
        return {
            "counts": summary["counts"],
            "heard": summary["heard"],
            "refusal_examples": refusals[:3],
            "escapes": [r for r in self.records if r.get("event") == "escape"],
        }


def escape_results(
    attempts: list[dict[str, Any]],
    token: int,
    double_quotes_before: str | None,
    double_quotes_after: str | None,
) -> dict[str, Any]:
    """Each escape attempt with ``ran`` decided, and the totals.

    An attempt ran if its marker file exists, it reported home what it looked for (the
    target's argv, another agent's payload, ``double_quotes`` = ``atom``), or (for
    ``double_quotes``) the target's flag in ``user`` changed during the phase.
    """
    out = []
    for a in attempts:
        carried = a.get("carried")
        ran = Path(a["marker"]).exists()
        leaked_token = False
        if a["reported"] and carried is not None:
            if a["name"] == "argv":
                ran = ran or carried.startswith("[") and carried != "[]"
                leaked_token = re.search(rf"\b{token}\b", carried) is not None
            elif a["name"] == "other_payload":
                ran = ran or carried != "[]"
            elif a["name"] == "double_quotes":
                ran = ran or carried == "atom"
        if a["name"] == "double_quotes" and double_quotes_after != double_quotes_before:
            ran = True
        out.append(
            {
                "name": a["name"],
                "via": a["via"],
                "verdict": a["verdict"],
                "ran": ran,
                "reported": a["reported"],
                "carried": carried,
                "leaked_token": leaked_token,
                "error": (a.get("error") or "")[:300],
            }
        )
    return {
        "attempts": out,
        "tried": len(out),
        "refused": sum(a["verdict"] == "refused" for a in out),
        "accepted": sum(a["verdict"] == "accepted" for a in out),
        "stopped": sum(a["verdict"] == "stopped" for a in out),
        "ran": sum(a["ran"] for a in out),
        "ran_names": [f"{a['via']}:{a['name']}" for a in out if a["ran"]],
    }


def token_proof(token: int, nonce: str) -> str:
    """Hex HMAC-SHA256 of ``nonce`` keyed by the token's canonical text."""
    return hmac.new(str(token).encode(), nonce.encode(), hashlib.sha256).hexdigest()


class _Conn:
    """An authenticated connection to the target: one request, one reply."""

    def __init__(self, port: int, token: int, timeout: float = 30.0) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        self.buf = b""
        hello = self.read()
        m = re.match(r"hello\(\d+,'?([0-9a-f]+)'?,", hello or "")
        if not m:
            self.sock.close()
            raise ConnectionError(f"no hello: {hello!r:.200}")
        self.sock.sendall(_frame(f"auth(['{token_proof(token, m.group(1))}']) .\n".encode()))
        verdict = self.read()
        if not verdict or not verdict.startswith("ok(authenticated)"):
            self.sock.close()
            raise ConnectionError(f"not authenticated: {verdict!r:.200}")

    def read(self) -> str | None:
        """The next frame's body (text); None when the node closed the connection."""
        while True:
            if len(self.buf) >= HEADER:
                if self.buf[:4] != MAGIC:
                    raise ConnectionError("not a frame")
                (n,) = struct.unpack(">I", self.buf[8:HEADER])
                if len(self.buf) >= HEADER + n:
                    body, self.buf = self.buf[HEADER : HEADER + n], self.buf[HEADER + n :]
                    return body[:4096].decode("utf-8", "replace")
            chunk = self.sock.recv(65536)
            if not chunk:
                return None
            self.buf += chunk

    def close(self) -> None:
        self.sock.close()


def _frame(body: bytes) -> bytes:
    return frame_header(len(body)) + body


def reply_kind(reply: str | None) -> str:
    """``ok``, ``closed``, or the formal of an error reply (``existence_error``, ...)."""
    if reply is None:
        return "closed"
    if reply.startswith("ok("):
        return "ok"
    m = re.match(r"error\(error\(([a-z_]+)", reply)
    return m.group(1) if m else "other"


class AuthFrames:
    """``big`` threads sending text frames of ``big_size`` bytes (a post whose argument is one
    long string) and ``flood`` threads sending small posts as fast as replies come, each on an
    authenticated connection (a new one when the node closes it)."""

    def __init__(
        self, port: int, token: int, big: int, big_size: int, flood: int, max_s: float = 600.0
    ) -> None:
        if big < 0 or flood < 0 or big + flood < 1 or big_size < 64:
            raise ValueError("authframes needs big + flood >= 1 and a big size >= 64")
        self.port, self.token, self.max_s = port, token, max_s
        head, tail = b'post(nobody, x, x, ["', b'"]) .\n'
        self.big_frame = _frame(head + b"a" * (big_size - len(head) - len(tail)) + tail)
        self.small_frame = _frame(b"post(nobody, x, x, []) .\n")
        self.lock = threading.Lock()
        self.counts: dict[str, dict[str, int]] = {
            k: {"connections": 0, "connect_failed": 0, "sent": 0, "bytes_sent": 0}
            for k in ("big", "flood")
        }
        self.stopping = threading.Event()
        self.errors: list[str] = []
        self.threads = [
            threading.Thread(target=self._loop, args=("big",), daemon=True) for _ in range(big)
        ] + [
            threading.Thread(target=self._loop, args=("flood",), daemon=True) for _ in range(flood)
        ]

    def start(self) -> None:
        for t in self.threads:
            t.start()

    def stop(self) -> dict:
        self.stopping.set()
        for t in self.threads:
            t.join(timeout=60)
        if any(t.is_alive() for t in self.threads):
            raise RuntimeError("authenticated frame senders did not stop within 60 s")
        return {
            **self.counts,
            "big_frame_bytes": len(self.big_frame),
            "sender_errors": self.errors[:3],
        }

    def _count(self, kind: str, key: str, n: int = 1) -> None:
        with self.lock:
            c = self.counts[kind]
            c[key] = c.get(key, 0) + n

    def _loop(self, kind: str) -> None:
        data = self.big_frame if kind == "big" else self.small_frame
        end = time.monotonic() + self.max_s
        conn: _Conn | None = None
        while not self.stopping.is_set() and time.monotonic() < end:
            try:
                if conn is None:
                    conn = _Conn(self.port, self.token)
                    self._count(kind, "connections")
                conn.sock.sendall(data)
                self._count(kind, "sent")
                self._count(kind, "bytes_sent", len(data))
                reply = conn.read()
                self._count(kind, f"reply_{reply_kind(reply)}")
                if reply is None:
                    conn.close()
                    conn = None
            except (OSError, ConnectionError) as exc:
                self._count(kind, "connect_failed" if conn is None else "reset")
                if conn is not None:
                    conn.close()
                    conn = None
                if len(self.errors) < 3:
                    self.errors.append(repr(exc)[:200])
                self.stopping.wait(0.2)
        if conn is not None:
            conn.close()
