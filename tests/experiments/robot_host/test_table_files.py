"""Final tables written atomically (issue 20): ``save_table_atomically`` writes what
``Trainer.save_table`` writes (same files, same bytes of the table), replaces an older table,
and leaves no temporary file; a real :class:`Trainer`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dfrl.experiments.robot_host.checkpoint import save_table_atomically
from dfrl.robots.tables import load_table
from dfrl.robots.training import Trainer, TrainerConfig


def test_atomic_table_is_the_trainers_table(tmp_path: Path) -> None:
    with Trainer(TrainerConfig(seed=3, iterations=20)) as trainer:
        for _ in range(20):
            trainer.step()
        plain = trainer.save_table(tmp_path / "plain" / "r1")
        (tmp_path / "tables").mkdir()
        (tmp_path / "tables" / "r1.npy").write_bytes(b"\x93NUMPY torn")  # an older torn one
        atomic = save_table_atomically(trainer, tmp_path / "tables" / "r1")
    assert atomic == tmp_path / "tables" / "r1.npy"
    assert (
        sorted(p.name for p in (tmp_path / "tables").iterdir())
        == sorted(p.name for p in plain.parent.iterdir())
        == ["r1.json", "r1.npy", "r1.visits.npy"]
    )
    a, b = load_table(atomic), load_table(plain)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.visits, b.visits)
    assert a.meta == b.meta
