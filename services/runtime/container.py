"""Several services in one OS process, as Nav2's component container: `omninav container FILE`.

Every service of FILE (a compose file; `up` writes one per `process:` of a run) is built as its own
Node with its own parameters and its own LiveRunner — the same code, keys, merge rules and
Diagnostic as when it runs alone — but all of them share one Zenoh session and one thread (below),
so the process imports numpy, numba and zenoh and opens a session once. A message one of them publishes
is handed straight to the inboxes of the others that take its key (no network, no router) and is
also put on the bus with destination "remote", so the recorder, the view and the services of other
processes see it and the container's own nodes do not get it twice. Each node still merges its
inputs by stamp (merge.py), so a service replays byte for byte whichever way it was run. The
container subscribes once per key for all its nodes that take it, and a payload is decoded once
for all of them (live.Received), whether it came from the bus or from a node beside them.

The services are driven by one thread (Executor), as Nav2's component_container drives its
components with one single-threaded executor: each service's inputs, merger, ticks and reports are
its LiveRunner's, but one thread takes every input and turns the runners that have work. With a
thread per service every message woke each service that takes it, and each wake-up of a Python
thread (a futex, a context switch, the GIL handed over) cost tens of microseconds of CPU on the
2-core development machine: about as much as the services' own work in a live mission.

The process has one identity: the union of what its services declare (launcher.identities).
Services with their own session (the recorder, the view: run_live) run in a thread beside them. A
recorder (a node with take_local) runs on the container's session instead: the services beside it
hand it what they publish, and its subscriptions take only what other processes publish, so the
container's messages that no other process takes never go through the router (in `navigate
--composed` the simulator's 100 Hz wheel states, ground truth, movers and wheel commands).
"""
from __future__ import annotations

import argparse
import logging
import queue
import sys
import threading
import time

from .compose import ComposeError, load_compose
from .live import POLL_S, LiveRunner, await_tokens, deliver, received_from
from .node import Node
from ...parameters.declare import ParamError
from .service_registry import UnknownService
from .run import build_node
from .zenoh_config import open_client
from .stop_signals import on_parent_exit, on_stop_signals

STOP_TIMEOUT_S = 10.0       # per service: its thread finishing after its stop
READY_TIMEOUT_S = 60.0      # for the others' tokens before the sources start anyway


class _Routed:
    """A runner's inbox in a container: what is put into it goes into the executor's one queue,
    tagged with the runner."""
    __slots__ = ("queue", "runner")

    def __init__(self, shared: queue.SimpleQueue, runner: LiveRunner | None):
        self.queue, self.runner = shared, runner

    def put(self, item: tuple) -> None:
        self.queue.put((self.runner, item))


