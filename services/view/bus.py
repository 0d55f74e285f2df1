"""How a view follows the bus: as a tool, until stopped (the Foxglove view's and the Rerun view's run_live)."""
from __future__ import annotations

import threading

from ..runtime.live import LiveRunner
from ..runtime.node import Node
from ..runtime.zenoh_config import open_client


def follow_the_bus(node: Node, router: str | None, stop_event: threading.Event) -> None:
    """Drive node from the bus until stop_event is set (`omninav run`'s signal handlers set it), then
    close it, whatever ended the run."""
    runner = LiveRunner(node, router)
    runner.stops_with(stop_event)
    try:
        # as a tool: the run's read-only identity where $OMNINAV_CREDENTIALS names none (joining.py)
        session = open_client(router, stopped=stop_event.is_set, as_tool=True, warn=node.log.warning)
        if session is not None:     # else stopped while waiting for the router
            with session:
                runner.run(session)
    finally:
        node.close()
