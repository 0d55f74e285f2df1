"""DWA against moving obstacles (services/local_planner/dynamic.py): each rollout checked against
the tracks predicted along it; meeting a person sooner than standing still would is illegal."""
import numpy as np
import pytest

from omninav.schemas.messages import Header, MapMetaData, Pose2D, Tracks
from omninav.services.local_planner.dwa import DwaPlanner
from omninav.services.local_planner.footprint_check import FootprintCheck
from omninav.geometry.movers import Movers, movers_at, tracks_problem
from omninav.services.local_planner.dynamic import carried_on, critic, first_contact, slack
from omninav.services.local_planner.params import DwaParams

FOOTPRINT = np.array([[0.416, 0.318], [-0.416, 0.318], [-0.416, -0.318], [0.416, -0.318]])
INFO = MapMetaData(resolution=0.05, width=160, height=120, origin=Pose2D(-3.0, -3.0, 0.0))
FREE = np.zeros((INFO.height, INFO.width), np.uint8)
PATH = np.column_stack([np.linspace(0.0, 4.5, 91), np.zeros(91), np.zeros(91)])
PARAMS = DwaParams(max_vel_x=0.5, max_vel_y=0.3, min_vel_y=-0.3, dynamic_horizon=2.5, evade_movers=True)


def movers(*tracks) -> Movers:
    t = np.array(tracks, float).reshape(-1, 5)
    return Movers(t[:, :2], t[:, 2:4], t[:, 4], np.zeros((len(t), 3)))


def chosen_slack(result, planner, track) -> np.ndarray:
    dt = planner.params.sim_time / (result.poses.shape[1] - 1)
    return slack(result.trajectory[None], dt, planner.footprint_check.footprint, track, 0.0, 0.0)[0][0]


@pytest.mark.parametrize("crossing", [(1.0, -1.2, 0.0, 0.9, 0.3), (1.2, 1.4, 0.0, -0.9, 0.3),
                                      (1.3, -1.0, -0.2, 0.6, 0.25)])
def test_dwa_does_not_drive_into_a_person_crossing_ahead_that_it_would_meet_without_the_tracks(crossing):
    planner = DwaPlanner(PARAMS, FootprintCheck(FOOTPRINT))
    track = movers(crossing)
    velocity = (0.5, 0.0, 0.0)           # cruising along the path
    blind = planner.compute((0.0, 0.0, 0.0), velocity, FREE, INFO, PATH)
    assert blind.status == "ok" and chosen_slack(blind, planner, track).min() < 0     # would meet them
    seeing = planner.compute((0.0, 0.0, 0.0), velocity, FREE, INFO, PATH, movers=track)
    assert seeing.status in ("ok", "evade")   # evade: every speed one period can reach meets them
    assert chosen_slack(seeing, planner, track).min() >= 0
    if seeing.status == "evade":              # ... and slowing down does not
        assert seeing.cmd[0] < velocity[0] - 0.1


def test_when_every_sample_of_the_window_meets_a_mover_the_way_meeting_none_is_ramped_towards():
    """A person crossing close ahead: every twist one period reaches meets them within the horizon;
    the evasion ramps over the whole velocity range and finds a way that meets no one — not a
    brake reported as failure (which stopped the robot in a crossing cylinder's way to replan:
    DynaBARN easy-24)."""
    planner = DwaPlanner(PARAMS, FootprintCheck(FOOTPRINT))
    track = movers((1.0, -1.2, 0.0, 0.9, 0.3))
    velocity = (0.5, 0.0, 0.0)
    window = planner.compute((0.0, 0.0, 0.0), velocity, FREE, INFO, PATH)
    poses, times = carried_on(window.poses, PARAMS.sim_time / (window.poses.shape[1] - 1), PARAMS.dynamic_horizon)
    hard, _ = slack(poses, times, planner.footprint_check.footprint, track, PARAMS.dynamic_obstacle_margin, 0.0)
    assert (first_contact(hard) < len(times)).all()        # the window's every sample meets them
    seeing = planner.compute((0.0, 0.0, 0.0), velocity, FREE, INFO, PATH, movers=track)
    assert seeing.status == "evade"
    poses, times = carried_on(seeing.trajectory[None], PARAMS.sim_time / (seeing.poses.shape[1] - 1),
                              PARAMS.dynamic_horizon)
    hard, _ = slack(poses, times, planner.footprint_check.footprint, track, PARAMS.dynamic_obstacle_margin, 0.0)
    assert first_contact(hard)[0] == len(times)            # the way chosen meets no one within the horizon