class Executor:
    """One thread driving several LiveRunners on one session: it takes every runner's inputs from
    one queue and turns a runner (LiveRunner.turn: release what its merger lets go, tick, report)
    when it was handed something, when its tick is due, or at least every poll period — the turns
    its own thread would make. Runners are added and stopped through the queue, so they start and
    finish on this thread, in the order asked."""

    def __init__(self, session, failed: list[str]):
        self.session = session
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.control = _Routed(self.queue, None)
        self.active: list[LiveRunner] = []
        self.failed = failed

    def adopt(self, runner: LiveRunner) -> None:
        """Route the runner's inbox here (before anything can reach it)."""
        runner._inbox = _Routed(self.queue, runner)

    def start(self, runner: LiveRunner) -> None:
        self.control.put(("start", runner))

    def stop(self, runner: LiveRunner, timeout_s: float) -> None:
        """Ask the runner to finish (its last inputs processed, its last Diagnostic out) and wait for it."""
        done = threading.Event()
        self.control.put(("stop", runner, done))
        done.wait(timeout_s)

    def end(self) -> None:
        self.control.put(("end",))

    def run(self) -> None:
        polled: dict[int, float] = {}
        while True:
            wait = min((r.wait_s() for r in self.active), default=POLL_S)
            handed: set[int] = set()
            try:
                item = self.queue.get(timeout=wait)
                while True:     # everything queued before turning, so stamps sort in one go
                    runner, what = item
                    if runner is None:
                        if self._control(what):
                            return
                    elif runner.node.name not in self.failed and self._guarded(runner, runner._handle, what):
                        handed.add(id(runner))
                    item = self.queue.get_nowait()
            except queue.Empty:
                pass
            now = time.monotonic()
            for runner in list(self.active):
                if id(runner) in handed or now >= polled.get(id(runner), 0.0) or runner.wait_s() == 0.0:
                    polled[id(runner)] = now + POLL_S
                    self._guarded(runner, runner.turn)

    def _control(self, what: tuple) -> bool:
        """Start or stop a runner; True at the end."""
        if what[0] == "start":
            self._guarded(what[1], what[1].open, self.session)
            if what[1].node.name not in self.failed:
                self.active.append(what[1])
        elif what[0] == "stop":
            runner, done = what[1], what[2]
            if runner in self.active:
                self.active.remove(runner)
                self._guarded(runner, runner.close)
            done.set()
        return what[0] == "end"

    def _guarded(self, runner: LiveRunner, call, *args) -> bool:
        """call(*args); an error is the runner's end (logged; the container then stops), not the thread's."""
        try:
            call(*args)
            return True
        except Exception:
            if runner in self.active:
                self.active.remove(runner)
            self.failed.append(runner.node.name)
            runner.node.log.exception("%s stopped on an error; stopping the container", runner.node.name)
            return False


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
        self.failed: list[str] = []      # services that ended on an error

    def stop(self) -> None:
        """Ask the container to stop, from any thread (at a signal on_stop_signals calls it on one of its own)."""
        self.stopping.set()

    def run(self) -> None:
        """Run every service until stop(); sources (the sim, which set the pace) only once the others
        are ready, so they hear from the first tick (and, started by `up`, once the other processes'
        listeners are: LiveRunner waits for $OMNINAV_LISTENERS). At the end stop them in
        reverse order, each finished (its last inputs processed, its final Diagnostic out) before the
        next is asked."""
        session = open_client(self.router, stopped=self.stopping.is_set)
        if session is None:     # stopped while waiting for the router
            return
        with session:
            executor = Executor(session, self.failed)
            own_session = [r for r in self.runners if hasattr(r.node, "run_live")]
            threads = {id(runner): threading.Thread(target=self._serve, args=(runner, session), name=runner.node.name)
                       for runner in own_session}
            recorders = [r.node.take_local for r in own_session if hasattr(r.node, "take_local")]
            for runner in self.runners:
                if runner not in own_session:
                    executor.adopt(runner)
                    runner.taps = recorders
            # before any node declares its token: whoever sees it may publish to it at once
            subscribers = [session.declare_subscriber(key, lambda s, takers=takers: deliver(takers, *received_from(s)))
                           for key, takers in self.routes.items()]
            driver = threading.Thread(target=executor.run, name="executor")
            driver.start()

            def start(runner: LiveRunner) -> None:
                if runner in own_session:
                    threads[id(runner)].start()
                else:
                    executor.start(runner)

            first = [r for r in self.runners if r.node.pace_s() is None]
            for runner in first:
                start(runner)
            await_tokens(session, {runner.node.keys.alive(runner.node.name) for runner in first}, READY_TIMEOUT_S,
                         lambda: self.stopping.is_set() or bool(self.failed))
            for runner in self.runners:
                if runner not in first:
                    start(runner)
            while not self.stopping.wait(0.2):
                if self.failed:
                    break       # a service ended on an error: the process ends, as a lone service's would
            for runner in reversed(self.runners):
                if runner not in own_session:
                    executor.stop(runner, STOP_TIMEOUT_S)
                elif threads[id(runner)].is_alive():
                    runner.stop()
                    threads[id(runner)].join(STOP_TIMEOUT_S)
            executor.end()
            driver.join(STOP_TIMEOUT_S)
            for subscriber in subscribers:
                subscriber.undeclare()

    def _serve(self, runner: LiveRunner, session) -> None:
        """A service with its own session (run_live) on its own thread; a recorder on the container's."""
        node = runner.node
        try:
            if hasattr(node, "take_local"):
                node.run_live(runner.router, runner.stop_event, session)
            else:
                node.run_live(runner.router, runner.stop_event)
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
    on_stop_signals(container.stop)
    on_parent_exit(container.stop)
    log.info("started %s (robot %s)", ", ".join(n.name for n in nodes), compose.robot)
    container.run()
    if container.failed:
        log.error("stopped: %s failed", ", ".join(container.failed))
        return 1
    log.info("stopped")
    return 0
