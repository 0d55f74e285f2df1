"""Shared fixtures: a loopback router per test and OS processes that are always stopped."""
from __future__ import annotations

import os
import signal
import subprocess
import textwrap
import sys
import time
from pathlib import Path

import pytest
from hypothesis import settings

from omninav.schemas.keys import KeyLayout
from omninav.services.runtime.acl import CREDENTIALS_ENV, DICTIONARY, TOOL
from omninav.services.runtime.lockstep import LOCKSTEP_ENV, Lockstep
from omninav.services.runtime.zenoh_config import ROUTER_ENV, free_loopback_port, open_client, open_router

from launching import processes_using

# tests assert behaviour, never timing: Hypothesis's per-example deadline (200 ms) failed property
# tests on a loaded machine
settings.register_profile("behaviour", deadline=None)
settings.load_profile("behaviour")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


def free_port() -> int:
    return free_loopback_port()


def wait_until(predicate, timeout: float = 10.0, interval: float = 0.05, what: str = "condition"):
    """Poll until predicate() is truthy; fail the test naming `what` if it never is."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    pytest.fail(f"timed out after {timeout}s waiting for {what}")


def wait_alive(endpoint: str, names, timeout: float = 180.0, robot: str = "r1") -> None:
    """Until every named service has declared its liveliness token (it can hear and speak)."""
    keys = KeyLayout(robot)
    with open_client(endpoint) as session:
        def all_alive():
            return all(any(r.ok is not None for r in session.liveliness().get(keys.alive(n), timeout=0.5))
                       for n in names)
        wait_until(all_alive, timeout, what=f"services {list(names)} to be ready")


@pytest.fixture
def router_endpoint():
    """A router on a free loopback port, in this process, for the duration of one test."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with open_router(endpoint):
        yield endpoint


class Processes:
    """Starts `omninav …` as child processes (own process groups) and stops every one at the end."""

    def __init__(self, tmp_path: Path, endpoint: str | None):
        self.tmp_path, self.endpoint = tmp_path, endpoint
        self.started: list[tuple[subprocess.Popen, Path]] = []
        self.lockstep_env: dict[str, str] = {}

    def in_lockstep(self, *names: str) -> None:
        """Every process started from now on steps with the simulator (services/runtime/lockstep.py);
        the sim waits for the named services (teleop included) before its first step."""
        self.lockstep_env = {LOCKSTEP_ENV: Lockstep(names).env_value()}

    def omninav(self, *args: str, env: dict | None = None, cwd: Path | None = None) -> subprocess.Popen:
        log = self.tmp_path / f"proc{len(self.started)}-{args[0]}.log"
        full_env = {**os.environ, **({ROUTER_ENV: self.endpoint} if self.endpoint else {}), **self.lockstep_env,
                    **(env or {})}
        proc = subprocess.Popen([sys.executable, "-m", "omninav.cli.main", *args], cwd=cwd or REPO,
                                env=full_env, stdout=open(log, "wb"), stderr=subprocess.STDOUT,
                                start_new_session=True)
        self.started.append((proc, log))
        return proc

    @staticmethod
    def output(proc_log: Path) -> str:
        return proc_log.read_text(errors="replace")

    def log_of(self, proc: subprocess.Popen) -> str:
        return next(self.output(log) for p, log in self.started if p is proc)

    @staticmethod
    def stop(proc: subprocess.Popen, sig: int = signal.SIGINT, timeout: float = 120.0) -> int:
        """The exit code once proc has stopped; the timeout is the recorder's stop_timeout_s: a
        recorder draining a lockstep sim's backlog had not stopped after 30 s (a fresh clone's suite
        beside two exploration benches on 2 cores)."""
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                pass
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGUSR1)     # any omninav command prints its threads' stacks to its log
                time.sleep(1.0)
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5)
        return proc.returncode

    def stop_all(self) -> None:
        for proc, _ in reversed(self.started):
            self.stop(proc)
            try:  # also anything it started in its group
                os.killpg(proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass


@pytest.fixture
def processes(tmp_path, router_endpoint):
    procs = Processes(tmp_path, router_endpoint)
    yield procs
    procs.stop_all()


@pytest.fixture
def processes_no_router(tmp_path):
    """For commands that start their own router (omninav up)."""
    procs = Processes(tmp_path, None)
    yield procs
    procs.stop_all()


@pytest.fixture
def endpoint():
    """A free loopback endpoint for `up`; afterwards nothing that used it may survive."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    yield endpoint
    for pid in processes_using(endpoint):  # only if a test failed half-way: never leave processes
        os.kill(pid, signal.SIGKILL)


@pytest.fixture
def up(endpoint, processes_no_router, tmp_path, monkeypatch):
    """Start `omninav up` on a compose text; `processes_no_router` stops it at the end. The run's
    identities go to `start.credentials`; this test's own sessions use the read-only tool one."""
    credentials = tmp_path / "credentials"

    def start(compose_text: str, *extra: str, env: dict | None = None):
        compose = tmp_path / "compose.yaml"
        compose.write_text(textwrap.dedent(compose_text))
        launcher = processes_no_router.omninav("up", str(compose), "--router", endpoint, "--credentials",
                                               str(credentials), *extra, env=env)
        # written before the router starts; a compose file that fails validation writes none
        wait_until(lambda: (credentials / DICTIONARY).exists() or launcher.poll() is not None, 60,
                   what="up writing the run's identities")
        return launcher
    monkeypatch.setenv(CREDENTIALS_ENV, str(credentials / TOOL))
    start.procs = processes_no_router
    start.credentials = credentials
    return start
