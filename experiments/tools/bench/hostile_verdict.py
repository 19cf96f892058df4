"""The targets of ``dfrl bench hostile``: when one phase passes (:func:`misses`).

A phase passes if

* no hop failed or went unfinished and at least one succeeded;
* the p90 is under ``P90_RATIO_MAX`` times the quiet p90;
* RSS once the threads have settled is within ``RSS_DELTA_MAX_MB`` of before (read at the
  settling time instead, a flood's idle connection workers, still alive then, once counted
  50.6 MB);
* an ordinary agent is accepted (the peer's agent starts its handler at the target) within
  ``ACCEPT_MAX_S`` of the attack's end (the attacker stopped and gone);
* the peak of threads stays under the ceiling that the node's limits allow
  (:func:`thread_ceiling`: the threads of the quiet target outside its pools, plus the most
  workers of the connection pool (twice ``max_connections``), ``max_agents`` for the agents
  pool, ``max_agents`` again for the messages pool, 2 for the bound notices pool, plus
  ``PEAK_SLACK``). The messages pool is the one the node does not bound by a limit of its own
  (only by the pool's maximum, 1000): the ceiling assumes one running message per agent, so a
  phase that needs more fails and shows it;
* once the pools' idle time has passed after the attack's end (the target runs with
  ``dfrl_pool_idle`` = ``pool_idle_s``, 5 s by default, instead of the node's 30 s, to keep
  the benchmark short), threads come down, within ``threads_wait_s``, to at most the quiet
  target's threads outside its pools plus the workers its pools keep warm (``KEEP_WARM`` each,
  at most the pool's maximum) plus ``SETTLED_SLACK`` (the peer's hop in flight):
  :func:`settled_bound`;
* the target did not stop the peer's agent (its home, the peer, was not told so; if it was,
  the benchmark starts a new one after the phase, so that the next phases measure again);
* the settled CPU use is within ``CPU_MARGIN`` (cores) of the quiet phase's;
* no escape ran.
"""

from __future__ import annotations

from typing import Any

P90_RATIO_MAX = 10.0
RSS_DELTA_MAX_MB = 50.0
KEEP_WARM = 8  # worker_pool.pl's keep(8): the node's pools pass no keep option
SETTLED_SLACK = 4  # the peer's hop in flight: a connection worker, its handler, a transient
PEAK_SLACK = 8  # threads that exit while their replacement starts, between two samples
ACCEPT_MAX_S = 20.0  # issue 16: an ordinary agent is accepted within 20 s
CPU_MARGIN = 0.25


def thread_ceiling(nonpool: int, limits: dict[str, int]) -> int:
    """The most threads the node's limits allow (see the module doc): ``nonpool`` threads
    outside the pools, every pool at the most workers its limits let it need, ``PEAK_SLACK``."""
    return nonpool + limits["connection_workers_max"] + 2 * limits["max_agents"] + 2 + PEAK_SLACK


def settled_bound(nonpool: int, limits: dict[str, int]) -> int:
    """The most threads of a settled node (see the module doc): ``nonpool`` threads outside the
    pools, ``KEEP_WARM`` idle workers in each pool (at most its maximum), ``SETTLED_SLACK``."""
    pool_max = {
        "connections": limits["connection_workers_max"],
        "agents": limits["max_agents"],
        "messages": limits["max_agents"],
        "dfrl_bound_notices": 2,
    }
    return nonpool + sum(min(KEEP_WARM, m) for m in pool_max.values()) + SETTLED_SLACK


def p90_ratio(hops: dict[str, Any], quiet: dict[str, Any] | None) -> float | None:
    """A phase's hop p90 over the quiet phase's; None without both."""
    q = quiet["hops"]["hop_p90_ms"] if quiet else None
    if not q or hops["hop_p90_ms"] is None:
        return None
    return round(hops["hop_p90_ms"] / q, 2)


def misses(p: dict[str, Any], quiet: dict[str, Any] | None) -> list[str]:
    """The targets phase ``p`` missed (see the module doc); none for a pass."""
    why: list[str] = []
    hops, rss, th, cpu = p["hops"], p["rss_mb"], p["threads"], p["cpu_cores"]
    if hops["succeeded"] == 0:
        why.append("no hop succeeded")
    if hops["failed"] or hops["unfinished"]:
        why.append(f"{hops['failed']} hops failed, {hops['unfinished']} unfinished")
    ratio = p["p90_ratio"]
    if ratio is not None and ratio >= P90_RATIO_MAX:
        why.append(f"p90 {ratio}x the quiet p90 (limit {P90_RATIO_MAX:g}x)")
    if rss["delta"] > RSS_DELTA_MAX_MB:
        why.append(f"RSS grew by {rss['delta']} MB (limit {RSS_DELTA_MAX_MB:g})")
    if p["peer_agent_stopped"]:
        why.append(f"the target stopped the peer's ordinary agent: {p['peer_agent_stopped'][0]}")
    if p["accepted_after_s"] is None or p["accepted_after_s"] > ACCEPT_MAX_S:
        why.append(f"no ordinary agent accepted within {ACCEPT_MAX_S:g} s of the attack's end")
    if th["peak"] >= th["peak_ceiling"]:
        why.append(f"peak of {th['peak']} threads, ceiling {th['peak_ceiling']}")
    if th["settled_bound"] is not None and th["settled"] > th["settled_bound"]:
        why.append(
            f"{th['settled']} threads {th['settled_after_s']} s after the attack, "
            f"bound {th['settled_bound']} (pools {_pool_sizes(th['pools_settled'])})"
        )
    if quiet is not None and cpu["settled"] > quiet["cpu_cores"]["phase"] + CPU_MARGIN:
        why.append(
            f"CPU {cpu['settled']:.2f} cores after settling, quiet "
            f"{quiet['cpu_cores']['phase']:.2f} (limit +{CPU_MARGIN:g})"
        )
    if p["escapes"] is not None and p["escapes"]["ran"]:
        why.append(f"{p['escapes']['ran']} escapes ran: {', '.join(p['escapes']['ran_names'])}")
    return why


def _pool_sizes(pools: dict[str, dict[str, int]]) -> str:
    return ", ".join(f"{k} {v['size']}" for k, v in sorted(pools.items()))
