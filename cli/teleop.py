"""`omninav teleop`: drive the robot from the keyboard, or along a fixed script timed in sim seconds.

Keys (read one at a time, terminal in raw mode): w/s = forward/backward, a/d = strafe left/right
(a differential drive ignores it), q/e = turn left/right, space = stop, x or Ctrl-C = quit. A key
sets its axis to the full speed in its direction and keeps the other axes. Terminals report no key
releases, only key repeats while a key is held, so the whole command drops to zero when no key
came for --key-timeout (wall) seconds; the chassis's acceleration limits turn that into a ramp.

cmd_vel_teleop is published at 10 Hz of wall time, stamped with the latest sim time seen on the clock
key, by a Node driven by the ordinary LiveRunner: the same publishers (BLOCK, the omninav attachment
with seq and stamp) as every service, so recordings of teleop runs replay like any other. It goes
into the command mux, which puts it ahead of navigation, then through the velocity smoother and the
collision monitor, which alone may send cmd_vel: a robot driven by hand still stops before an
obstacle. Under `omninav up` teleop needs the run's teleop identity: OMNINAV_CREDENTIALS=FOLDER/teleop.
"""
from __future__ import annotations

import argparse
import math
import os
import select
import signal
import sys
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

from ..services.runtime.errors import UserError, exits_2_on_user_error
from ..schemas.keys import DEFAULT_ROBOT
from ..schemas.messages import Clock, Twist
from ..services.runtime.live import LiveRunner
from ..services.runtime.run import add_lockstep_argument, lockstep_of
from ..services.runtime.node import NS_PER_S, Node
from ..services.runtime.zenoh_config import router_endpoint
from ..parameters.declare import Parameters
from ..services.runtime.stop_signals import stop_event

ZERO = (0.0, 0.0, 0.0)
KEY_AXES = {"w": (0, 1.0), "s": (0, -1.0), "a": (1, 1.0), "d": (1, -1.0), "q": (2, 1.0), "e": (2, -1.0)}
STOP_KEY = " "
QUIT_KEYS = ("x", "\x03")        # in raw mode Ctrl-C arrives as a character, not as SIGINT
ESCAPE = "\x1b"                  # arrow and function keys send escape sequences: ignored
PUBLISH_HZ = 10.0
CLOCK_NOTICE_S = 3.0             # say that no clock has come after this long
HELP_LINE = "w/s forward/back, a/d strafe, q/e turn, space stop, x quit"


class TeleopError(UserError):
    """A user error: printed as one line, exit status 2."""


# ---------------------------------------------------------------- keys (pure)

@dataclass(frozen=True)
class KeyState:
    twist: tuple[float, float, float] = ZERO
    last_key_s: float = -math.inf      # wall time of the last key that changed the command
    quit: bool = False


@dataclass(frozen=True)
class KeyMap:
    max_speed: float = 0.5     # m/s for w/s and a/d
    max_turn: float = 1.0      # rad/s for q/e
    key_timeout_s: float = 0.6

    def command(self, state: KeyState, now_s: float) -> tuple[float, float, float]:
        """The twist to send at now_s: the keys' twist, or zero once no key came for key_timeout_s."""
        return state.twist if now_s - state.last_key_s <= self.key_timeout_s else ZERO

    def press(self, state: KeyState, key: str, now_s: float) -> KeyState:
        """The state after one key. Unknown keys change nothing (and do not keep the command alive)."""
        key = key.lower()
        if key in QUIT_KEYS:
            return replace(state, twist=ZERO, quit=True)
        if key == STOP_KEY:
            return KeyState(ZERO, now_s)
        if key not in KEY_AXES:
            return state
        axis, sign = KEY_AXES[key]
        twist = list(self.command(state, now_s))      # after a timeout, start again from rest
        twist[axis] = sign * (self.max_turn if axis == 2 else self.max_speed)
        return KeyState(tuple(twist), now_s)


def keys_of(chunk: str) -> list[str]:
    """The single keys in what one read returned; an escape sequence (an arrow key) is dropped."""
    return [] if chunk.startswith(ESCAPE) else list(chunk)


# ---------------------------------------------------------------- scripts (pure)

@dataclass(frozen=True)
class ScriptStep:
    twist: tuple[float, float, float]
    seconds: float                      # sim seconds


