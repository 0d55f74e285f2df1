"""`omninav up [COMPOSE]`: a loopback router in this process and every service as its own process.

Each service runs as `omninav run …` in its own process group, so a Ctrl-C in the terminal reaches
only the launcher, which then stops the services itself in reverse order (the recorder, listed
first, stops last and records everything). Output lines are prefixed with the service's name.
Restart policy and start-failure rules: docs/compose.md.

Every run gets fresh identities (acl.py): one per service, plus the tool, teleop and operator ones
for processes started by hand, written to a folder only this user can read; each service finds
its own through $OMNINAV_CREDENTIALS, and the router admits only those users and lets each do
only what its Node declares.
"""
from __future__ import annotations

import argparse
import collections
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
from .acl import CREDENTIALS_ENV, TOOL, Grants, access_control, client_grants, node_grants, write_credentials
from .compose import Compose, ComposeError, ServiceSpec, load_compose
from .params import ParamError
from .service_registry import UnknownService
from .run import build_node
from .zenoh_config import ROUTER_ENV, open_router, router_endpoint

DEFAULT_COMPOSE = "compose/demo.yaml"
BACKOFF_FIRST_S = 0.5
BACKOFF_MAX_S = 10.0
STABLE_S = 10.0          # a run at least this long resets the backoff
START_WINDOW_S = 10.0    # a first run that exits with an error sooner than this could not start
STOP_TIMEOUT_S = 10.0    # after SIGINT, then SIGKILL
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
        super().__init__(f"{service.spec.name} could not start ({describe_exit(returncode)})")
        self.service = service


