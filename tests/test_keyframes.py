"""Movers on timed keyframes (sim/keyframes.py, sim/world.py): linear and Gazebo's PoseAnimation
interpolation against values worked out by hand from the formulas — the Hermite basis h00 = 2u³ −
3u² + 1, h10 = u³ − 2u² + u, h01 = −2u³ + 3u², h11 = u³ − u² and Catmull-Rom tangents per unit of
u — ends of an open track, a closed track, the loop's jump back, holding after the end; in a world
file and in the simulator."""
import numpy as np
import pytest
import yaml

from omninav.sim.keyframes import Keyframes
from omninav.sim.physics import SimParams, Simulation
from omninav.sim.world import load_world

# a U: (0, 0) → (4, 0) in 2 s → (4, 2) in 1 s → (0, 2) in 2 s; period 5 s
TIMES = np.array([0.0, 2.0, 3.0, 5.0])
POINTS = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]])
# its open Catmull-Rom tangents: m0 = (p1 − p0)/2 = (2, 0), m1 = (p2 − p0)/2 = (2, 1),
# m2 = (p3 − p1)/2 = (−2, 1), m3 = (p3 − p2)/2 = (−2, 0)


def track(interpolation, loop=True, times=TIMES, points=POINTS):
    return Keyframes(times, points, loop, interpolation)


def test_linear_goes_straight_between_keyframes_at_each_segments_speed():
    position, velocity = track("linear").state([1.0, 2.25, 4.0])
    np.testing.assert_allclose(position, [[2.0, 0.0], [4.0, 0.5], [2.0, 2.0]])
    np.testing.assert_allclose(velocity, [[2.0, 0.0], [0.0, 2.0], [-2.0, 0.0]])


@pytest.mark.parametrize("interpolation", ["linear", "gazebo"])
def test_keyframes_are_passed_exactly(interpolation):
    position, _ = track(interpolation).state(TIMES[:-1])
    np.testing.assert_allclose(position, POINTS[:-1], atol=1e-12)


def test_gazebo_follows_the_catmull_rom_hermite_segments_with_gazebos_end_tangents():
    position, velocity = track("gazebo").state([1.0, 2.25, 4.0])
    # t = 1: segment 0, u = 1/2, h = (1/2, 1/8, 1/2, −1/8): 1/8·(2, 0) + 1/2·(4, 0) − 1/8·(2, 1) = (2, −1/8);
    # dh/du = (−3/2, −1/4, 3/2, −1/4): −1/4·(2, 0) + 3/2·(4, 0) − 1/4·(2, 1) = (5, −1/4), over 2 s
    # t = 2.25: segment 1, u = 1/4, h = (27/32, 9/64, 5/32, −3/64):
    #   27/32·(4, 0) + 9/64·(2, 1) + 5/32·(4, 2) − 3/64·(−2, 1) = (4.375, 0.40625)
    # t = 4: the last segment (its end tangent (p3 − p2)/2), u = 1/2:
    #   1/2·(4, 2) + 1/8·(−2, 1) + 1/2·(0, 2) − 1/8·(−2, 0) = (2, 2.125)
    #   −3/2·(4, 2) − 1/4·(−2, 1) + 3/2·(0, 2) − 1/4·(−2, 0) = (−5, −1/4), over 2 s
    np.testing.assert_allclose(position, [[2.0, -0.125], [4.375, 0.40625], [2.0, 2.125]])
    np.testing.assert_allclose(velocity[[0, 2]], [[2.5, -0.125], [-2.5, -0.125]])
    # dh/du at u = 1/4: (−9/8, 3/16, 9/8, −5/16): −9/8·(4, 0) + 3/16·(2, 1) + 9/8·(4, 2) − 5/16·(−2, 1), over 1 s
    np.testing.assert_allclose(velocity[1], [1.0, 2.125])


