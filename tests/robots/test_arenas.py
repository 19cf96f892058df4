"""Arena files: the shipped ones load, bad ones are rejected with clear messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from dfrl.arenas import (
    HELD_OUT_ARENAS,
    PAPER_ARENAS,
    ArenaError,
    build_arena,
    builtin_arena_names,
    load_arena,
    parse_arena,
)


def _good() -> dict:
    return {
        "name": "mine",
        "size": [1.0, 0.8],
        "wall_height": 0.1,
        "blocks": [{"center": [0.2, 0.1], "size": [0.1, 0.2, 0.1], "yaw": 0.3}],
        "start": {"pose": [-0.3, -0.2, 0.0]},
    }


def test_paper_arenas_ship_with_their_block_counts() -> None:
    assert builtin_arena_names() == ["h1", "h2", "r1", "r2", "r3", "r4", "r5"]
    assert PAPER_ARENAS == ("r1", "r2", "r3", "r4", "r5") and HELD_OUT_ARENAS == ("h1", "h2")
    counts = {n: len(load_arena(n).blocks) for n in builtin_arena_names()}
    assert counts == {"r1": 1, "r2": 2, "r3": 2, "r4": 4, "r5": 0, "h1": 9, "h2": 3}
    assert load_arena("h2").size == (1.6, 0.8)
    r2, r3 = load_arena("r2"), load_arena("R3")
    assert [b.center for b in r2.blocks] != [b.center for b in r3.blocks]


def test_user_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(_good()))
    spec = load_arena(path)
    assert spec.name == "mine" and spec.size == (1.0, 0.8)
    assert spec.blocks[0].yaw == pytest.approx(0.3)
    assert parse_arena(spec.to_dict()).blocks == spec.blocks


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda d: d.pop("size"), "missing required key 'size'"),
        (lambda d: d.update(size=[1.0]), "size: expected a list of 2 numbers"),
        (lambda d: d.update(size=[1.0, -2]), "size[1]: expected a positive number"),
        (lambda d: d.update(wall_height="high"), "wall_height: expected a number"),
        (lambda d: d.update(colour="red"), "unknown key(s) ['colour']"),
        (
            lambda d: d["blocks"][0].update(size=[0.1, 0.1]),
            "blocks[0].size: expected a list of 3 numbers",
        ),
        (lambda d: d["blocks"][0].pop("center"), "blocks[0]: missing required key 'center'"),
        (
            lambda d: d["blocks"][0].update(center=[3.0, 0.0]),
            "blocks[0].center: [3.0, 0.0] lies outside",
        ),
        (lambda d: d["blocks"][0].update(yaw=None), "blocks[0].yaw: expected a number"),
        (lambda d: d.update(start={"random": False}), "start.random: must be true"),
        (
            lambda d: d.update(start={"pose": [0.2, 0.1, 0.0]}),
            "start.pose: (0.2, 0.1) is inside a block",
        ),
        (lambda d: d.update(start={}), "start: expected exactly one of"),
    ],
)
def test_bad_content_is_rejected_with_location(tmp_path: Path, mutate, expected: str) -> None:
    data = _good()
    mutate(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ArenaError) as info:
        load_arena(path)
    assert str(path) in str(info.value)
    assert expected in str(info.value)


def test_invalid_json_reports_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "broken.json"
    path.write_text('{\n  "name": "x",\n  "size": [1, 1,\n}')
    with pytest.raises(ArenaError, match=r"broken.json: line 4, column 1: invalid JSON"):
        load_arena(path)


def test_unknown_name_lists_builtins() -> None:
    with pytest.raises(ArenaError, match="unknown arena 'r9'.*r1, r2, r3, r4, r5"):
        load_arena("r9")


def test_free_pose_sampling_avoids_blocks_and_walls() -> None:
    spec = load_arena("r4")
    rng = np.random.default_rng(0)
    poses = np.array([spec.sample_free_pose(rng, 0.07)[:2] for _ in range(200)])
    assert np.all(spec.clearance(poses) >= 0.07)


def test_arena_loads_into_pybullet_with_solid_blocks() -> None:
    cid = p.connect(p.DIRECT)
    try:
        bodies = build_arena(load_arena("r1"), cid)
        assert bodies.blocks is not None and len(bodies.obstacles) == 2
        # a vertical ray onto the block's centre hits it at its top face (z = 0.1)
        hit = p.rayTest((0, 0, 1), (0, 0, -1), physicsClientId=cid)[0]
        assert hit[0] == bodies.blocks and hit[3][2] == pytest.approx(0.1, abs=1e-6)
        bodies5 = build_arena(load_arena("r5"), cid)
        assert bodies5.blocks is None
    finally:
        p.disconnect(physicsClientId=cid)


def test_start_pose_must_clear_blocks_by_the_robot_radius() -> None:
    # a pose 2 cm from the block's face: outside it, but the robot would touch it at step 1
    near = _good()
    near["blocks"][0]["yaw"] = 0.0
    near["start"] = {"pose": [0.2, 0.1 - 0.1 - 0.02, 0.0]}
    with pytest.raises(ArenaError, match=r"start\.pose: .* only 0\.020 m from a block or wall"):
        parse_arena(near, "near.json")
    # 2 cm from a wall
    wall = _good()
    wall["start"] = {"pose": [-0.48, 0.0, 0.0]}
    with pytest.raises(ArenaError, match=r"only 0\.020 m"):
        parse_arena(wall)
    # 5 cm away is enough
    ok = _good()
    ok["blocks"][0]["yaw"] = 0.0
    ok["start"] = {"pose": [0.2, 0.1 - 0.1 - 0.05, 0.0]}
    assert parse_arena(ok).start.pose is not None


def test_overlapping_blocks_are_an_error_unless_allowed() -> None:
    data = _good()
    data["blocks"] = [
        {"center": [0.2, 0.1], "size": [0.1, 0.2, 0.1]},
        {"center": [0.26, 0.1], "size": [0.1, 0.1, 0.1], "yaw": 0.7},
    ]
    with pytest.raises(ArenaError, match=r"blocks\[1\]: overlaps blocks\[0\]"):
        parse_arena(data, "lshape.json")
    data["allow_overlap"] = True
    spec = parse_arena(data)
    assert spec.allow_overlap and parse_arena(spec.to_dict()) == spec
    # blocks that only touch along an edge do not overlap
    touching = _good()
    touching["blocks"] = [
        {"center": [0.2, 0.1], "size": [0.1, 0.2, 0.1]},
        {"center": [0.3, 0.1], "size": [0.1, 0.2, 0.1]},
    ]
    assert len(parse_arena(touching).blocks) == 2
    with pytest.raises(ArenaError, match="allow_overlap: expected true or false"):
        parse_arena({**_good(), "allow_overlap": "yes"})