class Supervised:
    """One service of the compose file: its current process, restart bookkeeping and output."""

    def __init__(self, spec: ServiceSpec, endpoint: str, params_dir: Path, credentials: Path, out: Output):
        self.spec, self.endpoint, self.out = spec, endpoint, out
        self.credentials = credentials / spec.name
        self.params_file = self._write_params(params_dir)
        self.proc: subprocess.Popen | None = None
        self.reader: threading.Thread | None = None
        self.tail: collections.deque[str] = collections.deque(maxlen=TAIL_LINES)
        self.runs = 0
        self.started_at = 0.0
        self.backoff = BACKOFF_FIRST_S
        self.restart_at: float | None = None
        self.finished = False
        self.returncode: int | None = None

    def _write_params(self, params_dir: Path) -> Path | None:
        if not self.spec.params:
            return None
        path = params_dir / f"{self.spec.name}.yaml"
        # the ROS 2 layout, so no parameter can be mistaken for a node-name wrapper when read back
        path.write_text(yaml.safe_dump({self.spec.name: {"ros__parameters": self.spec.params}}))
        return path

    def command(self) -> list[str]:
        spec = self.spec
        cmd = [sys.executable, "-m", "omninav.cli.main", "run", spec.service or spec.name,
               "--robot", spec.robot, "--name", spec.name, "--router", self.endpoint]
        if spec.module:
            cmd += ["--module", spec.module]
        if self.params_file:
            cmd += ["--params", str(self.params_file)]
        return cmd

    def start(self) -> None:
        env = {**os.environ, ROUTER_ENV: self.endpoint, CREDENTIALS_ENV: str(self.credentials), "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen(self.command(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, env=env, process_group=0)
        self.runs += 1
        self.started_at = time.monotonic()
        self.restart_at = None
        self.tail.clear()
        self.reader = threading.Thread(target=self._pump, args=(self.proc,), daemon=True,
                                       name=f"output-{self.spec.name}")
        self.reader.start()
        self.out.say(f"started {self.spec.name} (pid {self.proc.pid})")

    def _pump(self, proc: subprocess.Popen) -> None:
        with proc.stdout:
            for raw in proc.stdout:
                text = raw.decode(errors="replace").rstrip("\r\n")
                self.tail.append(text)
                self.out.line(self.spec.name, text)

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
        spec, what = self.spec, f"{self.spec.name} ended with {describe_exit(returncode)} after {ran_s:.1f}s"
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
        """SIGINT to its process group, then SIGKILL after STOP_TIMEOUT_S; no restart afterwards."""
        self.restart_at = None
        self.finished = True
        if self.proc is None:
            return
        self.out.say(f"stopping {self.spec.name}")
        self._signal(signal.SIGINT)
        try:
            self.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.out.say(f"{self.spec.name} did not stop within {STOP_TIMEOUT_S:.0f}s; killing it")
            self._signal(signal.SIGKILL)
            self.proc.wait()
        self.out.say(f"{self.spec.name} stopped ({describe_exit(self._reaped())})")

    def _signal(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass


def _cannot_start(exc: CannotStart, out: Output) -> int:
    out.say(f"error: {exc}; its last output:", sys.stderr)
    for text in exc.service.tail:
        out.line(exc.service.spec.name, text, sys.stderr)
    return 1


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("compose", nargs="?", default=DEFAULT_COMPOSE,
                        help=f"compose file (default {DEFAULT_COMPOSE}; format: docs/compose.md)")
    parser.add_argument("--router", help="router endpoint to listen on (default: the compose file's, "
                                         "else $OMNINAV_ROUTER, else tcp/127.0.0.1:7447)")
    parser.add_argument("--for", dest="duration", type=float, metavar="SECONDS",
                        help="stop everything after this many seconds (default: run until Ctrl-C)")
    parser.add_argument("--credentials", metavar="FOLDER",
                        help="write this run's identities here (made readable by you only); tools use "
                             f"{CREDENTIALS_ENV}=FOLDER/{TOOL} (default: a temporary folder, printed)")


def identities(compose: Compose) -> dict[str, Grants]:
    """Every identity of a run and what it may do: each service's from its own Node's declarations
    (built with its parameters, as its process will build it), and the hand-started clients'."""
    grants = client_grants(compose.robot)
    for spec in compose.services:
        if spec.name in grants:
            raise ComposeError(f"{compose.path}: service name {spec.name!r} is reserved for an identity of `up`")
        try:
            node = build_node(spec.service or spec.name, overrides=spec.params, robot=spec.robot, name=spec.name,
                              spec=spec.module)
        except (UnknownService, ParamError) as exc:
            raise ComposeError(f"{compose.path}: {spec.name}: {exc}") from None
        except Exception as exc:    # its setup() failed: its process would fail the same way
            raise ComposeError(f"{compose.path}: {spec.name} cannot be built to read what it declares: "
                               f"{type(exc).__name__}: {exc}") from None
        grants[spec.name] = node_grants(node)
    return grants


def main(args: argparse.Namespace) -> int:
    out = Output()
    try:
        compose = load_compose(args.compose)
        endpoint = router_endpoint(args.router or compose.router)
        grants = identities(compose)
    except (ComposeError, ValueError) as exc:
        out.say(f"error: {exc}", sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with tempfile.TemporaryDirectory(prefix="omninav-up-") as params_dir:
        credentials = Path(args.credentials or Path(params_dir) / "credentials")
        try:
            dictionary = write_credentials(credentials, grants)
            router = open_router(endpoint, dictionary, access_control(grants))
        except OSError as exc:
            out.say(f"error: cannot write the credentials to {credentials}: {exc.strerror}", sys.stderr)
            return 1
        except zenoh.ZError as exc:
            out.say(f"error: cannot start the router on {endpoint}: {exc}", sys.stderr)
            return 1
        with router:
            out.say(f"router listening on {endpoint}")
            out.say(f"identities in {credentials} (tools: {CREDENTIALS_ENV}={credentials / TOOL})")
            services = [Supervised(spec, endpoint, Path(params_dir), credentials, out) for spec in compose.services]
            return _run(services, stop, args.duration, out, router)


def _run(services: list[Supervised], stop: threading.Event, duration: float | None, out: Output,
         router: zenoh.Session) -> int:
    try:
        return _supervise(services, stop, duration, out, router)
    finally:
        for service in reversed(services):
            service.stop()
        out.say("stopped")


def _wait_ready(service: Supervised, session: zenoh.Session, stop: threading.Event, out: Output) -> None:
    """Until the service's liveliness token appears, so what it records or answers is in place
    before the next one starts publishing (raises CannotStart if it dies meanwhile)."""
    key = KeyLayout(service.spec.robot).alive(service.spec.name)
    deadline = time.monotonic() + _READY_TIMEOUT_S
    while not stop.is_set() and time.monotonic() < deadline:
        if any(reply.ok is not None for reply in session.liveliness().get(key, timeout=_POLL_S)):
            return
        service.step(time.monotonic())
        if service.finished:
            return
        stop.wait(_POLL_S)
    if not stop.is_set():
        out.say(f"{service.spec.name} did not report ready within {_READY_TIMEOUT_S:.0f}s; starting the rest anyway")


def _supervise(services: list[Supervised], stop: threading.Event, duration: float | None, out: Output,
               session: zenoh.Session) -> int:
    try:
        for service in services:
            service.start()
            _wait_ready(service, session, stop, out)
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
