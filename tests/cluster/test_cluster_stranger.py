"""What a stranger gets from the README's cluster ("Running on a cluster", started word for
word in namespaces by readme_cluster.py): nothing. A process on a fourth host ``x``, holding
no certificate of the cluster CA, tries the scheduler, every worker and every nanny:

* a plain ``distributed.Client("tls://HEAD:8786")``; a Client speaking TLS without a
  certificate; a Client with a certificate of ANOTHER CA, and one with a node certificate of
  the project CA (the cluster has a CA of its own), both trusting the cluster CA so that the
  server is the one that refuses; a plain ``Client("tcp://HEAD:8786")``;
* a raw connection speaking Dask's plaintext protocol (``identity``) to every port the
  cluster listens on outside loopback, and one speaking TLS without a certificate;
* the dashboard's port 8787.

None may list the workers, run a task or get an answer. The control: the same client code,
from the same host, with the driver's cluster folder lists both workers and runs a task (which
sees ``dfrl.token``: what a member can do), and the same raw ``identity`` with that
certificate is answered by every port. The listeners, read with ``ss -ltn`` in each host: the
scheduler and each worker and nanny on their host's address, every HTTP server on 127.0.0.1,
nothing on a wildcard address.

The refusal of ``dfrl run --cluster tcp://...`` off loopback is
test_cluster_access.py (no namespaces).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from dfrl.experiments.tools.netns import Lab

from .readme_cluster import WHY, WORKERS, argv_of, cluster, flag, phase

pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")

PROBE = Path(__file__).with_name("stranger_probe.py")


def listeners(lab: Lab, host: str) -> list[str]:
    """``ADDRESS:PORT`` of every TCP listener in ``host`` (``ss -ltnH``)."""
    done = lab[host].run(["ss", "-ltnH"], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    return [line.split()[3] for line in done.stdout.splitlines() if line.strip()]


def on_loopback(listener: str) -> bool:
    return listener.startswith("127.") or listener.startswith("[::1]")


def probe(lab: Lab, cwd: Path, attempts: list[dict]) -> dict[str, dict]:
    """Run :mod:`stranger_probe` in host ``x``; label -> its result."""
    done = lab["x"].run(
        [sys.executable, str(PROBE), json.dumps(attempts)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    results = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert [r["label"] for r in results] == [a["label"] for a in attempts], done.stdout
    return {r["label"]: r for r in results}


def dfrl_certs(lab: Lab, cwd: Path, *args: str) -> None:
    done = lab["x"].run(
        argv_of("dfrl certs " + " ".join(args)), cwd=cwd, capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr


def test_a_stranger_can_neither_list_workers_nor_run_a_task(tmp_path: Path) -> None:
    with cluster(tmp_path, 1, others=("x",)) as (lab, drv, blocks):
        head = lab["head"].address
        # the listeners: the cluster's own on its hosts' addresses, HTTP on loopback only
        found = {h: listeners(lab, h) for h in ["head", *WORKERS]}
        phase(f"listeners: {found}")
        outside = {h: [a for a in ls if not on_loopback(a)] for h, ls in found.items()}
        assert outside["head"] == [f"{head}:8786"], found
        for w in WORKERS:
            assert len(outside[w]) == 2, found  # the worker, its nanny
            assert all(a.rsplit(":", 1)[0] == lab[w].address for a in outside[w]), found
        for h, ls in found.items():
            assert any(on_loopback(a) for a in ls), (h, found)  # HTTP moved, not gone
        # the stranger's host, with what a stranger may hold: the cluster CA's certificate
        # (public), and certificates of another CA and of the project CA's nodes
        x = tmp_path / "x"
        x.mkdir()
        dfrl_certs(lab, x, "init", "other")
        dfrl_certs(lab, x, "cluster", "stranger", "other", "--out", "other-ca")
        member = drv / flag(blocks["driver"][1], "--cluster-tls")
        node = drv / "node-stranger"
        done = lab["head"].run(
            argv_of(f"dfrl certs node stranger ca --out {node}"),
            cwd=drv,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
        ca = str(member / "ca.crt")
        certs = {
            "member": {
                "ca": ca,
                "cert": str(member / "cluster.crt"),
                "key": str(member / "cluster.key"),
            },
            "other CA": {
                "ca": ca,
                "cert": str(x / "other-ca" / "cluster.crt"),
                "key": str(x / "other-ca" / "cluster.key"),
            },
            "project CA node": {
                "ca": ca,
                "cert": str(node / "node.crt"),
                "key": str(node / "node.key"),
            },
        }
        scheduler = f"tls://{head}:8786"
        strangers = [
            {"label": "plain Client", "kind": "client", "address": scheduler, "tls": None},
            {
                "label": "Client, TLS without certificate",
                "kind": "client",
                "address": scheduler,
                "tls": "none",
            },
            {
                "label": "Client, other CA",
                "kind": "client",
                "address": scheduler,
                "tls": certs["other CA"],
            },
            {
                "label": "Client, project CA node",
                "kind": "client",
                "address": scheduler,
                "tls": certs["project CA node"],
            },
            {
                "label": "Client, plaintext",
                "kind": "client",
                "address": f"tcp://{head}:8786",
                "tls": None,
            },
            {"label": "dashboard port", "kind": "http", "address": f"{head}:8787", "tls": None},
        ]
        ports = [a for h in ["head", *WORKERS] for a in outside[h]]
        for a in ports:
            strangers += [
                {
                    "label": f"{a} plaintext",
                    "kind": "identity",
                    "address": f"tcp://{a}",
                    "tls": None,
                },
                {
                    "label": f"{a} without certificate",
                    "kind": "identity",
                    "address": f"tls://{a}",
                    "tls": "none",
                },
                {
                    "label": f"{a} other CA",
                    "kind": "identity",
                    "address": f"tls://{a}",
                    "tls": certs["other CA"],
                },
            ]
        controls = [
            {
                "label": "Client, member",
                "kind": "client",
                "address": scheduler,
                "tls": certs["member"],
            }
        ]
        controls += [
            {
                "label": f"{a} member",
                "kind": "identity",
                "address": f"tls://{a}",
                "tls": certs["member"],
            }
            for a in ports
        ]
        got = probe(lab, x, strangers + controls)
        report = "\n".join(
            f"{'GOT' if r['ok'] else 'refused'}: {label}: {r['detail'][:160]}"
            for label, r in got.items()
        )
        phase(f"probed:\n{report}")
        for s in strangers:
            assert not got[s["label"]]["ok"], report
        for c in controls:
            assert got[c["label"]]["ok"], report
        control = json.loads(got["Client, member"]["detail"])
        assert control["workers"] == len(WORKERS), report
        assert control["task"]["token_there"], report  # a member reads the token
        assert Path(control["task"]["cwd"]).name in WORKERS, report