def parse_script(text: str) -> tuple[ScriptStep, ...]:
    """'vx,vy,wz,seconds;vx,vy,wz,seconds;…' (a trailing ';' is allowed) into steps."""
    parts = text.split(";")
    if parts and not parts[-1].strip():
        parts = parts[:-1]
    if not parts:
        raise TeleopError("--script is empty: give steps 'vx,vy,wz,seconds;…' (m/s, m/s, rad/s, sim s)")
    steps = []
    for n, part in enumerate(parts, 1):
        where = f"--script step {n} ({part.strip()!r})"
        fields = part.split(",")
        if len(fields) != 4:
            raise TeleopError(f"{where}: expected 4 numbers vx,vy,wz,seconds, got {len(fields)} field(s)")
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise TeleopError(f"{where}: expected 4 numbers vx,vy,wz,seconds") from None
        if not all(math.isfinite(v) for v in values):
            raise TeleopError(f"{where}: every value must be finite")
        if values[3] <= 0:
            raise TeleopError(f"{where}: the duration must be positive, got {values[3]:g}")
        steps.append(ScriptStep((values[0], values[1], values[2]), values[3]))
    return tuple(steps)


def script_command(steps: tuple[ScriptStep, ...], elapsed_s: float) -> tuple[float, float, float] | None:
    """The twist of the step running elapsed_s sim seconds after the start; None once all are done."""
    end = 0.0
    for step in steps:
        end += step.seconds
        if elapsed_s < end:
            return step.twist
    return None


# ---------------------------------------------------------------- the node

@dataclass(frozen=True)
class TeleopParams(Parameters):
    rate_hz: float = PUBLISH_HZ


class TeleopNode(Node):
    """Publishes `command(wall_s, sim_ns)` on cmd_vel at rate_hz of wall time, once a clock came.

    `command` returns None when there is nothing more to send (the script is over): the node then
    publishes one zero and sets `finished`.
    """
    service = "teleop"
    Params = TeleopParams

    def __init__(self, command: Callable[[float, int], tuple[float, float, float] | None],
                 params: TeleopParams | None = None, robot: str = DEFAULT_ROBOT):
        self.command = command
        self.finished = threading.Event()
        self.clock_seen = False
        super().__init__(params, robot)

    def setup(self) -> None:
        self.cmd_vel = self.publisher("cmd_vel_teleop")
        self.subscribe("sim/clock", self.on_clock)

    def on_clock(self, _msg: Clock) -> None:
        self.clock_seen = True      # Node.process keeps now_ns, the latest sim time

    def pace_s(self) -> float:
        return 1.0 / self.params.rate_hz

    def tick(self) -> None:
        if not self.clock_seen or self.finished.is_set():
            return
        twist = self.command(time.monotonic(), self.now_ns)
        if twist is None:
            twist = ZERO
            self.finished.set()
        self.cmd_vel.publish(Twist(header=self.header("base_link"), linear_x=twist[0], linear_y=twist[1],
                                   angular_z=twist[2]))


class ScriptCommand:
    """A script's command at a sim time, counted from the first clock the node saw."""

    def __init__(self, steps: tuple[ScriptStep, ...]):
        self.steps = steps
        self.start_ns: int | None = None

    def __call__(self, _wall_s: float, sim_ns: int) -> tuple[float, float, float] | None:
        if self.start_ns is None:
            self.start_ns = sim_ns
        return script_command(self.steps, (sim_ns - self.start_ns) / NS_PER_S)


class KeyboardCommand:
    """The keyboard's current command (None after quit); `state` is replaced by the reading thread
    and read by the node's."""

    def __init__(self, keymap: KeyMap):
        self.keymap = keymap
        self.state = KeyState()

    def __call__(self, wall_s: float, _sim_ns: int) -> tuple[float, float, float] | None:
        return None if self.state.quit else self.keymap.command(self.state, wall_s)


# ---------------------------------------------------------------- the command

def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", default=DEFAULT_ROBOT, help="robot namespace (default r1)")
    parser.add_argument("--router", help="router endpoint (default $OMNINAV_ROUTER or tcp/127.0.0.1:7447)")
    parser.add_argument("--max-speed", type=float, default=KeyMap.max_speed, metavar="V",
                        help=f"m/s of w/s and a/d (default {KeyMap.max_speed})")
    parser.add_argument("--max-turn", type=float, default=KeyMap.max_turn, metavar="W",
                        help=f"rad/s of q/e (default {KeyMap.max_turn})")
    parser.add_argument("--key-timeout", type=float, default=KeyMap.key_timeout_s, metavar="S",
                        help="stop when no key came for this long, wall seconds (default "
                             f"{KeyMap.key_timeout_s}; longer than your keyboard's repeat delay)")
    add_lockstep_argument(parser)
    parser.add_argument("--script", metavar="STEPS",
                        help="drive 'vx,vy,wz,seconds;…' (sim seconds) instead of the keyboard, then stop and exit")


