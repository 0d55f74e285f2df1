"""Tools that just join (services/runtime/joining.py): `up` leaves its run's read-only tool identity
as this user's entry for its router's endpoint; `topics`, `echo`, `get`, `record` log in with it unless
$OMNINAV_CREDENTIALS names another; a refused login and an absent router each say one line."""
import json
import os
import signal
import stat
import tempfile

import pytest

from omninav.services.runtime.acl import CREDENTIALS_ENV, TOOL, Grants, write_credentials
from omninav.services.runtime.joining import FolderRefused, entry_name, published, runtime_folder
from omninav.services.runtime.zenoh_config import ROUTER_ENV, open_router

from conftest import free_port, wait_until
from launching import TALKER_LISTENER

EXIT_TIMEOUT_S = 60


@pytest.fixture
def runtime(tmp_path, monkeypatch):
    """This test's own runtime folder ($XDG_RUNTIME_DIR, 0700), inherited by what it starts; no
    $OMNINAV_CREDENTIALS (the `up` fixture sets the tool one)."""
    run = tmp_path / "xdg"
    run.mkdir(mode=0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(run))
    monkeypatch.delenv(CREDENTIALS_ENV, raising=False)
    return run / "omninav"


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _finished(procs, proc) -> tuple[int, list[str]]:
    return proc.wait(EXIT_TIMEOUT_S), procs.log_of(proc).splitlines()


def test_tools_join_up_through_its_entry_and_omninav_credentials_wins(up, endpoint, runtime, tmp_path, monkeypatch):
    monkeypatch.setenv(ROUTER_ENV, endpoint)       # as the README's live view: OMNINAV_ROUTER, nothing else
    launcher = up(TALKER_LISTENER)
    entry = runtime / entry_name(endpoint)
    wait_until(entry.exists, 60, what="up's entry for its router")
    assert entry.read_text() == (up.credentials / TOOL).read_text()    # the tool identity, nothing else
    assert (_mode(runtime), _mode(entry)) == (0o700, 0o600)
    assert entry.name == endpoint.replace("/", "%2F").replace(":", "%3A")
    assert [p.name for p in runtime.iterdir()] == [entry.name]

    procs = up.procs
    echo = procs.omninav("echo", "omninav/r1/chatter", "--count", "2", "--json")
    code, lines = _finished(procs, echo)
    assert code == 0 and len(lines) == 2 and json.loads(lines[0])["key"] == "omninav/r1/chatter", lines
    topics = procs.omninav("topics", "--duration", "2", "--json")
    get = procs.omninav("get", "omninav/r1/echo", "--json")
    (forged := tmp_path / "forged").write_text("tool:not-its-password\n")
    forged_get = procs.omninav("get", "omninav/r1/echo", env={CREDENTIALS_ENV: str(forged)})
    record = procs.omninav("record", "-o", str(tmp_path / "joined.mcap"), "omninav/r1/chatter")
    wait_until(lambda: "recording omninav/r1/chatter to" in procs.log_of(record) or record.poll() is not None, 60,
               what="record logged in and subscribed")
    assert procs.stop(record) == 0, procs.log_of(record)
    code, lines = _finished(procs, topics)
    assert code == 0 and "omninav/r1/chatter" in {t["key"] for t in json.loads(lines[-1])["topics"]}, lines
    code, lines = _finished(procs, get)
    assert code == 0 and json.loads(lines[0])["key"] == "omninav/r1/echo", lines
    code, lines = _finished(procs, forged_get)     # $OMNINAV_CREDENTIALS wins over the entry that works
    assert code == 1 and lines == [
        f"omninav get: the router {endpoint} refused the login of identity 'tool' from {CREDENTIALS_ENV}={forged}; "
        f"is that file of the run that started this router? (it is <run>/credentials/tool)"]

    assert procs.stop(launcher, signal.SIGINT) == 0
    assert not entry.exists()


def test_up_replaces_a_stale_entry_and_removes_it_at_sigterm(up, endpoint, runtime):
    runtime.mkdir(mode=0o700)
    entry = runtime / entry_name(endpoint)
    entry.write_text("tool:a-killed-run's-password\n")
    launcher = up(TALKER_LISTENER)
    wait_until(lambda: entry.read_text() == (up.credentials / TOOL).read_text(), 60, what="up replacing the stale entry")
    assert _mode(entry) == 0o600
    assert up.procs.stop(launcher, signal.SIGTERM) == 0
    assert not entry.exists()


