"""The Flower side of ``dfrl bench vs-flower``: one Flower server or client process.

Run by :mod:`.vs_flower`, never by a user, as
``python -m dfrl.experiments.tools.bench.flower_peer server|client ...``; it needs the extra
``flower`` (``pip install 'dfrl[flower]'``), imported here only, when the process runs.

``server``: Flower's gRPC server (``flwr.server.start_server``, the legacy API: one process,
no SuperLink) on ``127.0.0.1:PORT`` with a FedAvg strategy that waits for ``--clients``
clients, asks every one of them to fit in every round, evaluates nothing and times each round
(:class:`TimedFedAvg`); at the end it writes ``{"round_ms": [...], "results": [...],
"failures": [...]}`` to ``--out`` (one entry per round) and exits 0.

``client``: a ``NumPyClient`` holding arrays of ``--shapes`` (random, seeded by ``--index``),
whose ``fit`` keeps the parameters it is sent and returns them unchanged, with
``--samples`` as its number of examples (FedAvg's weight); it exits when the server ends.

Flower's telemetry is off in both (``FLWR_TELEMETRY_ENABLED=0``, set by the parent too).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

#: seconds a client keeps trying to reach the server before it gives up
CONNECT_WAIT_S = 60.0


def timed_fedavg(clients: int, initial: list[np.ndarray]) -> Any:
    """A FedAvg strategy over exactly ``clients`` clients, no evaluation, that times rounds.

    A round's time (``round_ms``) runs from the moment its fit instructions are ready
    (``configure_fit`` returned: the clients sampled, so waiting for them to connect is not
    counted) to the moment ``aggregate_fit`` returned the new parameters: sending the
    parameters to every client, their ``fit``, the replies, and the weighted average.
    """
    from flwr.common import ndarrays_to_parameters
    from flwr.server.strategy import FedAvg

    class TimedFedAvg(FedAvg):
        def __init__(self) -> None:
            super().__init__(
                fraction_fit=1.0,
                fraction_evaluate=0.0,
                min_fit_clients=clients,
                min_evaluate_clients=clients,
                min_available_clients=clients,
                initial_parameters=ndarrays_to_parameters(initial),
            )
            self.round_ms: list[float] = []
            self.results: list[int] = []
            self.failures: list[int] = []
            self._start = 0.0

        def configure_fit(self, server_round: int, parameters: Any, client_manager: Any) -> Any:
            out = super().configure_fit(server_round, parameters, client_manager)
            self._start = time.perf_counter()
            return out

        def aggregate_fit(self, server_round: int, results: Any, failures: Any) -> Any:
            out = super().aggregate_fit(server_round, results, failures)
            self.round_ms.append((time.perf_counter() - self._start) * 1000.0)
            self.results.append(len(results))
            self.failures.append(len(failures))
            return out

    return TimedFedAvg()


def arrays(shapes: list[list[int]], seed: int) -> list[np.ndarray]:
    """Random float64 arrays of ``shapes``, seeded by ``seed`` (what a client holds)."""
    rng = np.random.default_rng(seed)
    return [rng.standard_normal(tuple(shape)) for shape in shapes]


def run_server(port: int, clients: int, rounds: int, shapes: list[list[int]], out: Path) -> int:
    """Serve ``rounds`` FedAvg rounds to ``clients`` clients; write the round times to ``out``."""
    import flwr

    strategy = timed_fedavg(clients, arrays(shapes, 10_000))
    flwr.server.start_server(
        server_address=f"127.0.0.1:{port}",
        config=flwr.server.ServerConfig(num_rounds=rounds, round_timeout=60.0),
        strategy=strategy,
    )
    report = {
        "round_ms": strategy.round_ms,
        "results": strategy.results,
        "failures": strategy.failures,
    }
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(report), encoding="utf-8")
    tmp.replace(out)
    return 0


def run_client(port: int, shapes: list[list[int]], index: int, samples: int) -> int:
    """One client: fit keeps what it is sent and returns it unchanged, ``samples`` examples."""
    import flwr

    class Holder(flwr.client.NumPyClient):
        def __init__(self) -> None:
            self.held = arrays(shapes, index)

        def get_parameters(self, config: dict[str, Any]) -> list[np.ndarray]:
            return self.held

        def fit(self, parameters: list[np.ndarray], config: dict[str, Any]) -> Any:
            self.held = parameters
            return self.held, samples, {}

    flwr.client.start_client(
        server_address=f"127.0.0.1:{port}",
        client=Holder().to_client(),
        insecure=True,
        max_wait_time=CONNECT_WAIT_S,
    )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="flower_peer", description=__doc__)
    parser.add_argument("role", choices=["server", "client"])
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--shapes", required=True, help="JSON list of the arrays' shapes")
    parser.add_argument("--clients", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--index", type=int, default=0)
    parser.add_argument("--samples", type=int, default=1)
    args = parser.parse_args(argv)
    os.environ.setdefault("FLWR_TELEMETRY_ENABLED", "0")
    shapes = json.loads(args.shapes)
    if args.role == "server":
        if args.out is None:
            parser.error("server needs --out")
        return run_server(args.port, args.clients, args.rounds, shapes, args.out)
    return run_client(args.port, shapes, args.index, args.samples)


if __name__ == "__main__":
    sys.exit(main())
