"""A federation across hosts over mutual TLS, following experiments/README.md "Across machines
over TLS" word for word: the certificates made on the driver's host with the section's
``dfrl certs`` commands and each robot host's folder copied to it, three robot hosts in network
namespaces each running the section's ``dfrl robot --tls`` command, and the driver in a fourth
namespace running its ``dfrl run --tls`` command on its config. Every round must visit every
host and leave identical tables, the result files must have come back over the platform, and
a plaintext peer must be refused by a TLS robot node inside the namespaces.

Runs in CI (as root); skipped with the reason where namespaces cannot be made.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from dfrl.experiments.tools.netns import REPO_ROOT, Lab, leftover_namespaces, unavailable
from .test_federation_hosts import (
    argv_of,
    drive_and_check,
    make_token_file,
    section_blocks,
    wait_line,
)

WHY = unavailable() or (None if shutil.which("openssl") else "the openssl command is missing")
pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")

README = REPO_ROOT / "experiments" / "README.md"
ROBOT_HOSTS = ["h1", "h2", "h3"]

#: A plaintext platform client: connect, send a ping frame, print what came back (as hex) until
#: the node closes or 10 s pass. Run inside the driver's namespace.
PLAINTEXT_PEER = textwrap.dedent("""
    import json, socket, sys, time
    sys.path.insert(0, sys.argv[3])
    from tests.platform.wire_client import frame
    s = socket.create_connection((sys.argv[1], int(sys.argv[2])), timeout=10)
    s.sendall(frame(b"ping .\\n"))
    data, t0, closed = b"", time.monotonic(), False
    while not closed and time.monotonic() - t0 < 10:
        try:
            chunk = s.recv(4096)
        except ConnectionResetError:
            chunk = b""
        except TimeoutError:
            break
        closed = not chunk
        data += chunk
    print(json.dumps({"hex": data.hex(), "closed": closed}))
""")


def tls_blocks(text: str) -> dict[str, tuple[str, str]]:
    """``<!-- multihost-tls:KIND [ARG] -->`` markers -> (ARG, the next fenced block's text)."""
    blocks = {}
    for m in re.finditer(
        r"<!-- multihost-tls:(\w+)\s*([^ ]*?)\s*-->\s*```\w*\n(.*?)```", text, re.S
    ):
        blocks[m.group(1)] = (m.group(2), m.group(3))
    return blocks


def test_the_documented_tls_lan_setup_federates_three_hosts(tmp_path: Path) -> None:
    blocks = tls_blocks(README.read_text(encoding="utf-8"))
    assert set(blocks) >= {"certs", "robot", "config", "driver"}, "README TLS markers missing"
    cert_lines = blocks["certs"][1].strip().splitlines()
    robot_cmd = blocks["robot"][1].strip()
    config_name, config_text = blocks["config"]
    driver_cmd = blocks["driver"][1].strip()
    assert "--tls" in robot_cmd and "--tls" in driver_cmd

    t0 = time.monotonic()
    with Lab(ROBOT_HOSTS + ["driver"]) as lab:
        drv = tmp_path / "driver"
        drv.mkdir()
        token_file = make_token_file(lab, drv, section_blocks(README.read_text(encoding="utf-8")))
        # 1. certificates, made on the driver's host; the HOSTn line once per robot host
        for line in cert_lines:
            targets = [lab[h].address for h in ROBOT_HOSTS] if "HOSTn" in line else [None]
            for addr in targets:
                cmd = line.replace("HOSTn", addr) if addr else line
                made = lab["driver"].run(
                    argv_of(cmd), cwd=drv, timeout=60, capture_output=True, text=True
                )
                assert made.returncode == 0, f"{cmd}: {made.stderr}"
        # ... and each robot host's folder copied to it
        for h in ROBOT_HOSTS:
            (tmp_path / h).mkdir()
            folder = f"tls-{lab[h].address}"
            shutil.copytree(drv / folder, tmp_path / h / folder)
            shutil.copy2(token_file, tmp_path / h)
        # 2. the robot services
        for h in ROBOT_HOSTS:
            cwd = tmp_path / h
            line = robot_cmd.replace("HOSTn", lab[h].address)
            proc = lab[h].popen(
                argv_of(line),
                cwd=cwd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=open(cwd / "robot.err", "w"),
                text=True,
            )
            said = wait_line(proc, "dfrl robot listening on", 60)
            assert f"{lab[h].address}:7001" in said, said
        # a plaintext peer is refused by a TLS robot node: no hello, no pong, closed
        peer = lab["driver"].run(
            [sys.executable, "-c", PLAINTEXT_PEER, lab["h1"].address, "7001", str(REPO_ROOT)],
            timeout=30,
            capture_output=True,
            text=True,
        )
        assert peer.returncode == 0, peer.stderr
        seen = json.loads(peer.stdout)
        got = bytes.fromhex(seen["hex"])
        assert b"DFRL" not in got and b"pong" not in got and b"hello" not in got, got
        assert seen["closed"], "the TLS robot node kept a plaintext peer's connection open"
        # 3. the config, 4. the run
        cfg = config_text
        for i, h in enumerate(ROBOT_HOSTS):
            cfg = cfg.replace(f"HOST{i + 1}", lab[h].address)
        out, robots = drive_and_check(lab, drv, config_name, cfg, driver_cmd)
        summary = (out / "summary.md").read_text(encoding="utf-8")
        assert "federation complete" in summary, summary
        nodes = json.loads((out / "nodes.json").read_text(encoding="utf-8"))
        assert nodes["tls"] == str((drv / "tls-driver").resolve())
        launch = json.loads(next(out.glob("launch_*.json")).read_text(encoding="utf-8"))
        assert launch["log_to"][0] == lab["driver"].address
        for h in ROBOT_HOSTS:
            for log in (tmp_path / h).rglob("*.err"):
                text = log.read_text(encoding="utf-8")
                assert "round log to console" not in text, log
        tag = lab.tag
    assert not leftover_namespaces(tag)
    assert time.monotonic() - t0 < 150
