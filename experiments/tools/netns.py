"""Simulated hosts for tests and benchmarks: Linux network namespaces on a private bridge.

:class:`Lab` creates one namespace holding a bridge and N host namespaces, each joined to the
bridge by a veth pair and given an address in ``10.200.<lab>.0/24``. Nothing is attached to
the machine's own namespace: the hosts reach each other and nothing else, and every address a
test uses is one the lab made. ``close()`` (or leaving the ``with`` block) kills what was
started in the hosts and deletes every namespace, which removes the veths and the bridge.

With ``private=DIR`` every host also gets a mount namespace of its own with a private tmpfs
mounted over ``DIR``: what a host writes under ``DIR`` exists only in that host (no shared
disk between hosts, nor with the process that made the lab, which sees its own ``DIR``). The
mount namespace is held by a keeper process (``unshare --mount ... sleep``) that lives in the
machine's network namespace, so that ``kill`` of a host (its network namespace's processes)
leaves its disk as a killed machine's disk stays: a restarted host finds its files. Every
command of a host enters it (``ip netns exec NS nsenter -t KEEPER -m env -C CWD ...``; the
working directory is taken after entering, so it is a path of the host's own disk), and
:meth:`Host.view` gives the path under which the process that made the lab reads and writes a
host's file (``/proc/KEEPER/root/...``, as root): that is how a benchmark copies a host's files
out, never through a shared folder.

Needs root (CAP_NET_ADMIN) and ``ip``; :func:`unavailable` says why not, for ``pytest.skip``.
Private disks need ``unshare``, ``nsenter`` and ``env -C`` (util-linux, coreutils).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

SUBNET_PREFIX = "10.200"
#: the longest a host's disk (its keeper process) lives; the lab kills it when it closes
KEEPER_S = 6 * 3600


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
    link: str  #: the veth end on the bridge (cut it to cut the host off)
    procs: list[subprocess.Popen] = field(default_factory=list)
    #: the process holding this host's mount namespace (None: the host shares the disk)
    keeper: subprocess.Popen | None = None

    def command(self, argv: list[str], cwd: str | Path | None = None) -> list[str]:
        """``argv`` run inside this host, from ``cwd`` (a path as this host sees it)."""
        if self.keeper is None:
            return ["ip", "netns", "exec", self.namespace, *argv]
        return [
            "ip",
            "netns",
            "exec",
            self.namespace,
            "nsenter",
            "-t",
            str(self.keeper.pid),
            "-m",
            "env",
            "-C",
            str(cwd if cwd is not None else "/"),
            *argv,
        ]

    def view(self, path: str | Path) -> Path:
        """Where the lab's maker reads and writes this host's ``path`` (absolute)."""
        path = Path(path)
        if self.keeper is None:
            return path
        return Path(f"/proc/{self.keeper.pid}/root") / path.relative_to("/")

    def popen(self, argv: list[str], cwd: str | Path | None = None, **kwargs) -> subprocess.Popen:  # noqa: ANN003
        """Start ``argv`` inside this host, from ``cwd`` (this host's path); it is killed when
        the lab closes."""
        cmd, here = self._args(argv, cwd)
        proc = subprocess.Popen(cmd, cwd=here, **kwargs)
        self.procs.append(proc)
        return proc

    def run(
        self, argv: list[str], timeout: float = 60.0, cwd: str | Path | None = None, **kwargs
    ) -> subprocess.CompletedProcess:  # noqa: ANN003
        """Run ``argv`` inside this host, from ``cwd`` (this host's path), bounded."""
        cmd, here = self._args(argv, cwd)
        return subprocess.run(cmd, cwd=here, timeout=timeout, **kwargs)

    def _args(self, argv: list[str], cwd: str | Path | None) -> tuple[list[str], str | Path | None]:
        """The command and the working directory to start it from (this process's view: a
        host with a disk of its own takes its working directory after entering it)."""
        if self.keeper is None:
            return self.command(argv), cwd
        return self.command(argv, cwd), None


class Lab:
    """N hosts on one bridge; see the module doc.

    Parameters
    ----------
    hosts : list of str
        Host names (also the last part of their namespace names).
    lab_id : int
        Third octet of the subnet, so that labs of parallel test runs do not share one.
    private : Path, optional
        A folder (absolute, existing) that each host sees as a tmpfs of its own (see the
        module doc); None: the hosts share the machine's disk.
    """

    def __init__(
        self, hosts: list[str], lab_id: int | None = None, private: Path | None = None
    ) -> None:
        self.tag = f"dfrl{os.getpid() % 100000}"
        self.lab_id = (os.getpid() % 200) + 1 if lab_id is None else lab_id
        self.bridge_ns = f"{self.tag}-br"
        self.hosts: dict[str, Host] = {}
        self._made: list[str] = []
        try:
            self._make(hosts)
            if private is not None:
                for host in self.hosts.values():
                    self._give_disk(host, Path(private))
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

    def _give_disk(self, host: Host, private: Path) -> None:
        """A mount namespace for ``host`` with a tmpfs of its own over ``private``."""
        if not private.is_absolute() or not private.is_dir():
            raise ValueError(f"private must be an existing absolute folder, got {private}")
        keeper = subprocess.Popen(
            ["unshare", "--mount", "--propagation", "private", "--", "sleep", str(KEEPER_S)],
            stdin=subprocess.DEVNULL,
        )
        host.keeper = keeper
        mine = os.readlink("/proc/self/ns/mnt")
        deadline = time.monotonic() + 10
        while True:  # until unshare has made the namespace (then it execs sleep)
            try:
                if os.readlink(f"/proc/{keeper.pid}/ns/mnt") != mine:
                    break
            except OSError:
                pass
            if keeper.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"unshare --mount for {host.name} failed (exit {keeper.poll()})")
            time.sleep(0.01)
        done = subprocess.run(
            [
                "nsenter",
                "-t",
                str(keeper.pid),
                "-m",
                "mount",
                "-t",
                "tmpfs",
                "-o",
                "mode=0755",
                f"dfrl-{host.name}",
                str(private),
            ],
            capture_output=True,
            text=True,
            timeout=30,
        )
        if done.returncode != 0:
            raise RuntimeError(f"tmpfs for {host.name} over {private}: {done.stderr.strip()}")

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
        # the hosts' disks go with their keepers (the last process of each mount namespace)
        for host in self.hosts.values():
            if host.keeper is not None and host.keeper.poll() is None:
                host.keeper.kill()
                try:
                    host.keeper.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    pass


def _pids_in(ns: str) -> list[int]:
    done = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True)
    return [int(p) for p in done.stdout.split()] if done.returncode == 0 else []


def leftover_namespaces(prefix: str = "dfrl") -> list[str]:
    """Namespaces whose names start with ``prefix`` (a test checks it left none)."""
    done = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True)
    return [line.split()[0] for line in done.stdout.splitlines() if line.strip().startswith(prefix)]


REPO_ROOT = Path(__file__).resolve().parents[2]
