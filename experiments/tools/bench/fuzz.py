"""Mutated binary frames from an authenticated peer; the node must answer a ping after each one.

A target node (``hostile_node.pl target``, the platform's default limits, in its own ``swipl``
process on loopback) and this process as its peer. The valid frames are the bodies
``fuzz_seeds.pl`` prints (what ``fast_term_serialized/2`` makes of the requests an
authenticated peer sends, between them every opcode of the format). Each fuzzed frame is one
of them with 1-3 mutations (:data:`MUTATIONS`: bit flips, byte changes, truncation, a wrong
length in the header, inserted, deleted and duplicated bytes, a huge count written over a
varint) or, one frame in twenty, a nesting 5,000 to 100,000 deep written as a valid body. For
each frame: a new connection, the hello, a proof of the token, the frame, the end of the
connection's writing side (so that a body shorter than its header says ends as truncated),
the node's answer or the end of the connection; then a ``ping`` on a second authenticated
connection, kept open, which must be answered ``ok(pong(...))`` by the same process. A node
that dies (or stops answering) is a crash: it is recorded with the frame that did it and the
node is started again (up to ``max_crashes``), so a run counts crashes over its frames.

Every random choice comes from one ``random.Random(seed)``: a run is repeated with its seed.
``checkout`` runs the node of another checkout (say main's, as the control: there the fuzzer
must find the crash); ``native_check=False`` makes the node check bodies with the Prolog walk
of ``fast_term_check.pl`` (the platform without its C library).
"""

from __future__ import annotations

import hashlib
import hmac
import random
import re
import socket
import struct
import subprocess
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dfrl.experiments import processes
from dfrl.pybridge.codec import varint

HERE = Path(__file__).resolve().parent
TOKEN = "4243"
MAGIC = b"DFRL"
INTERESTING = (0, 1, 2, 3, 4, 6, 8, 9, 11, 12, 13, 14, 15, 16, 17, 18, 19, 0x7F, 0x80, 0xFF)
HUGE_VARINTS = (
    b"\xff" * 8 + b"\x7f",
    b"\x8f\xff\xff\xff\x7f",
    b"\x81\x80\x80\x80\x00",
    b"\x84\x00",
    b"\xff\xff\x7f",
)


@dataclass(frozen=True)
class FuzzConfig:
    """One run: how many frames, the seed (None: one is drawn and reported), the node."""

    frames: int = 20_000
    seed: int | None = None
    checkout: Path | None = None
    max_s: float = 3600.0
    reply_timeout_s: float = 5.0
    max_crashes: int = 20
    deep_every: int = 20
    native_check: bool = True


@dataclass
class FuzzResult:
    """What a run did; ``crashes`` lists each death with the frame that caused it."""

    seed: int
    checkout: str
    frames: int = 0
    seconds: float = 0.0
    replies: dict[str, int] = field(default_factory=dict)
    crashes: list[dict[str, Any]] = field(default_factory=list)
    first_crash_frame: int | None = None
    node_pids: list[int] = field(default_factory=list)
    pings: int = 0
    stopped_early: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data."""
        return asdict(self)


def frame(body: bytes, kind: bytes = b"B", length: int | None = None) -> bytes:
    """A frame holding ``body``; ``length`` overrides the header's length field."""
    n = len(body) if length is None else length
    return MAGIC + b"\x01" + kind + b"\0\0" + struct.pack(">I", n) + body


def seeds() -> list[tuple[str, bytes]]:
    """The valid bodies (name, bytes) that ``fuzz_seeds.pl`` prints."""
    out = subprocess.run(
        [processes.swipl(), "-q", str(HERE / "fuzz_seeds.pl")],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    ).stdout
    return [
        (name, bytes.fromhex(hexed))
        for name, hexed in (line.split() for line in out.splitlines() if line.strip())
    ]


def deep_body(rng: random.Random) -> tuple[bytes, str]:
    """A body nesting 5,000 to 100,000 levels (``f(f(...))`` or ``[[...]]``), valid as written,
    or with its cell count off by one."""
    depth = rng.choice((5_000, 10_000, 10_001, 50_000, 100_000))
    if rng.random() < 0.5:
        code = b"\x0d\x01\x0b\x01f" * depth + b"\x0b\x01a"
        cells = 2 * depth
        shape = "compound"
    else:
        code = b"\x08" * depth + b"\x09" * (depth + 1)
        cells = 3 * depth
        shape = "list"
    if rng.random() < 0.3:
        cells += rng.choice((-1, 1))
    return b"\x72" + varint(len(code)) + varint(cells) + code, f"deep_{shape}_{depth}"


