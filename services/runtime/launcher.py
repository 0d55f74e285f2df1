"""`omninav up [COMPOSE]`: a loopback router in this process and every service as its own process.

Each service runs as `omninav run …` in its own process group, so a Ctrl-C in the terminal reaches
only the launcher, which then stops the services itself in reverse order (the recorder, listed
first, stops last and records everything). Output lines are prefixed with the service's name.
Restart policy and start-failure rules: docs/compose.md.

Every run gets fresh identities (acl.py): one per service, plus the tool, teleop and operator ones
for processes started by hand, written to a folder only this user can read; each service finds
its own through $OMNINAV_CREDENTIALS, and the router admits only those users and lets each do
only what its Node declares. While the router is open the tool identity is also this user's
entry for its endpoint (joining.py), so `view`, `topics`, `echo`, `hz`, `get` and `record` just join.

The compose file is loaded and every Node built (to read what it declares) in a child process
(`prepare`, child.py), which hands over plain data and ends: its imports — numba, scipy, pymunk —
with the maps and JIT caches the Nodes load are over 100 MB this process would hold for the run.
Every process starts as soon as the file is loaded, all at once, while the child builds the Nodes
for the ACL; they connect when the router opens. A source (a Node with a pace of its own: the sim)
waits for the liveliness tokens of every service without one before it declares anything
($OMNINAV_LISTENERS, live.py), so its first messages find everyone listening.
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import yaml
import zenoh

from ...schemas.keys import KeyLayout
from .acl import (CREDENTIALS_ENV, TOOL, Grants, access_control, client_grants, node_grants, union, write_passwords,
                  write_puts)
from .child import Answers, Child, ChildDied
from .forked import ForkedProcess
from .joining import published
from .compose import Compose, ComposeError, ProcessSpec, load_compose
from ...parameters.declare import ParamError
from .service_registry import UnknownService
from .node import Node
from .live import LISTENERS_ENV, tokens_present
from .lockstep import LOCKSTEP_ENV, Lockstep, service_names
from .run import build_node
from .zenoh_config import ROUTER_ENV, open_router, router_endpoint
from .stop_signals import on_parent_exit, stop_event

DEFAULT_COMPOSE = "compose/demo.yaml"
BACKOFF_FIRST_S = 0.5
BACKOFF_MAX_S = 10.0
STABLE_S = 10.0          # a run at least this long resets the backoff
START_WINDOW_S = 10.0    # a first run that exits with an error sooner than this could not start
STOP_TIMEOUT_S = 10.0    # after SIGINT, then SIGKILL (a process's own: the longest its services ask for)
TAIL_LINES = 20          # output lines kept per service, shown when it cannot start
_POLL_S = 0.1
_READY_TIMEOUT_S = 60.0     # numba warm-up and imports on a loaded 2-core machine take a while


class Output:
    """One writer for every process's lines, so lines never interleave mid-line."""

    def __init__(self) -> None:
        self._lock = threading.Lock()

    def line(self, prefix: str, text: str, stream=None) -> None:
        with self._lock:
            try:
                stream = stream or sys.stdout
                stream.write(f"[{prefix}] {text}\n")
                stream.flush()
            except (BrokenPipeError, ValueError):  # nobody is reading any more; keep supervising
                pass

    def say(self, text: str, stream=None) -> None:
        self.line("up", text, stream)


def describe_exit(returncode: int) -> str:
    if returncode < 0:
        try:
            return f"signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"signal {-returncode}"
    return f"exit code {returncode}"


class CannotStart(RuntimeError):
    """A service whose first run failed on its own within START_WINDOW_S."""

    def __init__(self, service: Supervised, returncode: int):
        super().__init__(f"{service.name} could not start ({describe_exit(returncode)})")
        self.service = service


