"""omninav teleop: keys to commands and their timeout (pure), scripts, refusing a non-terminal,
a scripted run against a real clock source publishing stamped, sequenced cmd_vel_teleop, and the
keyboard in a pseudo-terminal (raw mode undone on exit)."""
import os
import pty
import select
import subprocess
import sys
import termios

import pytest

from omninav.cli.teleop import (ZERO, KeyMap, KeyState, ScriptStep, TeleopError, keys_of, parse_script,
                                 script_command)
from omninav.schemas import decode
from omninav.schemas.attachment import unpack_attachment
from omninav.schemas.messages import Twist
from omninav.services.runtime.zenoh_config import ROUTER_ENV, open_client

from conftest import REPO, wait_until

KEYS = KeyMap(max_speed=0.5, max_turn=1.0, key_timeout_s=0.6)


def pressed(*keys, t=0.0):
    state = KeyState()
    for key in keys:
        state = KEYS.press(state, key, t)
    return state


@pytest.mark.parametrize("key, twist", [("w", (0.5, 0.0, 0.0)), ("s", (-0.5, 0.0, 0.0)), ("a", (0.0, 0.5, 0.0)),
                                        ("d", (0.0, -0.5, 0.0)), ("q", (0.0, 0.0, 1.0)), ("e", (0.0, 0.0, -1.0)),
                                        ("W", (0.5, 0.0, 0.0))])
def test_each_key_sets_its_axis_to_full_speed(key, twist):
    state = pressed(key)
    assert KEYS.command(state, 0.0) == twist and not state.quit


def test_keys_combine_stop_and_quit():
    assert KEYS.command(pressed("w", "a", "e"), 0.0) == (0.5, 0.5, -1.0)
    assert KEYS.command(pressed("w", "s"), 0.0) == (-0.5, 0.0, 0.0)        # the opposite key reverses
    assert KEYS.command(pressed("w", "q", " "), 0.0) == ZERO
    for quit_key in ("x", "X", "\x03"):
        state = pressed("w", quit_key)
        assert state.quit and state.twist == ZERO
    unknown = pressed("w", "z")
    assert unknown == pressed("w") and not unknown.quit


def test_the_command_drops_to_zero_without_keys_for_the_timeout():
    state = KEYS.press(KeyState(), "w", 10.0)
    assert KEYS.command(state, 10.6) == (0.5, 0.0, 0.0)
    assert KEYS.command(state, 10.61) == ZERO
    state = KEYS.press(state, "w", 10.5)                   # a key repeat keeps it alive
    assert KEYS.command(state, 11.0) == (0.5, 0.0, 0.0)
    # after a timeout a key starts from rest: the forgotten forward speed does not come back
    assert KEYS.command(KEYS.press(state, "a", 20.0), 20.0) == (0.0, 0.5, 0.0)
    assert KEYS.command(KeyState(), 0.0) == ZERO


def test_escape_sequences_are_not_keys():
    assert keys_of("\x1b[A") == [] and keys_of("wa") == ["w", "a"]


def test_scripts_parse_and_run_in_sim_seconds():
    steps = parse_script(" 0.3, 0, 0, 1.5; 0,0.2,-0.5,0.5 ;")
    assert steps == (ScriptStep((0.3, 0.0, 0.0), 1.5), ScriptStep((0.0, 0.2, -0.5), 0.5))
    assert script_command(steps, 0.0) == (0.3, 0.0, 0.0)
    assert script_command(steps, 1.49) == (0.3, 0.0, 0.0)
    assert script_command(steps, 1.5) == (0.0, 0.2, -0.5)
    assert script_command(steps, 2.0) is None


@pytest.mark.parametrize("text, message", [
    ("", "--script is empty"),
    ("0.3,0,0", r"step 1 \('0.3,0,0'\): expected 4 numbers vx,vy,wz,seconds, got 3"),
    ("0.3,0,0,1;0.1,0,0,fast", r"step 2 \('0.1,0,0,fast'\): expected 4 numbers"),
    ("0.3,0,0,1;;0,0,0,1", r"step 2 \(''\): expected 4 numbers"),
    ("0.3,0,0,0", "the duration must be positive"),
    ("nan,0,0,1", "every value must be finite"),
])
def test_bad_scripts_fail_clearly(text, message):
    with pytest.raises(TeleopError, match=message):
        parse_script(text)