def mutate(rng: random.Random, body: bytes) -> tuple[bytes, int | None, list[str]]:
    """``body`` with 1-3 mutations; the header length to send (None: the body's) and their names."""
    b = bytearray(body)
    length: int | None = None
    names = []
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        op = rng.choice(MUTATIONS)
        names.append(op)
        n = len(b)
        i = rng.randrange(n) if n else 0
        if op == "bitflip" and n:
            b[i] ^= 1 << rng.randrange(8)
        elif op == "byte" and n:
            b[i] = rng.choice(INTERESTING) if rng.random() < 0.6 else rng.randrange(256)
        elif op == "truncate" and n:
            keep = rng.randrange(n)
            if rng.random() < 0.5:
                length = n  # the header still says the whole body
            del b[keep:]
        elif op == "length":
            length = rng.choice(
                (
                    max(0, n - 1),
                    n + 1,
                    n + rng.randrange(1, 100),
                    0,
                    rng.randrange(n + 1),
                    2**32 - 1,
                    33_554_432,
                    33_554_433,
                )
            )
        elif op == "insert":
            b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 9)))
        elif op == "delete" and n:
            del b[i : i + rng.randrange(1, 9)]
        elif op == "duplicate" and n:
            j = rng.randrange(n)
            chunk = b[i : i + rng.randrange(1, 33)]
            b[j:j] = chunk
        elif op == "huge_count" and n:
            at = rng.choice((1, 2, 3, i)) if n > 3 else i
            b[at : at + 1] = rng.choice(HUGE_VARINTS)
    return bytes(b), length, names


MUTATIONS = ("bitflip", "byte", "truncate", "length", "insert", "delete", "duplicate", "huge_count")


#: A goal run before the target starts: fast_term_check.pl's Prolog walk instead of its C one.
PROLOG_CHECK = "fast_term_check:retractall(native(_)), assertz(fast_term_check:native(false))"


