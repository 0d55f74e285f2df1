"""TEB (teb.py): the timed band among predicted movers and its homotopy-class exploration."""
import math

import numpy as np
import pytest

from omninav.geometry.movers import Movers
from omninav.geometry.se2 import wrap_angle
from omninav.services.costmap.layers import LETHAL_OBSTACLE
from omninav.services.local_planner.footprint_check import FootprintCheck
from omninav.services.local_planner.teb import TebParams, TebPlanner, signature, without_movers, Obstacle
from test_dwa import FOOTPRINT, costmap, straight
from test_eband import assert_within_velocity_limits, band_twists

CLEAR = dict(min_obstacle_dist=0.15, inflation_dist=0.25, dynamic_obstacle_inflation_dist=0.25,
             include_dynamic_obstacles=True)
HOLO = TebParams(holonomic_robot=True, max_vel_y=0.3, **CLEAR)
DIFF = TebParams(holonomic_robot=False, **CLEAR)
BOTH = pytest.mark.parametrize("params", [HOLO, DIFF], ids=["holonomic", "diff"])
ROBOT_REACH = math.hypot(0.2, 0.2)


def person(x, y, vx, vy, radius=0.25):
    return Movers(np.array([[x, y]], float), np.array([[vx, vy]], float), np.array([radius]), np.zeros((1, 3)))


def times_of(result):
    return np.concatenate([[0.0], np.cumsum(result.time_intervals)])


def footprint_gap(result, movers):
    """(K,) metres between the footprint's covering circle (its circumscribed one, conservatively)
    at each band pose and the mover where it is when the pose is reached."""
    at = movers.positions[0] + movers.velocities[0] * times_of(result)[:, None]
    return np.hypot(*(result.trajectory[:, :2] - at).T) - ROBOT_REACH - movers.radii[0]


