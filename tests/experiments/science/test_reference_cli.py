"""``dfrl reference``: builds into the cache folder, loads it back, exit codes."""

from __future__ import annotations

import json

import pytest

from dfrl.experiments.cli import main


def test_dfrl_reference_builds_loads_and_refuses(
    tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = [
        "reference",
        "--arena",
        "r1",
        "--iterations",
        "500",
        "--seeds",
        "2",
        "1",
        "--cache",
        str(tmp_path),
    ]
    assert main([*args, "--json"]) == 0
    built = json.loads(capsys.readouterr().out)
    assert built["cached"] is False and built["seeds"] == [1, 2]  # recorded sorted
    assert built["path"].startswith(str(tmp_path / "r1-qlearning-500x2-"))
    assert main(args) == 0  # the same recipe: loaded
    assert "loaded and verified" in capsys.readouterr().out
    q = next(tmp_path.glob("*.q.npy"))
    data = q.read_bytes()
    q.write_bytes(data[:-1] + bytes([data[-1] ^ 0xFF]))
    assert main(args) == 1
    assert f"{q}: sha256" in capsys.readouterr().err
    assert main(["reference", "--seeds", "5", "--cache", str(tmp_path)]) == 2  # ambiguous
    assert main(["reference", "--algo", "dqn", "--seed", "1", "--cache", str(tmp_path)]) == 2
