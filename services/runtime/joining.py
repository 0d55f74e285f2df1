"""Tools that just join: the run's read-only identity where the same Unix user's tools find it.

`omninav up` writes its run's `tool` identity (acl.TOOL: subscribe, get, liveliness, nothing else)
into a per-user runtime folder once its router is open, as one file named after the router's
endpoint, and removes it when the run ends. `view`, `topics`, `echo`, `hz`, `get` and `record`
connecting to that endpoint log in with it, unless $OMNINAV_CREDENTIALS names a file (which wins).

Threat model: processes of the same Unix user are trusted to read the run's read-only identity
(they can read its credentials folder anyway); other users are not, so the folder must be this
user's own with no group or other permissions, and is refused otherwise. Only the tool identity is
placed there, never the operator's, teleop's or a service's.

A refused login and an absent router look alike to zenoh 1.10 (zenoh.open raises "Unable to connect
to any of [...]. Timeout!" for both); what tells them apart is whether anything accepts a connection
on the endpoint (`listening`).
"""
from __future__ import annotations

import os
import socket
import stat
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator
from urllib.parse import quote

from .acl import CREDENTIALS_ENV, TOOL, read_credentials, write_private

FOLDER_NAME = "omninav"
_PROBE_S = 0.5


class FolderRefused(RuntimeError):
    """The runtime folder exists but is not this user's alone: nothing is read from it or written to it."""


class LoginRefused(RuntimeError):      # not an OSError: the recorder reads those as a disk failing
    """A router listens on the endpoint but does not let this client log in."""


def runtime_folder() -> Path:
    """This user's folder for the entries, made (0700) if missing: $XDG_RUNTIME_DIR/omninav when
    $XDG_RUNTIME_DIR is this user's private folder, else <temp dir>/omninav-<uid>. FolderRefused
    naming the folder and what is wrong with it when another user owns it or others may use it."""
    xdg = os.environ.get("XDG_RUNTIME_DIR")
    base = Path(xdg) if xdg and _private(Path(xdg)) is None else None
    folder = base / FOLDER_NAME if base else Path(tempfile.gettempdir()) / f"{FOLDER_NAME}-{os.getuid()}"
    try:
        folder.mkdir(mode=0o700)
    except FileExistsError:
        pass
    problem = _private(folder)
    if problem:
        raise FolderRefused(f"not using {folder} for the run's tool identity: {problem} "
                            f"(it must be a folder of uid {os.getuid()} with mode 0700)")
    return folder


def _private(folder: Path) -> str | None:
    """None if folder is a directory (not a link) of this user that nobody else may use, else what is wrong."""
    try:
        info = folder.lstat()
    except OSError as exc:
        return f"cannot read it ({exc.strerror})"
    if not stat.S_ISDIR(info.st_mode):
        return "it is not a folder"
    if info.st_uid != os.getuid():
        return f"it belongs to uid {info.st_uid}"
    if info.st_mode & 0o077:
        return f"its mode is {stat.S_IMODE(info.st_mode):04o}"
    return None


def entry_name(endpoint: str) -> str:
    """The file name of an endpoint's entry: the endpoint with every character but letters, digits
    and . - _ percent-encoded (tcp/127.0.0.1:7447 -> tcp%2F127.0.0.1%3A7447)."""
    return quote(endpoint, safe="")


@contextmanager
def published(endpoint: str, tool_file: Path, say: Callable[[str], None]) -> Iterator[Path | None]:
    """While the run's router is open on endpoint: a copy of its tool identity as that endpoint's
    entry (0600, replacing a stale one of a run that was killed), removed at the end. A refused
    folder is said in one line and the run goes on without an entry."""
    try:
        entry = runtime_folder() / entry_name(endpoint)
        text = tool_file.read_text()
        write_private(entry, text)
    except FolderRefused as exc:
        say(f"{exc}; tools need {CREDENTIALS_ENV}={tool_file}")
        entry = None
    try:
        yield entry
    finally:
        if entry is not None:
            forget(endpoint, only_if=text)


def forget(endpoint: str, only_if: str | None = None) -> None:
    """Remove the endpoint's entry (if its text is only_if, when given): its run has ended, or a
    router that is not a run's opened on the endpoint (`omninav router`)."""
    try:
        entry = runtime_folder() / entry_name(endpoint)
        if only_if is None or entry.read_text() == only_if:
            entry.unlink()
    except (FolderRefused, OSError):
        pass


@dataclass(frozen=True)
class Identity:
    """Who a client logs in as: user and password (None: no identity) and where they came from."""
    user: str | None
    password: str | None
    source: str         # a path, or a sentence saying why there is none


NO_IDENTITY_HINT = f"set {CREDENTIALS_ENV}=<run>/credentials/{TOOL}"


def login_identity(endpoint: str, credentials: str | None = None, as_tool: bool = False,
                   warn: Callable[[str], None] | None = None) -> Identity:
    """The identity to log in to endpoint with: the credentials file given, else $OMNINAV_CREDENTIALS's,
    else (a tool) the endpoint's entry in the runtime folder, else none. warn hears a refused folder."""
    given = credentials or os.environ.get(CREDENTIALS_ENV)
    if given:
        return Identity(*read_credentials(given), f"{CREDENTIALS_ENV}={given}")
    if not as_tool:
        return Identity(None, None, f"no {CREDENTIALS_ENV}")
    try:
        entry = runtime_folder() / entry_name(endpoint)
    except FolderRefused as exc:
        if warn:
            warn(str(exc))
        return Identity(None, None, f"no {CREDENTIALS_ENV}; the runtime folder is refused")
    try:
        return Identity(*read_credentials(entry), str(entry))
    except ValueError:      # no run has its router there (or it has just ended)
        return Identity(None, None, f"no {CREDENTIALS_ENV}, no entry {entry}")


def refusal(endpoint: str, identity: Identity) -> LoginRefused:
    """The one line a refused login says: the router, the identity tried, the fix."""
    if identity.user is None:
        return LoginRefused(f"the router {endpoint} refused a login with no identity ({identity.source}); "
                            f"is it a run of `omninav up` by another user or one whose entry was refused? "
                            f"{NO_IDENTITY_HINT}")
    if identity.source.startswith(CREDENTIALS_ENV):
        return LoginRefused(f"the router {endpoint} refused the login of identity '{identity.user}' from "
                            f"{identity.source}; is that file of the run that started this router? "
                            f"(it is <run>/credentials/{TOOL})")
    return LoginRefused(f"the router {endpoint} refused the login of identity '{identity.user}' from "
                        f"{identity.source}; is the run that started it still going? else {NO_IDENTITY_HINT}")


def listening(endpoint: str) -> bool:
    """Whether anything accepts a connection on the endpoint (tcp, tls or a unix socket; other
    protocols - quic, udp - cannot be probed: False)."""
    proto, _, address = endpoint.partition("/")
    address = address.partition("#")[0]
    if proto == "unixsock-stream":
        family, target = socket.AF_UNIX, address
    elif proto in ("tcp", "tls") and address.rpartition(":")[2].isdigit():
        host, _, port = address.rpartition(":")
        host = host.strip("[]")
        family, target = (socket.AF_INET6 if ":" in host else socket.AF_INET), (host, int(port))
    else:
        return False
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.settimeout(_PROBE_S)
        try:
            probe.connect(target)
        except OSError:
            return False
    return True
