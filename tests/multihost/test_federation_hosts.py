"""A federation across hosts, following experiments/README.md "Running across machines" word
for word: three robot hosts in network namespaces, each running the section's ``dfrl robot``
command, and the driver in a fourth namespace running its ``dfrl run`` command on its config.
Every round must visit every host and leave identical tables, and every result file must
have come back to the driver over the platform.

Runs in CI (as root); skipped with the reason where namespaces cannot be made.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from dfrl.experiments.tools.netns import REPO_ROOT, Lab, leftover_namespaces, unavailable

WHY = unavailable()
pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")

README = REPO_ROOT / "experiments" / "README.md"
ROBOT_HOSTS = ["h1", "h2", "h3"]


def section_blocks(text: str) -> dict[str, tuple[str, str]]:
    """``<!-- multihost:KIND [ARG] -->`` markers of the README section -> (ARG, the next fenced
    block's text)."""
    blocks = {}
    for m in re.finditer(r"<!-- multihost:(\w+)\s*([^ ]*?)\s*-->\s*```\w*\n(.*?)```", text, re.S):
        blocks[m.group(1)] = (m.group(2), m.group(3))
    return blocks


def argv_of(line: str) -> list[str]:
    """A documented ``dfrl ...`` command as an argv of this interpreter's ``dfrl``."""
    words = line.split()
    assert words[0] == "dfrl", line
    return [sys.executable, "-m", "dfrl", *words[1:]]


def drive_and_check(
    lab: Lab, drv: Path, config_name: str, cfg: str, driver_cmd: str
) -> tuple[Path, list[str]]:
    """Write the config, run the README's driver command in the driver's namespace and check
    what every recipe promises: exit 0, every planned round visiting every robot with no skip
    and identical tables, every robot's files back over the platform. Returns the results
    folder and the robot ids."""
    (drv / config_name).write_text(cfg, encoding="utf-8")
    done = lab["driver"].run(
        argv_of(driver_cmd), cwd=drv, timeout=180, capture_output=True, text=True
    )
    out = drv / driver_cmd.split("--out", 1)[1].split()[0]
    detail = f"exit {done.returncode}\n{done.stderr[-3000:]}"
    assert done.returncode == 0, detail
    assert done.stdout.strip().endswith(str(out.name)), detail
    with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    planned = json.loads(cfg)
    n_rounds = -(-planned["iterations"] // planned["respite"])
    robots = [r["id"] for r in planned["robots"]]
    assert len(rows) == n_rounds, detail
    for row in rows:
        assert row["visited"].split() == robots, row
        assert row["skipped"] == "", row
        assert row["all_equal"] == "true", row
        assert len({row[f"digest_{r}"] for r in robots}) == 1, row
    # the robots wrote their files under their own workdirs, never into the driver's folder
    for r in robots:
        assert (out / f"metrics_{r}.csv").stat().st_size > 0
        assert (out / f"shares_{r}.csv").is_file()
        assert (out / "tables" / f"{r}.npy").is_file()
    return out, robots


def make_token_file(lab: Lab, drv: Path, blocks: dict[str, tuple[str, str]]) -> Path:
    """Run the section's token command on the driver's host, in ``drv``; its token file
    (mode 0600, as every host gets a copy of it)."""
    cmd = blocks["token"][1].strip()
    made = lab["driver"].run(argv_of(cmd), cwd=drv, timeout=60, capture_output=True, text=True)
    assert made.returncode == 0, f"{cmd}: {made.stderr}"
    path = drv / cmd.split("--out", 1)[1].split()[0]
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    return path


def start_readme_robots(
    lab: Lab, tmp: Path, hosts: tuple[str, ...] | list[str], token: int
) -> None:
    """On each of ``hosts``, the README's ``dfrl robot`` command in its own folder ``tmp/<host>``
    with the README's token file (``token``), waited for until it listens."""
    from dfrl.experiments.tokens import write_secret_file

    robot_cmd = section_blocks(README.read_text(encoding="utf-8"))["robot"][1].strip()
    for h in hosts:
        (tmp / h).mkdir()
        write_secret_file(tmp / h / "dfrl.token", [token])
        proc = lab[h].popen(
            argv_of(robot_cmd.replace("HOSTn", lab[h].address)),
            cwd=tmp / h,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        wait_line(proc, "dfrl robot listening on", 60)


def wait_line(proc: subprocess.Popen, pattern: str, timeout_s: float) -> str:
    """The first stdout line of ``proc`` containing ``pattern``, read in a thread (bounded)."""
    found: list[str] = []
    seen: list[str] = []

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            seen.append(line)
            if pattern in line:
                found.append(line)
                return

    t = threading.Thread(target=read, daemon=True)
    t.start()
    t.join(timeout_s)
    if not found:
        raise AssertionError(
            f"no {pattern!r} within {timeout_s} s (exit {proc.poll()}): {''.join(seen)[-2000:]}"
        )
    return found[0]


def test_the_documented_lan_setup_federates_three_hosts(tmp_path: Path) -> None:
    blocks = section_blocks(README.read_text(encoding="utf-8"))
    assert set(blocks) >= {"token", "robot", "config", "driver"}, "README section markers missing"
    robot_cmd = blocks["robot"][1].strip()
    config_name, config_text = blocks["config"]
    driver_cmd = blocks["driver"][1].strip()

    t0 = time.monotonic()
    with Lab(ROBOT_HOSTS + ["driver"]) as lab:
        addresses = {f"HOST{i + 1}": lab[h].address for i, h in enumerate(ROBOT_HOSTS)}
        drv = tmp_path / "driver"
        drv.mkdir()
        token_file = make_token_file(lab, drv, blocks)
        for i, h in enumerate(ROBOT_HOSTS):
            cwd = tmp_path / h
            cwd.mkdir()
            shutil.copy2(token_file, cwd)  # scp -p: mode 0600 kept
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
        cfg = config_text
        for key, addr in addresses.items():
            cfg = cfg.replace(key, addr)
        out, robots = drive_and_check(lab, drv, config_name, cfg, driver_cmd)
        metrics = (out / "metrics.csv").read_text(encoding="utf-8").splitlines()
        assert {ln.split(",")[0] for ln in metrics[1:]} == set(robots)
        summary = (out / "summary.md").read_text(encoding="utf-8")
        assert "federation complete" in summary, summary
        # the agent's round log reached the driver through its console node, not through the
        # file system the namespaces share: no robot fell back to writing it locally
        for h in ROBOT_HOSTS:
            for log in (tmp_path / h).rglob("*.err"):
                assert "round log to console" not in log.read_text(encoding="utf-8"), log
        launch = json.loads(next(out.glob("launch_*.json")).read_text(encoding="utf-8"))
        assert launch["log_to"][0] == lab["driver"].address
        tag = lab.tag
    assert not leftover_namespaces(tag)
    assert time.monotonic() - t0 < 120
