"""`up`'s services forked from one prepared interpreter (services/runtime/forked.py): each behaves
as `python -m omninav.cli.main …` started afresh would — its output, its exit code, its environment,
its own process group, its command line, and it stops when asked."""
import os
import signal

from omninav.services.runtime.forked import ForkedProcess

from conftest import free_port, wait_until


def test_a_forked_command_gives_its_output_and_exit_code():
    listing = ForkedProcess(["services"], dict(os.environ))
    assert b"chassis" in listing.stdout.read()
    assert listing.wait(60) == 0
    unknown = ForkedProcess(["run", "no_such_service"], dict(os.environ))
    assert b"no_such_service" in unknown.stdout.read()
    assert unknown.wait(60) == 2


def test_a_forked_service_runs_in_the_environment_it_is_given():
    off_loopback = ForkedProcess(["run", "talker"], {**os.environ, "OMNINAV_ROUTER": "tcp/192.0.2.1:7447"})
    output = off_loopback.stdout.read()
    assert b"'tcp/192.0.2.1:7447' is not a loopback address" in output and b"Traceback" not in output
    assert off_loopback.wait(60) == 2


def test_a_forked_service_leads_its_own_group_shows_its_command_and_stops_when_asked():
    absent = f"tcp/127.0.0.1:{free_port()}"
    talker = ForkedProcess(["run", "talker", "--router", absent], dict(os.environ))
    expected = [b"-m", b"omninav.cli.main", b"run", b"talker", b"--router", absent.encode()]
    try:
        wait_until(lambda: open(f"/proc/{talker.pid}/cmdline", "rb").read().rstrip(b"\0").split(b"\0")[1:]
                   == expected, 60, what="the service's command line")
        assert os.getpgid(talker.pid) == talker.pid != os.getpgid(0)
        wait_until(lambda: b"started" in os.read(talker.stdout.fileno(), 4096), 60, what="the service's start")
        assert talker.poll() is None
    finally:
        os.killpg(talker.pid, signal.SIGINT)
    assert talker.wait(60) == 0
    assert b"[talker] stopped" in talker.stdout.read()