def test_gazebo_velocity_jumps_at_a_keyframe_between_segments_of_different_durations():
    # the tangent m1 = (2, 1) is per unit of u: over the 2 s segment before, over the 1 s segment after
    _, before = track("gazebo").state(2.0 - 1e-9)
    _, after = track("gazebo").state(2.0)
    np.testing.assert_allclose(before, [1.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(after, [2.0, 1.0])


@pytest.mark.parametrize("interpolation", ["linear", "gazebo"])
def test_a_loop_jumps_back_to_the_first_keyframe_and_starts_again(interpolation):
    moving = track(interpolation)
    np.testing.assert_allclose(moving.state(5.0 - 1e-9)[0], [0.0, 2.0], atol=1e-6)    # at the last keyframe
    np.testing.assert_allclose(moving.state(5.0)[0], [0.0, 0.0])                       # back at the first
    for t in (1.0, 2.25, 4.0):
        np.testing.assert_allclose(moving.state(t + 5.0)[0], moving.state(t)[0])
        np.testing.assert_allclose(moving.state(t + 10.0)[1], moving.state(t)[1])


@pytest.mark.parametrize("interpolation", ["linear", "gazebo"])
def test_without_a_loop_the_last_keyframe_holds_at_rest(interpolation):
    position, velocity = track(interpolation, loop=False).state([5.0, 7.0, 100.0])
    np.testing.assert_allclose(position, [[0.0, 2.0]] * 3)
    np.testing.assert_allclose(velocity, np.zeros((3, 2)))
    np.testing.assert_allclose(track(interpolation, loop=False).state(4.0)[0], track(interpolation).state(4.0)[0])


def test_a_closed_gazebo_track_wraps_its_end_tangents_and_loops_smoothly():
    # (0, 0) → (2, 0) → (2, 2) → (0, 0), 1 s each: first = last, so m0 = m3 = (p1 − p2)/2 = (0, −1),
    # m1 = (p2 − p0)/2 = (1, 1), m2 = (p3 − p1)/2 = (−1, 0)
    closed = track("gazebo", times=np.array([0.0, 1.0, 2.0, 3.0]),
                   points=np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 0.0]]))
    position, velocity = closed.state([0.5, 2.5])
    # u = 1/2: 1/8·(0, −1) + 1/2·(2, 0) − 1/8·(1, 1) = (0.875, −0.25) (an open track's m0 = (1, 0) gives (1, −0.125))
    #          1/2·(2, 2) + 1/8·(−1, 0) − 1/8·(0, −1) = (0.875, 1.125)
    np.testing.assert_allclose(position, [[0.875, -0.25], [0.875, 1.125]])
    # no jump at the loop's end, and the same velocity m3 = m0 = (0, −1) per 1 s on both sides of it
    end_position, end_velocity = closed.state(3.0 - 1e-9)
    np.testing.assert_allclose(end_position, [0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(end_velocity, [0.0, -1.0], atol=1e-6)
    np.testing.assert_allclose(closed.state(3.0)[1], [0.0, -1.0])
    # Gazebo takes first and last as equal within 1 mm per coordinate
    nearly = closed.points + np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0009, -0.0009]])
    np.testing.assert_allclose(track("gazebo", times=closed.times, points=nearly).tangents[0], [0.0, -1.0])


def test_state_takes_times_of_any_shape():
    position, velocity = track("gazebo").state(np.array([[1.0, 2.25], [4.0, 6.0]]))
    assert position.shape == velocity.shape == (2, 2, 2)
    np.testing.assert_allclose(position[1, 1], track("gazebo").state(1.0)[0])


def test_the_trace_follows_the_curve_through_every_keyframe():
    linear, gazebo = track("linear").trace(), track("gazebo").trace()
    np.testing.assert_allclose(linear, POINTS)
    assert len(gazebo) == 3 * 16 + 1
    np.testing.assert_allclose(gazebo[::16], POINTS)
    np.testing.assert_allclose(gazebo[8], [2.0, -0.125])           # segment 0 at u = 1/2, as above


# ---------------------------------------------------------------- in a world and the simulator

def keyframe_world(tmp_path, movers):
    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump({"bounds": [10.0, 8.0], "robot": {"start": [8.0, 6.0, 0.0]}, "movers": movers}))
    return load_world(path)


def test_a_world_mixes_path_and_keyframe_movers(tmp_path):
    frames = np.column_stack([TIMES, POINTS + 1.0]).tolist()
    world = keyframe_world(tmp_path, [
        {"radius": 0.5, "keyframes": frames, "interpolation": "gazebo"},
        {"radius": 0.3, "speed": 1.0, "path": [[1, 6], [5, 6]]},
        {"radius": 0.4, "keyframes": frames, "loop": False},
        {"radius": 0.2, "keyframes": [[0, 1, 7], [4, 5, 7]]}])             # a shorter track beside the others
    movers = world.movers
    assert movers.on_keyframes.tolist() == [True, False, True, True]
    np.testing.assert_allclose(movers.pose_at(1.0), [[3.0, 0.875], [2.0, 6.0], [3.0, 1.0], [2.0, 7.0]])
    np.testing.assert_allclose(movers.velocity_at(1.0), [[2.5, -0.125], [1.0, 0.0], [2.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(movers.pose_at(6.0)[[0, 2, 3]], [[3.0, 0.875], [1.0, 3.0], [3.0, 7.0]])  # looped; held; looped
    np.testing.assert_allclose(movers.circles_at(4.0), [[3.0, 3.125, 0.5], [5.0, 6.0, 0.3], [3.0, 3.0, 0.4],
                                                        [1.0, 7.0, 0.2]])
    np.testing.assert_allclose(movers.pose_after([1.0, 2.0, 4.0, 3.0]), [[3.0, 0.875], [3.0, 6.0], [3.0, 3.0], [4.0, 7.0]])
    np.testing.assert_allclose(movers.loops[2], POINTS + 1.0)                # the lanes a keyframe mover sweeps
    assert not movers.yield_distance.any()


def test_the_simulator_moves_keyframe_movers_by_the_clock_and_never_stops_them(tmp_path):
    frames = np.column_stack([TIMES, POINTS + [3.0, 5.0]]).tolist()     # the U passes over the robot at (7, 6)
    world = keyframe_world(tmp_path, [{"radius": 0.5, "keyframes": frames, "interpolation": "gazebo"}])
    sim = Simulation(world, SimParams().without_noise())
    previous = world.movers.pose_at(0.0)
    for _ in range(round(6.0 / sim.params.dt)):
        r = sim.step()
        np.testing.assert_allclose(r.mover_circles[:, :2], world.movers.pose_at(r.time), atol=1e-12)
        np.testing.assert_allclose(r.mover_velocities, (r.mover_circles[:, :2] - previous) / sim.params.dt, atol=1e-9)
        previous = r.mover_circles[:, :2]
    assert sim.collisions >= 1            # it ran over the parked robot: no yielding on keyframes
