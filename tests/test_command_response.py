"""The chassis's response to commands as the collision monitor models it: late by the delay, at the
acceleration limits, rolling on after a stop; and its paths ahead, worked out by hand. (Against the
simulated chassis: tests/test_gate_nodes.py, a turn beside a wall.)"""
import numpy as np
import pytest

from omninav.geometry.command_response import CommandResponse, poses_along
from omninav.geometry.se2 import integrate

MS = 1_000_000


def response() -> CommandResponse:
    return CommandResponse(delay_s=0.05, acc_limits=(2.0, 2.0, 4.0), step_s=0.01, keep_s=1.0)


def test_a_command_takes_effect_after_the_delay_and_is_reached_at_the_acceleration_limit():
    model = response()
    model.add(0, (0.5, 0.0, 1.0))
    assert model.velocity(50 * MS) == [0.0, 0.0, 0.0]                   # stamp + delay is not yet after it
    assert model.velocity(60 * MS) == pytest.approx([0.02, 0.0, 0.04])   # one step of 2 m/s² and 4 rad/s²
    assert model.velocity(300 * MS) == pytest.approx([0.5, 0.0, 1.0])    # reached after 25 steps (x)
    model.add(300 * MS, (0.0, 0.0, 0.0))
    assert model.velocity(400 * MS) == pytest.approx([0.4, 0.0, 0.8])    # still rolling 0.1 s after the stop
    assert model.velocity(700 * MS) == [0.0, 0.0, 0.0]


def test_the_motion_since_a_stop_is_the_delay_and_the_deceleration():
    model = response()
    model.add(0, (0.4, 0.0, 0.0))
    model.add(1000 * MS, (0.0, 0.0, 0.0))
    x, y, theta = model.motion(1000 * MS, 2000 * MS)
    rolled = 0.01 * sum([0.4] * 6 + [0.4 - 0.02 * k for k in range(1, 20)])   # up to 1.06 s, then 2 m/s² down
    assert (x, y, theta) == pytest.approx((rolled, 0.0, 0.0))
    assert model.motion(2000 * MS, 2500 * MS).tolist() == [0.0, 0.0, 0.0]


def test_a_path_ahead_carries_out_the_commands_on_their_way_the_new_one_held_then_braking():
    model = response()
    assert not model.path(0, (0.0, 0.0, 0.0), 0.1).any()                 # standing stays
    model.add(0, (0.3, 0.0, 0.0))
    model.add(1000 * MS, (0.3, 0.0, 0.0))
    stop = model.path(1050 * MS, (0.0, 0.0, 0.0), 0.1)
    go_on = model.path(1050 * MS, (0.3, 0.0, 0.0), 0.1)
    assert not stop[:, 1:].any() and not go_on[:, 1:].any() and len(go_on) == len(stop) + 10   # straight on
    # stopping: 0.3 m/s until the stop takes effect after 1.1 s, then 0.15 s of braking
    assert stop[-1, 0] == pytest.approx(0.01 * (0.3 * 6 + sum(0.3 - 0.02 * k for k in range(1, 15))))
    assert go_on[-1, 0] == pytest.approx(stop[-1, 0] + 0.3 * 0.1)       # the command held 0.1 s more


def test_poses_along_piecewise_twists_compose_the_arcs():
    twists = np.array([[0.5, 0.0, 1.0], [0.2, -0.1, -0.5], [0.0, 0.3, 0.0]])
    durations = np.array([0.3, 0.2, 0.5])
    expected = np.zeros(3)
    poses = poses_along(twists, durations)
    for k, (twist, dt) in enumerate(zip(twists, durations)):
        expected = integrate(expected, twist, dt)
        np.testing.assert_allclose(poses[k + 1], expected, atol=1e-12)