class _Node:
    """The target: ``hostile_node.pl target TOKEN`` of a checkout, its port and stderr tail."""

    def __init__(self, checkout: Path, native_check: bool = True) -> None:
        script = checkout / "experiments" / "tools" / "bench" / "hostile_node.pl"
        goal = [] if native_check else ["-g", PROLOG_CHECK]
        self.proc = processes.start(
            [processes.swipl(), "-q", *goal, str(script), "target", TOKEN],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        self.err: list[str] = []
        threading.Thread(target=self._drain_err, daemon=True).start()
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith("PORT"):
            self.stop()
            raise RuntimeError(f"target did not start: {''.join(self.err)[-2000:]}")
        self.port = int(line.split()[1])
        threading.Thread(target=self._drain_out, daemon=True).start()

    def _drain_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            if "ssert" in line or "pl-" in line or len(self.err) < 10:
                self.err = (self.err + [line])[-40:]

    def _drain_out(self) -> None:
        assert self.proc.stdout is not None
        for _ in self.proc.stdout:
            pass

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> None:
        if self.proc.stdin:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        processes.wait_or_stop(self.proc, 5.0)


def _read_exact(s: socket.socket, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        chunk = s.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


def _read_frame(s: socket.socket) -> bytes | None:
    header = _read_exact(s, 12)
    if header is None or header[:4] != MAGIC:
        return None
    (n,) = struct.unpack(">I", header[8:12])
    return _read_exact(s, n)


def _connect_auth(port: int, timeout: float) -> socket.socket:
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    try:
        hello = _read_frame(s)
        m = re.match(rb"hello\(\d+,'?([0-9a-f]+)'?,", hello or b"")
        if not m:
            raise ConnectionError(f"no hello: {hello!r}")
        proof = hmac.new(TOKEN.encode(), m.group(1), hashlib.sha256).hexdigest()
        s.sendall(frame(f"auth(['{proof}']) .\n".encode(), kind=b"T"))
        verdict = _read_frame(s)
        if not verdict or not verdict.startswith(b"ok(authenticated)"):
            raise ConnectionError(f"not authenticated: {verdict!r}")
    except BaseException:
        s.close()
        raise
    return s


def _reply_kind(reply: bytes | None) -> str:
    if reply is None:
        return "closed"
    m = re.search(rb"wire_error\(([a-z_]+)", reply)
    if m:
        return "wire_error:" + m.group(1).decode()
    if reply.startswith(b"error("):
        m = re.match(rb"error\(error\(([a-z_]+)", reply)
        return "error:" + (m.group(1).decode() if m else "other")
    return "ok" if reply.startswith(b"ok(") else "other"


def _send_fuzzed(port: int, data: bytes, timeout: float) -> str:
    """Send one frame on a fresh authenticated connection; the kind of answer it got."""
    with _connect_auth(port, timeout) as s:
        try:
            s.sendall(data)
            s.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # the node may close before all was sent
        try:
            return _reply_kind(_read_frame(s))
        except (TimeoutError, socket.timeout):
            return "no_answer"
        except OSError:
            return "reset"


class _Pinger:
    """An authenticated connection kept open for pings (opened again if the node closed it)."""

    def __init__(self, port: int, timeout: float) -> None:
        self.port, self.timeout = port, timeout
        self.sock: socket.socket | None = None

    def ping(self) -> bool:
        for _ in range(2):
            try:
                if self.sock is None:
                    self.sock = _connect_auth(self.port, self.timeout)
                self.sock.sendall(frame(b"ping .\n", kind=b"T"))
                reply = _read_frame(self.sock)
                if reply is not None and reply.startswith(b"ok(pong("):
                    return True
            except OSError:
                pass
            self.close()
        return False

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


def run(cfg: FuzzConfig = FuzzConfig(), progress: Any = None) -> FuzzResult:
    """Fuzz a target node with ``cfg.frames`` frames; see the module doc.

    Raises
    ------
    ExperimentError
        ``swipl`` is missing.
    RuntimeError
        The target did not start.
    """
    seed = cfg.seed if cfg.seed is not None else random.SystemRandom().randrange(2**32)
    rng = random.Random(seed)
    checkout = (cfg.checkout or HERE.parents[2]).resolve()
    valid = seeds()
    result = FuzzResult(seed=seed, checkout=str(checkout))
    node = _Node(checkout, cfg.native_check)
    result.node_pids.append(node.proc.pid)
    pinger = _Pinger(node.port, cfg.reply_timeout_s)
    t0 = time.monotonic()
    try:
        for k in range(1, cfg.frames + 1):
            if time.monotonic() - t0 > cfg.max_s:
                result.stopped_early = f"time limit {cfg.max_s:g} s"
                break
            if cfg.deep_every and rng.randrange(cfg.deep_every) == 0:
                body, name = deep_body(rng)
                data, names, seed_name = frame(body), [name], "deep"
            else:
                seed_name, body0 = rng.choice(valid)
                body, length, names = mutate(rng, body0)
                data = frame(body, length=length)
            try:
                kind = _send_fuzzed(node.port, data, cfg.reply_timeout_s)
            except OSError:
                kind = "connect_failed"
            result.frames = k
            result.replies[kind] = result.replies.get(kind, 0) + 1
            answered = pinger.ping()
            result.pings += 1
            if answered and node.alive():
                if progress and k % 1000 == 0:
                    progress(k, result)
                continue
            crash = {
                "frame": k,
                "seed_frame": seed_name,
                "mutations": names,
                "length": len(data) - 12,
                "frame_hex": data[:4096].hex(),
                "node_alive": node.alive(),
                "exit_code": node.proc.poll(),
                "stderr": "".join(node.err[:6])[-1500:],
            }
            result.crashes.append(crash)
            if result.first_crash_frame is None:
                result.first_crash_frame = k
            pinger.close()
            node.stop()
            if len(result.crashes) >= cfg.max_crashes:
                result.stopped_early = f"{cfg.max_crashes} crashes"
                break
            node = _Node(checkout, cfg.native_check)
            result.node_pids.append(node.proc.pid)
            pinger = _Pinger(node.port, cfg.reply_timeout_s)
    finally:
        result.seconds = round(time.monotonic() - t0, 2)
        pinger.close()
        node.stop()
    return result
