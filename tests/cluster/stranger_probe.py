"""What a process on another host gets from a Dask cluster: run by test_cluster_stranger.py
inside the stranger's namespace as ``python stranger_probe.py ATTEMPTS_JSON``; prints one JSON
line per attempt: ``{"label", "ok", "detail"}``.

An attempt (a dict) has ``label``, ``kind``, ``address`` and ``tls``:

* ``kind`` ``client``: a ``distributed.Client`` lists the workers (``scheduler_info``) and runs
  a task (:func:`task`); ``ok`` if both worked (``detail``: the worker count and the task's
  answer).
* ``kind`` ``identity``: one raw comm of Dask's protocol to a server (scheduler, worker,
  nanny) sends ``{"op": "identity"}`` and reads the answer; ``ok`` if one came.
* ``kind`` ``http``: a TCP connection to ``HOST:PORT``; ``ok`` if it was accepted.
* ``tls``: ``null`` (no TLS context: plaintext, or a Client given none), ``"none"`` (TLS
  without a certificate, not checking the server's), or ``{"ca", "cert", "key"}`` (a
  ``distributed.Security`` with that certificate).

Every attempt runs in a child process of its own, forked before this process made any
client (a Client that failed leaves state behind that spoils the next one), and is bounded:
:data:`TIMEOUT_S` to connect, to read and for the task, :data:`ATTEMPT_S` in all (then the
child is killed and the attempt counts as answered by nothing).
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import socket
import ssl
import sys
from typing import Any

from distributed import Client, Security
from distributed.comm import connect

TIMEOUT_S = 8.0
ATTEMPT_S = 40.0


def task() -> dict[str, Any]:
    """What the task reports from the worker: its folder and whether ``dfrl.token`` is
    there (what the attacker of the issue read)."""
    import os

    return {"cwd": os.getcwd(), "token_there": os.path.exists("dfrl.token")}


class CertlessTls(Security):
    """TLS without a certificate, trusting any server: a stranger that speaks TLS."""

    def get_connection_args(self, role: str) -> dict[str, Any]:
        ctx = ssl.create_default_context()
        ctx.check_hostname = False
        ctx.verify_mode = ssl.CERT_NONE
        return {"ssl_context": ctx, "require_encryption": True, "extra_conn_args": {}}


def security_of(tls: Any) -> Security | None:
    if tls is None:
        return None
    if tls == "none":
        return CertlessTls()
    return Security(
        tls_ca_file=tls["ca"],
        tls_client_cert=tls["cert"],
        tls_client_key=tls["key"],
        require_encryption=True,
    )


def try_client(address: str, tls: Any) -> str:
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers lack this file
    sec = security_of(tls)
    with Client(
        address,
        timeout=TIMEOUT_S,
        set_as_default=False,
        **({"security": sec} if sec is not None else {}),
    ) as client:
        workers = len(client.scheduler_info(n_workers=-1)["workers"])
        answer = client.submit(task, pure=False).result(timeout=TIMEOUT_S)
    return json.dumps({"workers": workers, "task": answer})


async def _identity(address: str, tls: Any) -> str:
    sec = security_of(tls)
    args = sec.get_connection_args("client") if sec is not None else {}
    comm = await connect(
        address, timeout=TIMEOUT_S, **({"ssl_context": args["ssl_context"]} if args else {})
    )
    try:
        await asyncio.wait_for(comm.write({"op": "identity", "reply": True}), TIMEOUT_S)
        reply = await asyncio.wait_for(comm.read(), TIMEOUT_S)
    finally:
        comm.abort()
    return json.dumps({"type": reply.get("type") if isinstance(reply, dict) else repr(reply)})


def try_http(address: str) -> str:
    host, port = address.rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=TIMEOUT_S):
        return "accepted"


def attempt(spec: dict[str, Any]) -> dict[str, Any]:
    try:
        if spec["kind"] == "client":
            detail = try_client(spec["address"], spec["tls"])
        elif spec["kind"] == "identity":
            detail = asyncio.run(
                asyncio.wait_for(_identity(spec["address"], spec["tls"]), 3 * TIMEOUT_S)
            )
        else:
            detail = try_http(spec["address"])
        return {"label": spec["label"], "ok": True, "detail": detail}
    except Exception as exc:  # noqa: BLE001 - a refusal is the answer we record
        return {
            "label": spec["label"],
            "ok": False,
            "detail": f"{type(exc).__name__}: {str(exc)[:300]}",
        }


def _child(spec: dict[str, Any], out: Any) -> None:
    out.send(attempt(spec))
    out.close()


def attempt_alone(spec: dict[str, Any]) -> dict[str, Any]:
    """:func:`attempt` in a forked child, killed after :data:`ATTEMPT_S`."""
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(spec, send), daemon=True)
    child.start()
    send.close()
    try:
        if receive.poll(ATTEMPT_S):
            return receive.recv()
        return {
            "label": spec["label"],
            "ok": False,
            "detail": f"no answer within {ATTEMPT_S:.0f} s (child killed)",
        }
    except EOFError:
        return {
            "label": spec["label"],
            "ok": False,
            "detail": f"the attempt's process died (exit {child.exitcode})",
        }
    finally:
        child.kill()
        child.join(10)


def main(argv: list[str]) -> int:
    for spec in json.loads(argv[1]):
        print(json.dumps(attempt_alone(spec)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
