"""The README's cluster ("Running on a cluster") in network namespaces, shared by the tests of
this folder: its ``cluster:`` blocks read from experiments/README.md (:func:`cluster_blocks`)
and run word for word (:func:`cluster`): the token, the cluster certificates (one per worker
host, copied beside its token), the TLS scheduler in ``head``, a TLS worker in ``w1`` and
``w2``.

Needs root, ``ip`` and Dask distributed: :data:`WHY` says why not (None when it can run).
"""

from __future__ import annotations

import csv
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from dfrl.experiments.tools.netns import REPO_ROOT, Lab, leftover_namespaces, unavailable

try:
    import distributed  # noqa: F401

    ENGINE = None
except ImportError:
    ENGINE = "Dask distributed is not installed (pip install -e '.[cluster]'; scripts/test.sh does)"

WHY = unavailable() or ENGINE

README = REPO_ROOT / "experiments" / "README.md"
WORKERS = ["w1", "w2"]


def cluster_blocks() -> dict[str, tuple[str, str]]:
    """``<!-- cluster:KIND [ARG] -->`` markers of the README -> (ARG, the next fenced block)."""
    text = README.read_text(encoding="utf-8")
    found = {
        m.group(1): (m.group(2), m.group(3))
        for m in re.finditer(r"<!-- cluster:(\w+)\s*([^ ]*?)\s*-->\s*```\w*\n(.*?)```", text, re.S)
    }
    assert set(found) >= {"token", "certs", "scheduler", "worker", "config", "driver"}, found.keys()
    return found


def argv_of(line: str) -> list[str]:
    """A documented ``dfrl ...`` or ``dask ...`` command as an argv of this interpreter."""
    words = line.split()
    assert words[0] in ("dfrl", "dask"), line
    return [sys.executable, "-m", words[0], *words[1:]]


T0 = time.monotonic()


def phase(what: str) -> None:
    """A timestamped line on stderr (pytest shows it with a failure): where the time went."""
    print(f"[{time.monotonic() - T0:7.1f} s] {what}", file=sys.stderr, flush=True)


def wait_for(path: Path, pattern: str, timeout_s: float) -> None:
    """Until ``path`` holds ``pattern`` (bounded: ``timeout_s``)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.is_file() and pattern in path.read_text(encoding="utf-8", errors="replace"):
            return
        time.sleep(0.1)
    text = path.read_text(encoding="utf-8", errors="replace") if path.is_file() else ""
    raise AssertionError(f"no {pattern!r} in {path} within {timeout_s} s: {text[-2000:]}")


def flag(line: str, name: str) -> str:
    """The word after ``name`` in a documented command line."""
    words = line.split()
    assert name in words, (name, line)
    return words[words.index(name) + 1]


def run_certs(lab: Lab, drv: Path, blocks: dict) -> dict[str, Path]:
    """Run the README's ``cluster:certs`` block in ``drv`` (a line naming ``HOSTn`` once per
    worker host); the worker name -> the folder made for its host."""
    made: dict[str, Path] = {}
    for line in blocks["certs"][1].strip().splitlines():
        for w in WORKERS if "HOSTn" in line else [None]:
            cmd = line.replace("HOSTn", lab[w].address) if w else line
            done = lab["head"].run(argv_of(cmd), cwd=drv, capture_output=True, text=True)
            assert done.returncode == 0, (cmd, done.stderr)
            if w:
                made[w] = drv / flag(cmd, "--out")
    return made


@contextmanager
def cluster(
    tmp: Path, per_worker: int, others: tuple[str, ...] = ()
) -> Iterator[tuple[Lab, Path, dict]]:
    """The README's cluster in namespaces: token, cluster certificates, scheduler, workers
    offering ``per_worker`` CPUs (and hosts ``others`` with nothing started); yields the lab,
    the driver's folder and the blocks. The lab is gone afterwards."""
    blocks = cluster_blocks()
    with Lab(["head", *WORKERS, *others]) as lab:
        head = lab["head"].address
        drv = tmp / "head"
        drv.mkdir()
        cmd = blocks["token"][1].strip()
        made = lab["head"].run(argv_of(cmd), cwd=drv, capture_output=True, text=True)
        assert made.returncode == 0, made.stderr
        token = drv / cmd.split("--out", 1)[1].split()[0]
        member = run_certs(lab, drv, blocks)
        phase("token and certificates made")
        line = blocks["scheduler"][1].strip().replace("HEAD", head)
        lab["head"].popen(
            argv_of(line),
            cwd=drv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=open(drv / "scheduler.log", "w"),
        )
        wait_for(drv / "scheduler.log", "Scheduler at:", 60)
        phase("scheduler up")
        for w in WORKERS:
            cwd = tmp / w
            cwd.mkdir()
            shutil.copy2(token, cwd)  # scp -p: mode 0600 kept
            line = (
                blocks["worker"][1]
                .strip()
                .replace("HEAD", head)
                .replace("HOSTn", lab[w].address)
                .replace("=N", f"={per_worker}")
                .replace(" N ", f" {per_worker} ")
            )
            assert " N" not in line and "HOST" not in line, line
            shutil.copytree(member[w], cwd / Path(flag(line, "--tls-cert")).parent)  # scp -rp
            lab[w].popen(
                argv_of(line),
                cwd=cwd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=open(cwd / "worker.log", "w"),
            )
        for w in WORKERS:
            wait_for(tmp / w / "worker.log", "Registered to:", 60)
        phase("workers registered")
        yield lab, drv, blocks
        phase("closing the lab")
    phase("lab closed")
    assert not leftover_namespaces(lab.tag)


def driver_cmd(blocks: dict, lab: Lab) -> str:
    return blocks["driver"][1].strip().replace("HEAD", lab["head"].address)


def rounds_of(out: Path) -> list[dict[str, str]]:
    with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def logs_of(tmp_path: Path) -> str:
    """The workers' logs and the services' stderr tails (what a failed check shows)."""
    parts = []
    for f in sorted(tmp_path.glob("w*/worker.log")) + sorted(
        tmp_path.glob("w*/dfrl-robot/*/service-*")
    ):
        parts.append(f"--- {f.relative_to(tmp_path)}\n{f.read_text(errors='replace')[-1500:]}")
    return "\n".join(parts)
