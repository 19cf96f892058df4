"""The live view's web server: one page, its assets, and the run's events pushed to it.

Routes (``GET`` only):

============================ ===========================================================
``/``                        the page (``static/index.html``)
``/static/<name>``           its script and style sheet (package data, nothing from outside)
``/events``                  server-sent events: every event from the first (or from
                             ``Last-Event-ID`` + 1, or ``?from=N``), then the new ones in
                             messages :data:`SEND_S` apart at least; ``data:`` is a JSON
                             array of events, ``id:`` the last ``seq``
``/events.json?from=N``      the same events as one JSON array (tests, scripts)
============================ ===========================================================

Threading model: one poller thread reads the results folder every ``poll_s`` seconds
(:class:`~dfrl.experiments.tools.view.source.EventSource`, the only reader) and appends to the event
list under a condition; each HTTP connection has its own thread (``ThreadingHTTPServer``)
that only reads the list and waits on the condition. Nothing is printed.
"""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlparse

from dfrl.experiments.tools.view.source import EventSource
from dfrl.experiments.tools.view.tail import file_mtime

_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
}
#: Events sent in one server-sent message at most.
BATCH = 2000
#: Seconds between two keep-alive comments on an idle event stream.
HEARTBEAT_S = 10.0
#: Seconds between two messages of one event stream at least: what comes in between goes
#: in the next message (a page redraws once per message at most, so fewer is cheaper).
SEND_S = 0.25


def _asset(name: str) -> bytes | None:
    root = resources.files("dfrl.experiments.tools.view") / "static"
    item = root / name
    if "/" in name or name.startswith(".") or not item.is_file():
        return None
    return item.read_bytes()


class ViewServer:
    """A running view of one results folder (see :func:`start_view`).

    Attributes
    ----------
    url : str
        ``http://HOST:PORT/``.
    source : EventSource
    """

    def __init__(
        self,
        results_dir: str | Path,
        host: str = "127.0.0.1",
        port: int = 0,
        poll_s: float = 0.25,
        fresh: bool = False,
    ) -> None:
        self.results_dir = Path(results_dir)
        self.source = EventSource(self.results_dir)
        self.poll_s = poll_s
        self.errors: list[str] = []
        #: CPU seconds the poller thread spent reading the folder so far
        self.poll_cpu_s = 0.0
        self._cond = threading.Condition()
        self._closed = threading.Event()
        self._since = time.time() if fresh else None
        self._httpd = ThreadingHTTPServer((host, port), _handler(self))
        self._httpd.daemon_threads = True
        bound_host, bound_port = self._httpd.socket.getsockname()[:2]
        shown = f"[{bound_host}]" if ":" in str(bound_host) else bound_host
        self.url = f"http://{shown}:{bound_port}/"
        self._poller = threading.Thread(target=self._poll_loop, name="view-poll", daemon=True)
        self._serve = threading.Thread(
            target=self._httpd.serve_forever,
            name="view-http",
            kwargs={"poll_interval": 0.2},
            daemon=True,
        )
        self._poller.start()
        self._serve.start()

    # -- events ------------------------------------------------------------------------
    def events_from(self, first: int, limit: int = BATCH) -> list[dict[str, Any]]:
        """Events numbered ``first`` on (at most ``limit``)."""
        with self._cond:
            return self.source.events[first : first + limit]

    def wait_events(self, first: int, timeout: float) -> list[dict[str, Any]]:
        """Events from ``first`` on, waiting up to ``timeout`` for one (empty: none)."""
        with self._cond:
            self._cond.wait_for(
                lambda: len(self.source.events) > first or self._closed.is_set(), timeout
            )
            return self.source.events[first : first + BATCH]

    def pause(self, seconds: float) -> None:
        """Wait ``seconds`` (less if the view closes)."""
        self._closed.wait(seconds)

    def _fresh(self) -> bool:
        if self._since is None:
            return True
        mtime = file_mtime(self.results_dir / "config.json")
        if mtime is not None and mtime >= self._since - 1.0:
            self._since = None
        return self._since is None

    def _poll_loop(self) -> None:
        first = True
        while not self._closed.is_set():
            try:
                if self._fresh():
                    # read outside the lock (the list only grows; readers slice it)
                    c0 = time.thread_time()
                    # a finished run is read whole first (curves merged by time); a live
                    # one is followed poll by poll (a drain would never end)
                    finished = (self.results_dir / "summary.md").is_file()
                    new = self.source.drain() if first and finished else self.source.poll()
                    self.poll_cpu_s += time.thread_time() - c0
                    first = False
                    if new:
                        with self._cond:
                            self._cond.notify_all()
            except Exception as exc:  # noqa: BLE001 - the view says it, the run goes on
                self.errors.append(f"{type(exc).__name__}: {exc}")
                with self._cond:
                    self.source.events.append(
                        {
                            "seq": len(self.source.events),
                            "t": time.time(),
                            "kind": "error",
                            "text": self.errors[-1],
                        }
                    )
                    self._cond.notify_all()
            self._closed.wait(self.poll_s if self.source.live else max(1.0, self.poll_s))

    # -- life --------------------------------------------------------------------------
    def close(self) -> None:
        """Stop polling and serving; open event streams end."""
        if self._closed.is_set():
            return
        self._closed.set()
        with self._cond:
            self._cond.notify_all()
        self._httpd.shutdown()
        self._httpd.server_close()
        self._poller.join(timeout=5)
        self._serve.join(timeout=5)

    def __enter__(self) -> "ViewServer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed.is_set()