@BOTH
def test_a_straight_free_corridor_gives_the_time_optimal_profile(params):
    costs, info, check = costmap(boxes=[(-3.0, 0.6, 3.0, 0.8), (-3.0, -0.8, 3.0, -0.6)])
    planner = TebPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    for _ in range(3):
        result = planner.compute((-2.0, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, path)
    assert result.status == "ok", result.message
    twist = band_twists(result.trajectory, result.time_intervals)
    times = times_of(result)
    # from standing: at acc_lim_x up to max_vel_x and on at it (soft limits: penalty_epsilon inside them)
    speed_cap = np.minimum(params.max_vel_x, params.acc_lim_x * times[1:]) + 1e-9
    assert np.all(twist[:, 0] <= speed_cap + params.penalty_epsilon)
    cruising = times[1:] > params.max_vel_x / params.acc_lim_x + 1.0
    assert np.all(twist[cruising, 0] >= params.max_vel_x - params.penalty_epsilon - 0.02)
    ideal = 3.0 / params.max_vel_x + params.max_vel_x / params.acc_lim_x   # 3 m from rest to rest
    assert times[-1] == pytest.approx(ideal, rel=0.1)
    assert np.abs(result.trajectory[:, 1]).max() < 0.02


@BOTH
def test_a_person_crossing_ahead_is_passed_behind_with_clearance(params):
    costs, info, check = costmap()
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    # walking up across the path; at the robot's pace both would reach (0, 0) about together
    crossing = person(0.0, -1.2, 0.0, 0.4)
    planner = TebPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    for _ in range(3):
        result = planner.compute((-1.2, 0.0, 0.0), (0.3, 0.0, 0.0), costs, info, path, crossing)
    assert result.status == "ok", result.message
    gap = footprint_gap(result, crossing)
    assert gap.min() >= params.min_obstacle_dist - 0.05
    # where the band crosses the person's line it does so after them (below their feet: they walk up)
    k = int(np.argmin(np.abs(result.trajectory[:, 0])))
    person_y = crossing.positions[0, 1] + crossing.velocities[0, 1] * times_of(result)[k]
    assert result.trajectory[k, 1] < person_y - crossing.radii[0]
    # without the person the band would have met them
    blind = TebPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    for _ in range(3):
        unaware = blind.compute((-1.2, 0.0, 0.0), (0.3, 0.0, 0.0), costs, info, path)
    assert footprint_gap(unaware, crossing).min() < 0.0


@BOTH
def test_the_drive_constraints_hold_on_every_pose_pair(params):
    costs, info, check = costmap(boxes=[(0.3, -0.1, 0.6, 0.2)])
    planner = TebPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    walker = person(1.5, 1.5, 0.0, -0.4)
    for _ in range(3):
        result = planner.compute((-1.5, 0.0, 0.0), (0.2, 0.0, 0.0), costs, info, path, walker)
    assert result.status == "ok", result.message
    twist = band_twists(result.trajectory, result.time_intervals)
    assert_within_velocity_limits(twist, params)
    if not params.holonomic_robot:
        band = result.trajectory
        step = np.diff(band, axis=0)
        moving = np.hypot(step[:, 0], step[:, 1]) > 0.01
        chord = np.arctan2(step[:, 1], step[:, 0])
        middle = band[:-1, 2] + wrap_angle(step[:, 2]) / 2
        off = np.abs(wrap_angle(chord - middle))
        assert np.minimum(off, np.pi - off)[moving].max() < 0.03     # each step an arc, driven forwards or back
        assert result.cmd[1] == 0.0


@BOTH
def test_homotopy_exploration_passes_a_pillar_on_its_free_side(params):
    # a pillar on the path; on its left a wall leaves no room, its right is free
    costs, info, check = costmap(boxes=[(-0.15, -0.15, 0.15, 0.15), (-0.3, 0.45, 0.3, 3.0)])
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    teb = TebPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    result = teb.compute((-1.5, 0.0, 0.0), (0.2, 0.0, 0.0), costs, info, path)
    assert result.status == "ok", result.message
    k = int(np.argmin(np.abs(result.trajectory[:, 0])))
    assert result.trajectory[k, 1] < -0.4                                   # right of the pillar
    assert teb.band.footprint_check.legal_poses(result.trajectory, costs, info).all()
    # one band alone, started on the path, is stuck against the pillar
    single = TebPlanner(TebParams(**{**params.__dict__, "enable_homotopy_class_planning": False}),
                        FootprintCheck(FOOTPRINT.points, check))
    stuck = single.compute((-1.5, 0.0, 0.0), (0.2, 0.0, 0.0), costs, info, path)
    assert not single.band.footprint_check.legal_poses(stuck.trajectory, costs, info).all()


@pytest.mark.parametrize("hysteresis, flips", [(1.0, True), (0.5, False)])
def test_the_band_driven_is_kept_unless_another_is_cheaper_by_the_hysteresis(hysteresis, flips):
    costs, info, check = costmap(boxes=[(-0.15, -0.15, 0.15, 0.15)])   # a pillar on the path, both sides free
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    params = TebParams(holonomic_robot=False, selection_cost_hysteresis=hysteresis, selection_prefer_initial_plan=1.0,
                       **CLEAR)
    planner = TebPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    sides = []
    for y in (0.0, 0.1, -0.1, 0.15, -0.15):     # the robot wobbles across the path's line
        result = planner.compute((-1.5, y, 0.0), (0.2, 0.0, 0.0), costs, info, path)
        assert result.status == "ok"
        sides.append(np.sign(result.trajectory[np.argmin(np.abs(result.trajectory[:, 0])), 1]))
    assert (len(set(sides)) > 1) == flips


def test_signature_names_the_side_each_obstacle_is_passed_on():
    band = np.column_stack([np.linspace(-2, 2, 21), np.zeros(21), np.zeros(21)])
    dts = np.full(20, 0.2)
    left_of_band, right_of_band, far = (Obstacle(np.array([0.0, -0.5]), 0.2), Obstacle(np.array([0.0, 0.5]), 0.2),
                                        Obstacle(np.array([0.0, 5.0]), 0.2))
    assert signature(band, dts, [left_of_band, right_of_band, far], None, 0.5) == (1, -1, 0)
    # a mover is taken where it is when the band comes closest: walking down, it is below at t = 2 s
    walker = person(0.0, 1.0, 0.0, -1.0)
    assert signature(band, dts, [Obstacle(np.zeros(2), 0.25, mover=0)], walker, 0.5) == (1,)


def test_without_movers_takes_out_a_movers_marks_and_leaves_walls():
    costs, info, check = costmap(boxes=[(0.9, -0.1, 1.1, 0.1), (-2.0, -0.1, -1.8, 0.1)])
    walker = person(1.4, 0.0, 0.5, 0.0, radius=0.1)   # was at 1.1 (0.6 s ago): its marks are where the box is
    cleared = without_movers(costs, info, walker, 0.2)
    row, col = int((0.0 + 3.0) / 0.05), int((1.0 + 3.0) / 0.05)
    assert costs[row, col] >= LETHAL_OBSTACLE and cleared[row, col] == 0
    wall = int((-1.9 + 3.0) / 0.05)
    assert cleared[row, wall] == costs[row, wall] >= LETHAL_OBSTACLE


def test_teb_is_a_local_planner_controller():
    from omninav.services.local_planner.control import LocalControl, LocalControlParams
    control = LocalControl(LocalControlParams(controller="teb", teb={"min_obstacle_dist": 0.1}), 0.05)
    assert isinstance(control.controller, TebPlanner)
    assert control.controller.params.max_vel_x == LocalControlParams().max_vel_x   # the node's limits
    with pytest.raises(ValueError, match="selection_cost_hysteresis"):
        LocalControl(LocalControlParams(controller="teb", teb={"selection_cost_hysteresis": 0}), 0.05)
    with pytest.raises(ValueError, match="no_such_name"):
        LocalControl(LocalControlParams(controller="teb", teb={"no_such_name": 1}), 0.05)


def test_a_detour_names_its_via_point_whatever_the_span_keeps_either_side():
    """An obstacle near the span's start: far fewer points are kept before the via point than after
    it, so the detour's middle is nowhere near the via point; the via point's own legs are what is
    checked open (they were the middle three points before: the span's far end, not the detour)."""
    from omninav.services.local_planner.teb import _detour
    span = np.column_stack([np.arange(0.0, 10.01, 0.1), np.zeros(101), np.zeros(101)])
    detour, via = _detour(span, Obstacle(np.array([1.5, 0.1]), 0.2), 1.0, 0.4)
    assert detour[via, :2] == pytest.approx([1.5, 0.1 + 0.6]) and via < len(detour) // 2 - 10
    assert detour[via - 1, 0] < 1.5 - 0.6 and detour[via + 1, 0] > 1.5 + 0.6      # the span's points beside it
