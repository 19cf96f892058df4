"""The results folder of a federated experiment: reading the pieces, writing the tables.

Layout (see ``experiments/README.md``)::

    config.json            the experiment config, resolved (ExperimentConfig.resolved)
    provenance.json        versions, commit, host, command line (experiments/provenance.py)
    nodes.json             robots' addresses, the agents and their itineraries
    metrics.csv            robot, iteration, q_sum, cumulative_reward, collisions, shared,
                           q_sum_before_share: one row per robot and iteration (:mod:`.metrics`)
    rounds.csv             one row per agent round: times, hops, bytes, method, a digest per
                           robot right after the share, all_equal
    q_sum.png, cumulative_reward.png, curves.png
    summary.md
    metrics_<robot>.csv    per-robot metrics, written by the node while it runs
    shares_<robot>.csv     per-robot applied shares (index, iteration, time, sha256, the
                           write's round, agent, epoch, and the sum it left): the history
                           :mod:`.history` checks
    eval_<robot>.csv       greedy evaluations while learning (``eval_every``), and
    live_evaluations.csv   all robots' in one file (:mod:`.evaluations`)
    rounds_<agent>.log     the agent's log: one JSON object per line (round, finished,
                           aborted and control events)
    nodes/<robot>.json     node configs; logs/<robot>.err, logs/launch_<agent>.out
    tables/<robot>.npy     final tables (robots.tables format)
    params/<robot>.npy     a function learner's (linear, dqn) final parameters instead
                           (+ .json, format dfrl-params/2)
    checkpoint/<robot>.npy each robot's last checkpoint (table or parameters)
    tensorboard/           with ``--tensorboard``: event files from the CSVs (:mod:`.tensorboard`)
    tidy/                  steps.csv, shares.csv, rounds.csv: long tables, unique keys
                           (:mod:`.tidy`)
    distillation.csv       a grid federation's distillation residual per robot and round
    fedavg_weights.csv     each robot's weight (samples) per round of a FedAvg of parameters
                           (both from the robots' ``distillation_<robot>.csv`` and
                           ``weights_<robot>.csv``: :mod:`.carried`)

Modules: :mod:`.agent_log` (the agent's JSON-lines log), :mod:`.rounds` (shares, their
matching to rounds, ``rounds.csv``), :mod:`.metrics` (``metrics.csv``), :mod:`.evaluations`
(``live_evaluations.csv``), :mod:`.files` (JSON files), :mod:`.summary` (:class:`Results` and
``summary.md``), :mod:`.history` (the history checker: did the writes the robots recorded
keep the rules: no doubled write, no epoch regressed, no stale epoch, no split round),
:mod:`.tidy` (the long tables of ``tidy/``), :mod:`.what_ran` (the summary's first lines:
status, itinerary, what the agents carried, the learners), :mod:`.carried` (distillation
residuals and FedAvg weights), :mod:`.ending` (all the end-of-run files at once: what the
driver writes when a run ends and ``dfrl collect`` when the driver did not).
"""
from __future__ import annotations

from dfrl.experiments.driver.results.agent_log import (Aborted, AgentLog, ControlEvent, RoundRecord,
                                                Skip, parse_event, read_rounds_log)
from dfrl.experiments.driver.results.files import read_json, write_json
from dfrl.experiments.driver.results.history import (HistoryVerdict, Violation, check_history,
                                                     check_shares)
from dfrl.experiments.driver.results.metrics import (METRICS_FIELDS, MetricsFormatError,
                                                     merge_metrics, read_metrics)
from dfrl.experiments.driver.results.rounds import (ROUNDS_FIELDS, Share, count_equal, match_shares,
                                             read_rounds_csv, read_shares, write_rounds_csv)
from dfrl.experiments.driver.results.summary import Results, node_warnings, write_summary

__all__ = ["Aborted", "AgentLog", "ControlEvent", "HistoryVerdict", "METRICS_FIELDS",
           "MetricsFormatError",
           "ROUNDS_FIELDS", "Results", "RoundRecord", "Share", "Skip", "Violation",
           "check_history", "check_shares", "count_equal", "match_shares", "merge_metrics",
           "node_warnings", "parse_event", "read_json", "read_metrics", "read_rounds_csv",
           "read_rounds_log", "read_shares", "write_json", "write_rounds_csv", "write_summary"]