class Supervised:
    """One process of the compose file (a service, or a container of several): its current OS
    process, restart bookkeeping and output."""

    def __init__(self, spec: ProcessSpec, endpoint: str, params_dir: Path, credentials: Path, out: Output,
                 listeners: tuple[str, ...] = (), stop_timeout_s: float = STOP_TIMEOUT_S):
        self.spec, self.name, self.endpoint, self.out = spec, spec.name, endpoint, out
        self.listeners = listeners      # the tokens its sources wait for (Loaded.listeners)
        self.stop_timeout_s = stop_timeout_s
        self.credentials = credentials / spec.name
        self.params_file = self._write_params(params_dir)
        self.proc: ForkedProcess | None = None
        self.reader: threading.Thread | None = None
        self.tail: collections.deque[str] = collections.deque(maxlen=TAIL_LINES)
        self.runs = 0
        self.started_at = 0.0
        self.backoff = BACKOFF_FIRST_S
        self.restart_at: float | None = None
        self.finished = False
        self.returncode: int | None = None

    def _write_params(self, params_dir: Path) -> Path | None:
        if self.spec.container:     # a compose file of its services alone, for `omninav container`
            path = params_dir / f"{self.name}.compose.yaml"
            entries = [{"name": s.name, **({"module": s.module} if s.module else {"service": s.service}),
                        "robot": s.robot, "params": s.params} for s in self.spec.services]
            path.write_text(yaml.safe_dump({"services": entries}, sort_keys=False))
            return path
        spec = self.spec.services[0]
        if not spec.params:
            return None
        path = params_dir / f"{spec.name}.yaml"
        # the ROS 2 layout, so no parameter can be mistaken for a node-name wrapper when read back
        path.write_text(yaml.safe_dump({spec.name: {"ros__parameters": spec.params}}))
        return path

    def command(self) -> list[str]:
        if self.spec.container:
            return [sys.executable, "-m", "omninav.cli.main", "container", str(self.params_file),
                    "--router", self.endpoint]
        spec = self.spec.services[0]
        cmd = [sys.executable, "-m", "omninav.cli.main", "run", spec.service or spec.name,
               "--robot", spec.robot, "--name", spec.name, "--router", self.endpoint]
        if spec.module:
            cmd += ["--module", spec.module]
        if self.params_file:
            cmd += ["--params", str(self.params_file)]
        return cmd

    def start(self) -> None:
        env = {**os.environ, ROUTER_ENV: self.endpoint, CREDENTIALS_ENV: str(self.credentials),
               LISTENERS_ENV: ",".join(self.listeners), "PYTHONUNBUFFERED": "1"}
        self.proc = ForkedProcess(self.command()[3:], env)
        self.runs += 1
        self.started_at = time.monotonic()
        self.restart_at = None
        self.tail.clear()
        self.reader = threading.Thread(target=self._pump, args=(self.proc,), daemon=True,
                                       name=f"output-{self.name}")
        self.reader.start()
        self.out.say(f"started {self.name} (pid {self.proc.pid})")

    def _pump(self, proc: ForkedProcess) -> None:
        with proc.stdout:
            for raw in proc.stdout:
                text = raw.decode(errors="replace").rstrip("\r\n")
                self.tail.append(text)
                self.out.line(self.name, text)

    def _reaped(self) -> int:
        """Wait for the output of the process that just ended; forget the process."""
        returncode = self.proc.returncode
        if self.reader is not None:
            self.reader.join(5.0)
        self.proc = self.reader = None
        self.returncode = returncode
        return returncode

    def step(self, now: float) -> None:
        """Notice an exit and apply the restart policy; start a due restart. Raises CannotStart."""
        if self.proc is not None and self.proc.poll() is not None:
            ran_s = now - self.started_at
            returncode = self._reaped()
            if self.runs == 1 and returncode > 0 and ran_s < START_WINDOW_S:
                raise CannotStart(self, returncode)
            self._after_exit(returncode, ran_s, now)
        if self.restart_at is not None and now >= self.restart_at:
            self.start()

    def _after_exit(self, returncode: int, ran_s: float, now: float) -> None:
        spec, what = self.spec, f"{self.name} ended with {describe_exit(returncode)} after {ran_s:.1f}s"
        wanted = spec.restart == "always" or (spec.restart == "on-failure" and returncode != 0)
        if not wanted:
            self.finished = True
            self.out.say(f"{what}; not restarted (restart: {spec.restart})")
            return
        if spec.max_restarts is not None and self.runs > spec.max_restarts:
            self.finished = True
            self.out.say(f"{what}; giving up after {spec.max_restarts} restart(s)")
            return
        if ran_s >= STABLE_S:
            self.backoff = BACKOFF_FIRST_S
        self.restart_at = now + self.backoff
        self.out.say(f"{what}; restarting in {self.backoff:.1f}s (restart {self.runs})")
        self.backoff = min(2 * self.backoff, BACKOFF_MAX_S)

    def stop(self) -> None:
        """SIGINT to its process group, then SIGKILL after stop_timeout_s; no restart afterwards."""
        self.restart_at = None
        self.finished = True
        if self.proc is None:
            return
        self.out.say(f"stopping {self.name}")
        self._signal(signal.SIGINT)
        try:
            self.proc.wait(self.stop_timeout_s)
        except subprocess.TimeoutExpired:
            self.out.say(f"{self.name} did not stop within {self.stop_timeout_s:.0f}s; killing it")
            self._signal(signal.SIGKILL)
            self.proc.wait()
        self.out.say(f"{self.name} stopped ({describe_exit(self._reaped())})")

    def _signal(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass


def _cannot_start(exc: CannotStart, out: Output) -> int:
    out.say(f"error: {exc}; its last output:", sys.stderr)
    for text in exc.service.tail:
        out.line(exc.service.name, text, sys.stderr)
    return 1


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("compose", nargs="?", default=DEFAULT_COMPOSE,
                        help=f"compose file (default {DEFAULT_COMPOSE}; format: docs/compose.md)")
    parser.add_argument("--router", help="router endpoint to listen on (default: the compose file's, "
                                         "else $OMNINAV_ROUTER, else tcp/127.0.0.1:7447)")
    parser.add_argument("--for", dest="duration", type=float, metavar="SECONDS",
                        help="stop everything after this many seconds (default: run until Ctrl-C)")
    parser.add_argument("--credentials", metavar="FOLDER",
                        help="write this run's identities here (made readable by you only; default: a "
                             f"temporary folder, printed); your tools find FOLDER/{TOOL} without "
                             f"{CREDENTIALS_ENV} (services/runtime/joining.py)")
    parser.add_argument("--lockstep", nargs="?", const="", metavar="ALSO",
                        help="run in lockstep with the simulator (services/runtime/lockstep.py): the same "
                             "messages at any machine load, as fast as the services compute; the sim waits "
                             "for every service and for ALSO (comma-separated clients such as navigate)")
    parser.add_argument("--prepared", action="store_true",
                        help="take what `prepare` makes of the compose file (loaded, then every identity's "
                             "rights) pickled on stdin rather than from a child of its own: navigate makes it "
                             "in the child that checks its goals, while up starts")


def build_nodes(compose: Compose) -> dict[str, Node]:
    """Every service's Node, built with its parameters as its process will build it (ComposeError
    naming the service whose setup fails: its process would fail the same way)."""
    nodes = {}
    for spec in compose.services:
        try:
            nodes[spec.name] = build_node(spec.service or spec.name, overrides=spec.params, robot=spec.robot,
                                          name=spec.name, node_type=spec.node_type)
        except (UnknownService, ParamError) as exc:
            raise ComposeError(f"{compose.path}: {spec.name}: {exc}") from None
        except Exception as exc:    # its setup() failed
            raise ComposeError(f"{compose.path}: {spec.name} cannot be built to read what it declares: "
                               f"{type(exc).__name__}: {exc}") from None
    return nodes


def identities(compose: Compose) -> dict[str, Grants]:
    """Every identity of a run and what it may do: each process's from the declarations of its
    services' Nodes, built here (a container may do what any of its services may), and the
    hand-started clients'."""
    identity_names(compose)
    nodes = build_nodes(compose)
    grants = client_grants(compose.robot)
    for process in compose.processes:
        grants[process.name] = union(node_grants(nodes[spec.name]) for spec in process.services)
    return grants


@dataclasses.dataclass(frozen=True)
class Loaded:
    """A compose file as `up` runs it, plain data: the specs without their Node classes, and what
    the classes tell (lockstep_participants, the listeners' tokens, each process's stop timeout)."""
    compose: Compose
    participants: list[str]
    listeners: tuple[str, ...]
    stop_timeouts: dict[str, float]


def prepare(compose_path: Path):
    """Yields the compose file Loaded, then, the Nodes built, every identity's rights (ComposeError
    naming what is wrong): `up` runs it in a child process, starting the processes between."""
    compose = load_compose(compose_path)
    plain = tuple(dataclasses.replace(s, node_type=None) for s in compose.services)
    processes = tuple(dataclasses.replace(p, services=tuple(dataclasses.replace(s, node_type=None) for s in p.services))
                      for p in compose.processes)
    yield Loaded(dataclasses.replace(compose, services=plain, processes=processes), lockstep_participants(compose),
                 listeners(compose),
                 {p.name: max(s.node_type.stop_timeout_s for s in p.services) for p in compose.processes})
    yield identities(compose)


def sets_its_own_pace(cls: type) -> bool:
    """Whether a Node class may be a source: it has a pace of its own (the sim, the talker, a map
    server that publishes once), depending on its parameters."""
    return cls.pace_s is not Node.pace_s


def listeners(compose: Compose) -> tuple[str, ...]:
    """The liveliness tokens of the services that set no pace of their own: those a source waits
    for before its first message (an instance of a class that may be a source but is not one with
    its parameters, a map server publishing on the clock, is not waited for)."""
    return tuple(KeyLayout(spec.robot).alive(spec.name) for spec in compose.services
                 if not sets_its_own_pace(spec.node_type))


def lockstep_participants(compose: Compose) -> list[str]:
    """The services that report their progress in a lockstep run: all but the coordinator (the sim)
    and those that talk to Zenoh themselves (the recorder, the view), which nothing waits for."""
    names = []
    for spec in compose.services:
        cls = spec.node_type
        if not cls.coordinates_lockstep and not hasattr(cls, "run_live"):
            names.append(spec.name)
    return names


def identity_names(compose: Compose) -> list[str]:
    """The users of a run: the hand-started clients' and one per process (ComposeError if a
    process takes a client's name)."""
    clients = list(client_grants(compose.robot))
    for process in compose.processes:
        if process.name in clients:
            raise ComposeError(f"{compose.path}: the name {process.name!r} is reserved for an identity of `up`")
    return [*clients, *(process.name for process in compose.processes)]


def main(args: argparse.Namespace) -> int:
    out = Output()
    preparation = Answers(sys.stdin.buffer, "prepare") if args.prepared else Child(prepare, Path(args.compose))
    with preparation as child:
        try:
            loaded: Loaded = child.next()
            compose = loaded.compose
            endpoint = router_endpoint(args.router or compose.router)
            users = identity_names(compose)
            if args.lockstep is not None:
                also = service_names(args.lockstep)
                os.environ[LOCKSTEP_ENV] = Lockstep((*loaded.participants, *also)).env_value()
        except (ComposeError, UnknownService, ValueError, ChildDied) as exc:
            out.say(f"error: {exc}", sys.stderr)
            return 2
        return _launch(args, out, child, loaded, endpoint, users)


def _launch(args: argparse.Namespace, out: Output, child: Answers, loaded: Loaded, endpoint: str, users: list[str]) -> int:
    compose = loaded.compose
    stop = stop_event()
    on_parent_exit(stop.set)        # `navigate` killed outright: the stack it started stops all the same
    with tempfile.TemporaryDirectory(prefix="omninav-up-") as params_dir:
        credentials = Path(args.credentials or Path(params_dir) / "credentials")
        try:
            dictionary = write_passwords(credentials, users)
        except OSError as exc:
            out.say(f"error: cannot write the credentials to {credentials}: {exc.strerror}", sys.stderr)
            return 1
        services = [Supervised(spec, endpoint, Path(params_dir), credentials, out, loaded.listeners,
                               loaded.stop_timeouts[spec.name])
                    for spec in compose.processes]
        # every process starts now: they import and build their nodes while the child builds them too
        # (for the rights), and connect once the router is open; the sources then wait for the others
        for service in services:
            service.start()
        try:
            grants: dict[str, Grants] = child.next()
            child.close()
            write_puts(credentials, grants)
            router = open_router(endpoint, dictionary, access_control(grants))
        except (ComposeError, ChildDied, OSError, zenoh.ZError) as exc:
            for service in reversed(services):
                service.stop()
            return _not_started(exc, credentials, endpoint, out)
        # the entry only once the router holds the endpoint: a run that could not open it leaves another's alone
        with router, published(endpoint, credentials / TOOL, out.say) as entry:
            out.say(f"router listening on {endpoint}")
            out.say(f"identities in {credentials}; this user's tools log in with {entry or credentials / TOOL} "
                    f"(the run's read-only identity; {CREDENTIALS_ENV} names another)")
            return _run(services, stop, args.duration, out, router)


def _not_started(exc: Exception, credentials: Path, endpoint: str, out: Output) -> int:
    if isinstance(exc, ComposeError):       # a service's setup failed
        out.say(f"error: {exc}", sys.stderr)
        return 2
    if isinstance(exc, ChildDied):
        out.say(f"error: {exc}", sys.stderr)
        return 1
    if isinstance(exc, OSError):
        out.say(f"error: cannot write the credentials to {credentials}: {exc.strerror}", sys.stderr)
    else:
        out.say(f"error: cannot start the router on {endpoint}: {exc}", sys.stderr)
    return 1


def _run(services: list[Supervised], stop: threading.Event, duration: float | None, out: Output,
         router: zenoh.Session) -> int:
    try:
        return _supervise(services, stop, duration, out, router)
    finally:
        for service in reversed(services):
            service.stop()
        out.say("stopped")


def _wait_ready(services: list[Supervised], session: zenoh.Session, stop: threading.Event, out: Output) -> None:
    """Until the liveliness token of each service of these processes appears (raises CannotStart if
    one dies meanwhile), saying which did not within _READY_TIMEOUT_S."""
    waiting = {KeyLayout(spec.robot).alive(spec.name): service for service in services for spec in service.spec.services}
    deadline = time.monotonic() + _READY_TIMEOUT_S
    while not stop.is_set() and time.monotonic() < deadline:
        for key in tokens_present(session, waiting, _POLL_S):
            del waiting[key]
        for service in {id(s): s for s in waiting.values()}.values():
            service.step(time.monotonic())
        waiting = {key: service for key, service in waiting.items() if not service.finished}
        if not waiting:
            return
        stop.wait(_POLL_S / 2)
    if not stop.is_set():
        late = sorted({service.name for service in waiting.values()})
        out.say(f"{', '.join(late)} did not report ready within {_READY_TIMEOUT_S:.0f}s")


def _supervise(services: list[Supervised], stop: threading.Event, duration: float | None, out: Output,
               session: zenoh.Session) -> int:
    try:
        _wait_ready(services, session, stop, out)
    except CannotStart as exc:
        return _cannot_start(exc, out)
    deadline = None if duration is None else time.monotonic() + duration
    while not stop.wait(_POLL_S):
        now = time.monotonic()
        if deadline is not None and now >= deadline:
            break
        try:
            for service in services:
                service.step(now)
        except CannotStart as exc:
            return _cannot_start(exc, out)
        if all(s.finished for s in services):
            out.say("every service has ended")
            return 0 if all(s.returncode == 0 for s in services) else 1
    return 0