def start_view(
    results_dir: str | Path,
    host: str = "127.0.0.1",
    port: int = 0,
    *,
    poll_s: float = 0.25,
    fresh: bool = False,
) -> ViewServer:
    """Serve the live view of a results folder (a run going on, or a finished one).

    Parameters
    ----------
    results_dir : str or Path
    host : str
        Address to bind (loopback by default; another one only when asked for).
    port : int
        0: a free port chosen by the OS (see ``.url``).
    poll_s : float
        Seconds between two reads of the folder.
    fresh : bool
        Wait for a ``config.json`` written from now on (a run about to start in a folder
        that may still hold an older run's files).

    Returns
    -------
    ViewServer
        Serving already; ``.close()`` stops it. Prints nothing.
    """
    return ViewServer(results_dir, host, port, poll_s, fresh)


def _handler(view: ViewServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "dfrl-view"
        protocol_version = "HTTP/1.1"

        def log_message(self, format: str, *args: Any) -> None:  # noqa: A002
            pass  # nothing printed

        def do_GET(self) -> None:  # noqa: N802 - http.server's name
            url = urlparse(self.path)
            query = parse_qs(url.query)
            if url.path in ("/", "/index.html"):
                self._file("index.html")
            elif url.path.startswith("/static/"):
                self._file(url.path[len("/static/") :])
            elif url.path == "/favicon.ico":
                self._send(204, "image/x-icon", b"")
            elif url.path == "/events.json":
                first = _int(query.get("from", ["0"])[0])
                body = json.dumps(view.events_from(first, 10**9)).encode()
                self._send(200, "application/json", body)
            elif url.path == "/events":
                last = self.headers.get("Last-Event-ID")
                first = _int(last) + 1 if last else _int(query.get("from", ["0"])[0])
                self._stream(first)
            else:
                self._send(404, "text/plain", b"not found\n")

        def _file(self, name: str) -> None:
            body = _asset(name)
            if body is None:
                self._send(404, "text/plain", b"not found\n")
            else:
                self._send(200, _TYPES.get(Path(name).suffix, "application/octet-stream"), body)

        def _send(self, code: int, ctype: str, body: bytes) -> None:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def _stream(self, first: int) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.send_header("Connection", "close")
            self.end_headers()
            self.close_connection = True
            try:
                self.wfile.write(b"retry: 1000\n\n")
                self.wfile.flush()
                while not view.closed:
                    batch = view.wait_events(first, HEARTBEAT_S)
                    if batch:
                        data = json.dumps(batch, separators=(",", ":"))
                        self.wfile.write(f"id: {batch[-1]['seq']}\ndata: {data}\n\n".encode())
                        first = batch[-1]["seq"] + 1
                    else:
                        self.wfile.write(b": ping\n\n")
                    self.wfile.flush()
                    if batch and len(batch) < BATCH:
                        view.pause(SEND_S)  # gather what comes next
            except (BrokenPipeError, ConnectionResetError, OSError):
                return  # the browser went away

    return Handler


def _int(text: str) -> int:
    try:
        return max(0, int(text))
    except ValueError:
        return 0