def test_no_router_and_a_refused_login_each_say_one_line(processes_no_router, runtime, tmp_path):
    procs = processes_no_router
    absent = f"tcp/127.0.0.1:{free_port()}"
    nobody = procs.omninav("get", "omninav/r1/echo", "--timeout", "1", "--router", absent)

    ids = tmp_path / "ids"
    dictionary = write_credentials(ids, {TOOL: Grants(subscribe=("omninav/**",))})
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    runtime.mkdir(mode=0o700)
    stale = runtime / entry_name(endpoint)
    with open_router(endpoint, dictionary):
        stale.write_text("tool:a-killed-run's-password\n")
        with_stale = procs.omninav("get", "omninav/r1/echo", "--timeout", "2", "--router", endpoint)
        code, lines = _finished(procs, with_stale)
        assert code == 1 and lines == [
            f"omninav get: the router {endpoint} refused the login of identity 'tool' from {stale}; is the run "
            f"that started it still going? else set {CREDENTIALS_ENV}=<run>/credentials/tool"]
        stale.unlink()
        no_identity = procs.omninav("topics", "--router", endpoint)      # it waits for a router, not for this
        recorder = procs.omninav("record", "-o", str(tmp_path / "refused.mcap"), "--router", endpoint)
        code, lines = _finished(procs, recorder)    # not taken for a disk failing
        assert code == 1 and f"ERROR [record] the router {endpoint} refused a login with no identity" in lines[-1], lines
        code, lines = _finished(procs, no_identity)
        assert code == 1 and lines == [
            f"omninav topics: the router {endpoint} refused a login with no identity (no {CREDENTIALS_ENV}, "
            f"no entry {stale}); is it a run of `omninav up` by another user or one whose entry was refused? "
            f"set {CREDENTIALS_ENV}=<run>/credentials/tool"]
    code, lines = _finished(procs, nobody)
    assert code == 1 and lines == [f"omninav get: no router listening at {absent} (waited 1 s; start one with "
                                   f"`omninav up` or `omninav router`)"]


def test_a_folder_others_may_use_or_another_user_owns_is_refused(runtime, tmp_path, monkeypatch):
    assert runtime_folder() == runtime and _mode(runtime) == 0o700      # made on first use
    os.chmod(runtime, 0o755)
    with pytest.raises(FolderRefused, match=f"not using {runtime} for the run's tool identity: its mode is 0755 "
                                            f"\\(it must be a folder of uid {os.getuid()} with mode 0700\\)"):
        runtime_folder()
    said = []
    with published("tcp/127.0.0.1:7447", tmp_path / "tool", said.append) as entry:    # up goes on without
        assert entry is None
    assert said == [f"not using {runtime} for the run's tool identity: its mode is 0755 (it must be a folder of "
                    f"uid {os.getuid()} with mode 0700); tools need {CREDENTIALS_ENV}={tmp_path / 'tool'}"]
    if os.getuid() == 0:
        os.chmod(runtime, 0o700)
        os.chown(runtime, 12345, -1)
        with pytest.raises(FolderRefused, match="it belongs to uid 12345"):
            runtime_folder()
    # an $XDG_RUNTIME_DIR that is not this user's private folder is not used: the temp dir's is
    os.chmod(runtime.parent, 0o755)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert runtime_folder() == tmp_path / f"omninav-{os.getuid()}"


def test_a_service_refused_by_its_router_says_so_once_and_goes_on_trying_until_stopped(up, endpoint, runtime, tmp_path):
    """A service is no tool: three slow handshakes on a loaded machine are no proof of a refused login,
    so it does not give up; it says once why it does not come up, and stops when asked."""
    up(TALKER_LISTENER)
    (forged := tmp_path / "forged").write_text("talker:not-its-password\n")
    procs = up.procs
    talker = procs.omninav("run", "talker", "--name", "talker2", "--router", endpoint, env={CREDENTIALS_ENV: str(forged)})
    wait_until(lambda: "refused the login" in procs.log_of(talker), 60, what="the service saying its login was refused")
    assert talker.poll() is None
    assert procs.stop(talker) == 0 and procs.log_of(talker).count("refused the login") == 1
