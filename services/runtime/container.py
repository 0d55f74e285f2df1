"""Several services in one OS process, as Nav2's component container: `omninav container FILE`.

Every service of FILE (a compose file; `up` writes one per `process:` of a run) is built as its own
Node with its own parameters and driven by its own LiveRunner thread — the same code, keys, merge
rules and Diagnostic as when it runs alone — but all of them share one Zenoh session, so the
process imports numpy, numba and zenoh and opens a session once. A message one of them publishes
is handed straight to the inboxes of the others that take its key (no network, no router) and is
also put on the bus with destination "remote", so the recorder, the view and the services of other
processes see it and the container's own nodes do not get it twice. Each node still merges its
inputs by stamp (merge.py), so a service replays byte for byte whichever way it was run. The
container subscribes once per key for all its nodes that take it, and a payload is decoded once
for all of them (live.Received), whether it came from the bus or from a node beside them.

The process has one identity: the union of what its services declare (launcher.identities).
Services with their own session (the recorder, the view: run_live) run in a thread beside them.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from .compose import ComposeError, load_compose
from .live import LiveRunner, await_tokens, deliver, received_from
from .node import Node
from ...parameters.declare import ParamError
from .service_registry import UnknownService
from .run import build_node
from .zenoh_config import open_client

STOP_TIMEOUT_S = 10.0       # per service: its thread finishing after its stop
READY_TIMEOUT_S = 60.0      # for the others' tokens before the sources start anyway


class Container:
    def __init__(self, nodes: list[Node], router: str | None = None, *, sync_timeout_s: float = 1.0):
        self.router = router
        self.runners = [LiveRunner(node, router, sync_timeout_s=sync_timeout_s) for node in nodes]
        self.routes: dict[str, list[tuple[LiveRunner, int]]] = {}
        for runner in self.runners:
            if not hasattr(runner.node, "run_live"):
                for index, inp in enumerate(runner.node.inputs):
                    self.routes.setdefault(inp.key, []).append((runner, index))
        for runner in self.runners:
            runner.local = self.routes
        self.stopping = threading.Event()
        self.failed: list[str] = []      # services whose thread ended on an error

    def stop(self) -> None:
        """Ask the container to stop; safe from a signal handler."""
        self.stopping.set()

    def run(self) -> None:
        """Run every service until stop(); sources (the sim, which set the pace) only once the others
        are ready, so they hear from the first tick (and, started by `up`, once the other processes'
        listeners are: LiveRunner waits for $OMNINAV_LISTENERS). At the end stop them in
        reverse order, each finished (its last inputs processed, its final Diagnostic out) before the
        next is asked."""
        with open_client(self.router) as session:
            # before any node declares its token: whoever sees it may publish to it at once
            subscribers = [session.declare_subscriber(key, lambda s, takers=takers: deliver(takers, *received_from(s)))
                           for key, takers in self.routes.items()]
            threads = {id(runner): threading.Thread(target=self._serve, args=(runner, session), name=runner.node.name)
                       for runner in self.runners}
            first = [r for r in self.runners if r.node.pace_s() is None]
            for runner in first:
                threads[id(runner)].start()
            await_tokens(session, {runner.node.keys.alive(runner.node.name) for runner in first}, READY_TIMEOUT_S,
                         lambda: self.stopping.is_set() or bool(self.failed))
            for runner in self.runners:
                if runner not in first:
                    threads[id(runner)].start()
            while not self.stopping.wait(0.2):
                if self.failed:
                    break       # a service ended on an error: the process ends, as a lone service's would
            for runner in reversed(self.runners):
                runner.stop()
                if threads[id(runner)].is_alive():
                    threads[id(runner)].join(STOP_TIMEOUT_S)
            for subscriber in subscribers:
                subscriber.undeclare()

    def _serve(self, runner: LiveRunner, session) -> None:
        node = runner.node
        try:
            if hasattr(node, "run_live"):       # talks to Zenoh itself, on its own session
                node.run_live(runner.router, runner.stop_event)
            else:
                runner.run(session)
        except Exception:
            self.failed.append(node.name)
            node.log.exception("%s stopped on an error; stopping the container", node.name)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("compose", help="a compose file: every service in it runs in this process")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--log-level", default="INFO")


def main(args: argparse.Namespace) -> int:
    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(levelname)s [%(name)s] %(message)s")
    log = logging.getLogger("omninav.container")
    try:
        compose = load_compose(args.compose)
        nodes = [build_node(s.service or s.name, overrides=s.params, robot=s.robot, name=s.name, node_type=s.node_type)
                 for s in compose.services]
    except (ComposeError, UnknownService, ParamError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    container = Container(nodes, args.router)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: container.stop())
    log.info("started %s (robot %s)", ", ".join(n.name for n in nodes), compose.robot)
    container.run()
    if container.failed:
        log.error("stopped: %s failed", ", ".join(container.failed))
        return 1
    log.info("stopped")
    return 0