def test_rollouts_are_carried_on_at_their_last_twist_to_the_horizon():
    dt = 0.05
    line = np.column_stack([np.arange(5) * 0.1, np.zeros(5), np.zeros(5)])       # 2 m/s straight on
    arc_twist = (1.0, 0.0, 1.0)
    from omninav.geometry.se2 import integrate
    arc = np.array([integrate((0.0, 0.0, 0.0), arc_twist, k * dt) for k in range(5)])
    poses, times = carried_on(np.stack([line, arc]), dt, 1.0)
    assert times[-1] == pytest.approx(1.0) and np.all(np.diff(times) > 0)
    assert poses[0, -1] == pytest.approx([2.0, 0.0, 0.0])
    assert poses[1, -1] == pytest.approx(integrate((0.0, 0.0, 0.0), arc_twist, 1.0), abs=1e-9)
    same, same_times = carried_on(np.stack([line]), dt, 0.1)                    # the horizon within the rollout
    assert same.shape == (1, 5, 3) and same_times[-1] == pytest.approx(0.2)


def test_a_person_walking_into_a_standing_robot_is_left_not_waited_for():
    """Someone comes at the robot from behind faster than it can go: standing is met soonest,
    every rollout ahead is legal, and DWA drives on rather than brake."""
    planner = DwaPlanner(PARAMS, FootprintCheck(FOOTPRINT))
    track = movers((-1.4, 0.0, 1.0, 0.0, 0.3))
    result = planner.compute((0.0, 0.0, 0.0), (0.2, 0.0, 0.0), FREE, INFO, PATH, movers=track)
    assert result.status == "ok" and result.cmd[0] > 0.2


def test_critic_rules_on_synthetic_slacks():
    # rollout 0 closes in at step 2, rollout 1 at step 3, rollout 2 backs away from a mover already near
    hard = np.array([[0.5, 0.1, -0.1, -0.3], [0.5, 0.3, 0.1, -0.1], [-0.05, 0.0, 0.1, 0.2]])
    assert first_contact(hard).tolist() == [2, 3, 4]
    legal, cost = critic(hard, hard, np.array([[0.5, 0.2, 0.0, -0.2]]), 0.8, 10.0)
    assert legal.tolist() == [False, True, True]          # standing is met at step 3
    assert cost[2] == 0.0 and cost[0] > cost[1] > 0       # deeper than at the start costs
    # a mover within the margin walking at the robot: standing meets them at once, and so does
    # driving on towards them — illegal, not "no sooner than standing"; backing away is legal
    near = np.array([[-0.05, -0.1, -0.2, -0.3], [-0.05, -0.02, 0.02, 0.05]])
    standing = np.array([[-0.05, -0.07, -0.09, -0.11]])
    assert critic(near, near, standing, 0.8, 10.0, closing_at_once=True)[0].tolist() == [False, True]
    assert critic(near, near, standing, 0.8, 10.0)[0].tolist() == [True, True]     # without evade_movers


def test_tracks_are_predicted_to_the_tick_and_carried_into_the_planners_frame():
    msg = Tracks(header=Header(stamp_ns=1_000_000_000, frame_id="odom"), ids=np.array([7]),
                 states=np.array([[1.0, 2.0, 0.5, 0.0]]), covariances=np.eye(4)[None] * 0.01, radii=np.array([0.3]))
    assert tracks_problem(msg) == ""
    placed = movers_at(msg, 1.5, (10.0, 0.0, np.pi / 2), 0.1)      # odom's origin at (10, 0), turned left
    assert np.allclose(placed.positions, [[8.0, 1.25]]) and np.allclose(placed.velocities, [[0.0, 0.5]])
    assert placed.variance[0, 0] > 0.01                             # grown over the half second
    assert len(movers_at(msg, 1.5, (0.0, 0.0, 0.0), 0.6)) == 0     # slower than min_speed: the costmap's
    msg.radii = np.array([0.3, 0.2])
    assert "radii has 2" in tracks_problem(msg)


def test_backing_from_a_person_in_the_way_starts_no_escape():
    """DWA's escape (forward samples held back until the robot has backed escape_reset_dist) is for
    gaps it does not fit, which stay put; a person who walks on frees the way at once."""
    planner = DwaPlanner(DwaParams(min_vel_x=0.0, holonomic_robot=False, evade_movers=True), FootprintCheck(FOOTPRINT))
    in_the_way = movers((0.77, 0.0, -0.05, 0.0, 0.3))     # within the kept margin of the front, coming on
    first = planner.compute((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), FREE, INFO, PATH, movers=in_the_way)
    assert first.status in ("evade", "escape") and first.cmd[0] < 0       # backs away
    gone = planner.compute((-0.02, 0.0, 0.0), (0.0, 0.0, 0.0), FREE, INFO, PATH)
    assert gone.status == "ok" and gone.cmd[0] > 0


def test_the_nearest_movers_edge_is_measured_from_a_point_and_is_infinite_without_movers():
    movers = Movers(np.array([[3.0, 4.0], [0.0, -1.0]]), np.zeros((2, 2)), np.array([0.5, 0.25]), np.zeros((2, 3)))
    assert movers.nearest_edge((0.0, 0.0, 1.2)) == pytest.approx(0.75)      # the second, 1 m off, radius 0.25
    assert Movers(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3))).nearest_edge((0.0, 0.0)) == np.inf
