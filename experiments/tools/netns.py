"""Simulated hosts for tests and benchmarks: Linux network namespaces on a private bridge.

:class:`Lab` creates one namespace holding a bridge and N host namespaces, each joined to the
bridge by a veth pair and given an address in ``10.200.<lab>.0/24``. Nothing is attached to
the machine's own namespace: the hosts reach each other and nothing else, and every address a
test uses is one the lab made. ``close()`` (or leaving the ``with`` block) kills what was
started in the hosts and deletes every namespace, which removes the veths and the bridge.

Needs root (CAP_NET_ADMIN) and ``ip``; :func:`unavailable` says why not, for ``pytest.skip``.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

SUBNET_PREFIX = "10.200"


def unavailable() -> str | None:
    """Why namespaces cannot be made here (None when they can)."""
    if shutil.which("ip") is None:
        return "the 'ip' command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "creating network namespaces needs root"
    probe = f"dfrl-probe-{os.getpid()}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def _ip(*args: str, ns: str | None = None) -> None:
    cmd = ["ip", *(["-n", ns] if ns else []), *args]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: {done.stderr.strip()}")


@dataclass
class Host:
    """One simulated host: a namespace with one interface on the lab's bridge."""

    name: str
    namespace: str
    address: str
    link: str                    #: the veth end on the bridge (cut it to cut the host off)
    procs: list[subprocess.Popen] = field(default_factory=list)

    def command(self, argv: list[str]) -> list[str]:
        """``argv`` run inside this host."""
        return ["ip", "netns", "exec", self.namespace, *argv]

    def popen(self, argv: list[str], **kwargs) -> subprocess.Popen:  # noqa: ANN003
        """Start ``argv`` inside this host; it is killed when the lab closes."""
        proc = subprocess.Popen(self.command(argv), **kwargs)
        self.procs.append(proc)
        return proc

    def run(self, argv: list[str], timeout: float = 60.0, **kwargs) -> subprocess.CompletedProcess:  # noqa: ANN003
        return subprocess.run(self.command(argv), timeout=timeout, **kwargs)


class Lab:
    """N hosts on one bridge; see the module doc.

    Parameters
    ----------
    hosts : list of str
        Host names (also the last part of their namespace names).
    lab_id : int
        Third octet of the subnet, so that labs of parallel test runs do not share one.
    """

    def __init__(self, hosts: list[str], lab_id: int | None = None) -> None:
        self.tag = f"dfrl{os.getpid() % 100000}"
        self.lab_id = (os.getpid() % 200) + 1 if lab_id is None else lab_id
        self.bridge_ns = f"{self.tag}-br"
        self.hosts: dict[str, Host] = {}
        self._made: list[str] = []
        try:
            self._make(hosts)
        except BaseException:
            self.close()
            raise

    def _make(self, names: list[str]) -> None:
        _ip("netns", "add", self.bridge_ns)
        self._made.append(self.bridge_ns)
        _ip("link", "add", "br0", "type", "bridge", ns=self.bridge_ns)
        _ip("link", "set", "br0", "up", ns=self.bridge_ns)
        for i, name in enumerate(names):
            ns = f"{self.tag}-{name}"
            _ip("netns", "add", ns)
            self._made.append(ns)
            link = f"v{i}"
            # both ends are created inside the bridge namespace, then one moves to the host
            _ip("link", "add", link, "type", "veth", "peer", "name", "eth0", ns=self.bridge_ns)
            _ip("link", "set", "eth0", "netns", ns, ns=self.bridge_ns)
            _ip("link", "set", link, "master", "br0", ns=self.bridge_ns)
            _ip("link", "set", link, "up", ns=self.bridge_ns)
            address = f"{SUBNET_PREFIX}.{self.lab_id}.{i + 1}"
            _ip("addr", "add", f"{address}/24", "dev", "eth0", ns=ns)
            _ip("link", "set", "eth0", "up", ns=ns)
            _ip("link", "set", "lo", "up", ns=ns)
            self.hosts[name] = Host(name, ns, address, link)

    def __enter__(self) -> "Lab":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __getitem__(self, name: str) -> Host:
        return self.hosts[name]

    def cut(self, name: str) -> None:
        """Cut host ``name`` off the bridge (its processes keep running)."""
        _ip("link", "set", self.hosts[name].link, "down", ns=self.bridge_ns)

    def mend(self, name: str) -> None:
        """Reconnect a host cut off by :meth:`cut`."""
        _ip("link", "set", self.hosts[name].link, "up", ns=self.bridge_ns)

    def kill(self, name: str) -> int:
        """kill -9 every process in host ``name`` (the host dies; its namespace and link stay,
        so it can be started again); return how many were killed."""
        pids = _pids_in(self.hosts[name].namespace)
        for pid in pids:
            try:
                os.kill(pid, 9)
            except ProcessLookupError:
                pass
        return len(pids)

    def close(self) -> None:
        """Kill every process started in a host, then delete every namespace."""
        for host in self.hosts.values():
            for proc in host.procs:
                if proc.poll() is None:
                    proc.kill()
            for proc in host.procs:
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    pass
        # processes started by hand with `ip netns exec` die with their namespace's last user
        for ns in reversed(self._made):
            for pid in _pids_in(ns):
                try:
                    os.kill(pid, 9)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                if subprocess.run(["ip", "netns", "del", ns], capture_output=True).returncode == 0:
                    break
                time.sleep(0.1)
        self._made.clear()


def _pids_in(ns: str) -> list[int]:
    done = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True)
    return [int(p) for p in done.stdout.split()] if done.returncode == 0 else []


def leftover_namespaces(prefix: str = "dfrl") -> list[str]:
    """Namespaces whose names start with ``prefix`` (a test checks it left none)."""
    done = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True)
    return [line.split()[0] for line in done.stdout.splitlines()
            if line.strip().startswith(prefix)]


REPO_ROOT = Path(__file__).resolve().parents[2]
