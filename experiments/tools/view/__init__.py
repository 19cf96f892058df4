"""The live view of a federated run: a web page served from the run, updated by server-sent
events read from the results folder (``dfrl run --view``, ``dfrl view RESULTS_DIR``).

* :func:`start_view` / :class:`ViewServer`: the server (:mod:`.server`);
* :class:`EventSource`: the results folder turned into events (:mod:`.source`);
* :func:`append_event`: the run's own ``events.jsonl`` (hops, robot states, poses).
"""

from dfrl.experiments.driver.launcher.events import EVENTS_FILE, append_event
from dfrl.experiments.tools.view.server import ViewServer, start_view
from dfrl.experiments.tools.view.source import EventSource

__all__ = ["EVENTS_FILE", "EventSource", "ViewServer", "append_event", "start_view"]
