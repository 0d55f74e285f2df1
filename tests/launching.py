"""Shared by the tests that start processes (`omninav up`, `navigate`): processes seen through
/proc, a compose text, echo counting, waiting on a process's log."""
import os
import re
import subprocess
import time
from pathlib import Path

from omninav.schemas import decode

TALKER_LISTENER = """\
    services:
      - name: talker
        service: talker
        params: {rate: 4}
      - name: listener
        service: listener
    """


# ------------------------------------------------------------------ processes seen through /proc

def _stat(pid: int) -> tuple[str, int] | None:
    """(state, parent pid) of a process, None if it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return fields[0], int(fields[1])


def _cmdline(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except (FileNotFoundError, ProcessLookupError):
        return []


def _all_pids() -> list[int]:
    return [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit()]


def alive(pid: int) -> bool:
    stat = _stat(pid)
    return stat is not None and stat[0] != "Z"


def children(pid: int) -> list[int]:
    return [p for p in _all_pids() if (_stat(p) or ("", 0))[1] == pid and alive(p)]


def descendants(pid: int) -> list[int]:
    found, todo = [], [pid]
    while todo:
        kids = children(todo.pop())
        found += kids
        todo += kids
    return found


def launched(up_pid: int) -> list[int]:
    """The processes `up` started, services or containers (forked from its fork server: its
    grandchildren), by their command lines."""
    return [p for p in descendants(up_pid) if "omninav.cli.main" in _cmdline(p)]


def service_pids(up_pid: int) -> dict[str, int]:
    """name -> pid of the `omninav run … --name NAME` processes `up` started (forked from its fork
    server: its grandchildren)."""
    out = {}
    for pid in descendants(up_pid):
        cmd = _cmdline(pid)
        if "run" in cmd and "--name" in cmd:
            out[cmd[cmd.index("--name") + 1]] = pid
    return out


def processes_using(endpoint: str) -> list[int]:
    """Every live process started for this test: `up` and its services all carry the endpoint."""
    return [p for p in _all_pids() if p != os.getpid() and endpoint in _cmdline(p) and alive(p)]


def echo_subscriber(session, echoes: list):
    return session.declare_subscriber("omninav/r1/echo", lambda s: echoes.append(decode(s.payload.to_bytes())))


def count_echoes(echoes: list) -> int:
    return sum(m.text.startswith("echo:") for m in list(echoes))


def command_chain(processes) -> list:
    """The gates between teleop and the chassis as processes: teleop puts cmd_vel_teleop, the mux
    passes it to the smoother, and only the collision monitor puts cmd_vel."""
    return [processes.omninav("run", name) for name in ("cmd_vel_mux", "velocity_smoother", "collision_monitor")]


def router_of(log: Path) -> str | None:
    """The endpoint `up` said its router listens on, in a services.log, once it has said so."""
    found = re.search(r"router listening on (\S+)", log.read_text(errors="replace")) if log.exists() else None
    return found.group(1) if found else None


def wait_for(condition, process: subprocess.Popen, what: str, seconds: float = 300.0):
    """condition()'s first true value; fails if the process ends first (a liveness bound, not a timing)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        assert process.poll() is None, f"the process ended (exit {process.returncode}) before {what}"
        time.sleep(0.2)
    raise AssertionError(f"no {what} within {seconds:g} s")