@exits_2_on_user_error("teleop")
def main(args: argparse.Namespace) -> int:
    for name, value in (("--max-speed", args.max_speed), ("--max-turn", args.max_turn),
                        ("--key-timeout", args.key_timeout)):
        if not (math.isfinite(value) and value > 0):
            raise TeleopError(f"{name} must be a positive number, got {value:g}")
    steps = parse_script(args.script) if args.script is not None else None
    if steps is None and not sys.stdin.isatty():
        raise TeleopError("standard input is not a terminal: run it in a terminal to drive by keyboard, "
                          "or give --script 'vx,vy,wz,seconds;…'")
    try:
        router = router_endpoint(args.router)
        keyboard = None if steps else KeyboardCommand(KeyMap(args.max_speed, args.max_turn, args.key_timeout))
        node = TeleopNode(ScriptCommand(steps) if steps else keyboard, robot=args.robot)
    except ValueError as exc:            # a non-loopback router, a bad robot name
        raise TeleopError(str(exc)) from None
    runner = LiveRunner(node, router, lockstep=lockstep_of(args))
    worker = threading.Thread(target=runner.run, name="teleop-bus", daemon=True)
    worker.start()
    try:
        if keyboard is None:
            ok = _run_script(node, worker, steps, router)
        else:
            ok = _run_keyboard(node, worker, keyboard, router)
    finally:
        runner.stop()
        # without a clock nothing was sent, and the thread may still wait for the router: do not wait long
        worker.join(10.0 if node.clock_seen else 1.0)
    return 0 if ok else 1


def _clock_notice(node: TeleopNode, router: str, started: float, noticed: bool, out) -> bool:
    if not noticed and not node.clock_seen and time.monotonic() - started > CLOCK_NOTICE_S:
        out(f"no sim clock yet on {node.inputs[0].key} through the router at {router}: "
            "are the router and the sim running? (waiting)")
        return True
    return noticed


def _run_script(node: TeleopNode, worker: threading.Thread, steps: tuple[ScriptStep, ...], router: str) -> bool:
    started, noticed = time.monotonic(), False
    stop = stop_event()
    while not node.finished.wait(0.1):
        if stop.is_set():
            print("teleop: interrupted; the chassis stops by itself when commands stop coming", file=sys.stderr)
            return True
        if not worker.is_alive():
            print("omninav teleop: error: the bus connection ended", file=sys.stderr)
            return False
        noticed = _clock_notice(node, router, started, noticed,
                                lambda text: print(f"teleop: {text}", file=sys.stderr))
    total = sum(step.seconds for step in steps)
    print(f"teleop: script done ({len(steps)} steps, {total:g} s of sim time); sent zero")
    return True


def _run_keyboard(node: TeleopNode, worker: threading.Thread, keyboard: KeyboardCommand, router: str) -> bool:
    import termios
    import tty

    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    # SIGTERM / SIGHUP must still run the `finally` that gives the terminal back
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, lambda *_: sys.exit(1))
    started, noticed = time.monotonic(), False

    def line(text: str) -> None:
        sys.stdout.write(f"\r{text}\x1b[K\r\n")
        sys.stdout.flush()

    try:
        tty.setraw(fd)
        line(f"teleop {node.cmd_vel.key}: {HELP_LINE}")
        while not keyboard.state.quit:
            if not worker.is_alive():
                line("omninav teleop: error: the bus connection ended")
                return False
            ready, _, _ = select.select([fd], [], [], 1.0 / PUBLISH_HZ)
            if ready:
                for key in keys_of(os.read(fd, 32).decode(errors="ignore")):
                    keyboard.state = keyboard.keymap.press(keyboard.state, key, time.monotonic())
            noticed = _clock_notice(node, router, started, noticed, line)
            vx, vy, wz = keyboard.keymap.command(keyboard.state, time.monotonic())
            sim = f"sim {node.now_ns / NS_PER_S:8.2f} s" if node.clock_seen else "waiting for the sim clock"
            sys.stdout.write(f"\rvx {vx:+.2f} m/s  vy {vy:+.2f} m/s  wz {wz:+.2f} rad/s | {sim}\x1b[K")
            sys.stdout.flush()
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        sys.stdout.write("\n")
    if node.clock_seen:
        node.finished.wait(2.0 / PUBLISH_HZ)     # the node's next tick sends the final zero
    return True
