"""Reports and figures: the plots of a federated run
(:mod:`dfrl.experiments.driver.results.plots`), curve statistics (:mod:`.stats`) and the paper
reproduction's ``report.md`` (:mod:`.paper`).

Library code only: functions return values (paths, statistics) and raise; nothing prints.
"""

from __future__ import annotations

from dfrl.experiments.science.report.paper import write_report
from dfrl.experiments.driver.results.plots import plot_both, plot_experiment, plot_metric
from dfrl.experiments.science.report.stats import (
    ALGO_NAMES,
    COMBOS,
    CombinationRun,
    RunStats,
    StandaloneRuns,
    stats_of,
)
from dfrl.experiments.science.curves import dip, late_growth, reward_rate, smooth, t_fraction

__all__ = [
    "ALGO_NAMES",
    "COMBOS",
    "CombinationRun",
    "RunStats",
    "StandaloneRuns",
    "dip",
    "late_growth",
    "plot_both",
    "plot_experiment",
    "plot_metric",
    "reward_rate",
    "smooth",
    "stats_of",
    "t_fraction",
    "write_report",
]