def _teleop(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "omninav.cli.main", "teleop", *args], cwd=REPO,
                          stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)


def test_without_a_terminal_or_a_script_it_refuses_clearly():
    done = _teleop()
    assert done.returncode == 2
    assert "standard input is not a terminal" in done.stderr and "--script" in done.stderr
    assert "Traceback" not in done.stderr
    done = _teleop("--script", "1,0,0")
    assert done.returncode == 2 and "expected 4 numbers" in done.stderr and "Traceback" not in done.stderr


def test_a_script_drives_on_sim_time_with_sequenced_stamped_commands(processes, router_endpoint):
    received = []
    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber("omninav/r1/cmd_vel_teleop", lambda s: received.append(
            (decode(s.payload.to_bytes(), Twist), unpack_attachment(s.attachment.to_bytes() if s.attachment else None))))
        processes.omninav("run", "talker")            # the sim clock at 100 Hz, rate 1
        teleop = processes.omninav("teleop", "--script", "0.3,0,0,0.5;0,0,-0.4,0.3")
        assert teleop.wait(60) == 0, processes.log_of(teleop)
        wait_until(lambda: received and received[-1][0].linear_x == 0.0 and received[-1][0].angular_z == 0.0,
                   10, what="the final zero command")
        sub.undeclare()
    assert "script done (2 steps" in processes.log_of(teleop)
    twists = [(m.linear_x, m.linear_y, m.angular_z) for m, _ in received]
    assert twists[0] == (0.3, 0.0, 0.0) and (0.0, 0.0, -0.4) in twists and twists[-1] == ZERO
    assert twists.index((0.0, 0.0, -0.4)) > twists.index((0.3, 0.0, 0.0))
    stamps = [m.header.stamp_ns for m, _ in received]
    assert stamps[0] > 0 and stamps == sorted(stamps)              # sim time from the clock
    assert stamps[-1] - stamps[0] >= 0.7e9                          # the script's 0.8 s, at 10 Hz
    for msg, envelope in received:                                  # the omninav attachment, as every node sends
        assert envelope is not None and envelope.type_name == "Twist"
        assert (envelope.seq, envelope.stamp_ns) == (msg.header.seq, msg.header.stamp_ns)
    assert [m.header.seq for m, _ in received] == list(range(1, len(received) + 1))


def test_the_keyboard_drives_in_a_terminal_and_gives_it_back(processes, router_endpoint):
    master, slave = pty.openpty()
    before = termios.tcgetattr(slave)
    received = []
    screen = bytearray()

    def read_screen():
        while select.select([master], [], [], 0)[0]:
            screen.extend(os.read(master, 4096))
        return screen.decode(errors="replace")

    with open_client(router_endpoint) as session:
        sub = session.declare_subscriber("omninav/r1/cmd_vel_teleop",
                                         lambda s: received.append(decode(s.payload.to_bytes(), Twist)))
        processes.omninav("run", "talker")
        teleop = subprocess.Popen([sys.executable, "-m", "omninav.cli.main", "teleop", "--key-timeout", "5"],
                                  cwd=REPO, stdin=slave, stdout=slave, stderr=slave, start_new_session=True,
                                  env={**os.environ, ROUTER_ENV: router_endpoint})
        try:
            wait_until(lambda: "| sim " in read_screen(), 30, what="teleop showing the sim time")
            os.write(master, b"w")
            wait_until(lambda: any(m.linear_x == 0.5 for m in received), 10, what="a forward command")
            wait_until(lambda: "vx +0.50 m/s" in read_screen(), 10, what="the command on screen")
            os.write(master, b"x")
            assert teleop.wait(30) == 0
        finally:
            if teleop.poll() is None:
                teleop.kill()
                teleop.wait(5)
        wait_until(lambda: received[-1].linear_x == 0.0, 10, what="the zero sent on quit")
        sub.undeclare()
    assert termios.tcgetattr(slave) == before          # raw mode undone
    os.close(master)
    os.close(slave)
