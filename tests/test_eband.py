"""Elastic-band local planner: behaviour on inflated costmaps built by the costmap core."""
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import least_squares

from omninav.services.local_planner.footprint_check import FootprintCheck, footprint_outline
from omninav.services.local_planner.eband import (BandProblem, ElasticBandPlanner, clearance_field, covering_circles,
                                                  initial_band, local_goal, span_path)
from omninav.services.local_planner.params import ElasticBandParams
from omninav.geometry.movers import Movers
from omninav.geometry.se2 import integrate, wrap_angle
from test_dwa import FOOTPRINT, costmap, footprint_hits_lethal, straight

HOLO = ElasticBandParams(holonomic_robot=True, max_vel_y=0.3, min_obstacle_dist=0.15, inflation_dist=0.25)
DIFF = ElasticBandParams(holonomic_robot=False, min_obstacle_dist=0.15, inflation_dist=0.25)
BOTH = pytest.mark.parametrize("params", [HOLO, DIFF], ids=["holonomic", "diff"])


def band_twists(trajectory, intervals):
    """(K-1, 3) body twists of the band's intervals, as the band's velocity edges define them."""
    c, s = np.cos(trajectory[:-1, 2]), np.sin(trajectory[:-1, 2])
    d = np.diff(trajectory, axis=0)
    twist = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(d[:, 2])])
    return twist / intervals[:, None]


def assert_within_velocity_limits(twist, params):
    assert np.all(twist[:, 0] <= params.max_vel_x + 1e-9)
    assert np.all(twist[:, 0] >= -params.max_vel_x_backwards - 1e-9)
    assert np.all(np.abs(twist[:, 2]) <= params.max_vel_theta + 1e-9)
    if params.holonomic_robot:
        assert np.all(np.abs(twist[:, 1]) <= params.max_vel_y + 1e-9)


def distance_to_box(pose, box):
    """Metres from the footprint polygon (sampled every 5 mm) at `pose` to the rectangle (x0, y0, x1, y1)."""
    outline = footprint_outline(FOOTPRINT.points, 0.005)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    x = pose[0] + c * outline[:, 0] - s * outline[:, 1]
    y = pose[1] + s * outline[:, 0] + c * outline[:, 1]
    dx = np.maximum(0.0, np.maximum(box[0] - x, x - box[2]))
    dy = np.maximum(0.0, np.maximum(box[1] - y, y - box[3]))
    return float(np.hypot(dx, dy).min())


def corner_path():
    """East along y = 0 to x = 0.8, then north (the corner's pose faces north)."""
    return np.concatenate([straight(-2.0, 0.0, 0.8, 0.0, n=57), straight(0.8, 0.0, 0.8, 2.5, n=51)[1:]])


def drive(planner, costs, info, path, pose, cycles, goal_tolerance=0.03):
    """Closed loop with a kinematic model: each command is driven for one control period."""
    dt = 1.0 / planner.params.controller_frequency
    pose, velocity = np.array(pose, float), np.zeros(3)
    trace, results = [pose], []
    for _ in range(cycles):
        result = planner.compute(pose, velocity, costs, info, path)
        results.append(result)
        velocity = result.cmd
        pose = integrate(pose, velocity, dt)
        trace.append(pose)
        if math.hypot(*(pose[:2] - path[-1, :2])) < goal_tolerance:
            break
    return np.array(trace), results


@BOTH
def test_a_straight_free_path_gives_a_forward_command_and_a_band_on_the_path(params):
    costs, info, check = costmap()
    planner = ElasticBandPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    result = planner.compute((-2.0, 0.0, 0.0), (0.2, 0.0, 0.0), costs, info, straight(-2.5, 0.0, 2.5, 0.0, n=101))
    assert result.status == "ok", result.message
    assert result.cmd[0] > 0.2 and abs(result.cmd[1]) < 1e-3 and abs(result.cmd[2]) < 1e-3
    band = result.trajectory
    assert np.allclose(band[0], (-2.0, 0.0, 0.0))
    assert np.isclose(band[-1, 0], -2.0 + params.max_global_plan_lookahead_dist, atol=1e-9)   # the lookahead's end
    assert np.abs(band[:, 1]).max() < 0.01 and np.abs(wrap_angle(band[:, 2])).max() < 0.01
    assert np.all(np.diff(band[:, 0]) > 0)
    assert len(result.time_intervals) == len(band) - 1 and np.all(result.time_intervals > 0)
    assert result.clearance == pytest.approx(1e3 - planner.radius)   # no obstacle on the map


@BOTH
def test_an_obstacle_beside_the_path_pushes_the_band_to_min_obstacle_dist(params):
    box = (-0.2, 0.25, 0.2, 0.8)
    costs, info, check = costmap(boxes=[box])
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    assert min(distance_to_box(p, box) for p in path) < 0.1       # the path itself passes too close
    planner = ElasticBandPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    for _ in range(3):   # a few control cycles refine the warm-started band
        result = planner.compute((-1.5, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, path)
    assert result.status == "ok", result.message
    clearance = [distance_to_box(p, box) for p in result.trajectory]
    assert min(clearance) >= params.min_obstacle_dist
    assert result.trajectory[:, 1].min() < -0.05                   # it went round the box's side
    assert result.trajectory[:, 1].max() < 0.05                    # never towards it


@BOTH
def test_the_band_keeps_the_velocity_and_acceleration_limits(params):
    costs, info, check = costmap(boxes=[(0.0, 0.5, 0.4, 0.9)])
    planner = ElasticBandPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    path = corner_path()
    start = np.array([-0.5, 0.0, 0.0])
    for velocity in ((0.0, 0.0, 0.0), (0.35, 0.0, 0.2)):
        planner.reset()
        result = planner.compute(start, velocity, costs, info, path)
        assert result.status == "ok", result.message
        twist = band_twists(result.trajectory, result.time_intervals)
        assert_within_velocity_limits(twist, params)
        spans = np.concatenate([[result.time_intervals[0]],
                                (result.time_intervals[:-1] + result.time_intervals[1:]) / 2])
        accel = np.diff(np.vstack([velocity, twist]), axis=0) / spans[:, None]
        limits = np.array([params.acc_lim_x, params.acc_lim_y, params.acc_lim_theta])
        # acceleration limits are soft: TEB's penalties, starting penalty_epsilon inside them
        assert np.all(np.abs(accel) <= limits + params.penalty_epsilon)
        # the command itself is within the hard limits and one control period's reach
        reach = limits / params.controller_frequency + 1e-12
        assert np.all(np.abs(result.cmd - velocity) <= reach)
        assert -params.max_vel_x_backwards <= result.cmd[0] <= params.max_vel_x
        assert abs(result.cmd[2]) <= params.max_vel_theta


def test_diff_mode_commands_no_vy_and_keeps_the_band_on_arcs():
    costs, info, check = costmap(boxes=[(0.0, 0.5, 0.4, 0.9)])
    planner = ElasticBandPlanner(DIFF, FootprintCheck(FOOTPRINT.points, check))
    path = corner_path()
    for pose, velocity in (((-0.5, 0.0, 0.0), (0.3, 0.0, 0.0)), ((-0.2, -0.1, 0.3), (0.2, 0.0, 0.2))):
        result = planner.compute(pose, velocity, costs, info, path)
        assert result.status == "ok", result.message
        assert result.cmd[1] == 0.0
        band = result.trajectory
        assert abs(wrap_angle(band[-1, 2] - band[0, 2])) > 0.5       # the band turns the corner
        step = np.diff(band, axis=0)
        moving = np.hypot(step[:, 0], step[:, 1]) > 0.01
        # non-holonomic: each chord points half-way between its end headings (both on one arc)
        chord = np.arctan2(step[:, 1], step[:, 0])
        middle = band[:-1, 2] + wrap_angle(step[:, 2]) / 2
        assert np.abs(wrap_angle(chord - middle))[moving].max() < 0.02
        assert np.all(band_twists(band, result.time_intervals)[:, 0] > -1e-6)   # and forwards


def test_holonomic_mode_may_strafe():
    costs, info, check = costmap()
    planner = ElasticBandPlanner(HOLO, FootprintCheck(FOOTPRINT.points, check))
    result = planner.compute((0.0, 0.0, 0.0), (0.0, 0.2, 0.0), costs, info, straight(0.0, 0.0, 0.0, 2.0))
    assert result.status == "ok" and result.cmd[1] > 0.2


@BOTH
def test_a_blocked_path_brakes_with_no_valid_trajectory(params):
    costs, info, check = costmap(boxes=[(0.3, -3.0, 0.5, 3.0)])   # a wall across the whole map, just ahead
    planner = ElasticBandPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    result = planner.compute((0.0, 0.0, 0.0), (0.3, 0.0, 0.2), costs, info, straight(-1.0, 0.0, 2.5, 0.0))
    assert result.status == "no_valid_trajectory"
    assert "braking" in result.message
    assert np.allclose(result.cmd, [0.3 - params.acc_lim_x / 20, 0.0, 0.2 - params.acc_lim_theta / 20])
    assert len(result.trajectory) >= params.min_samples                    # the failed band, for display


def test_no_path_on_the_costmap_is_no_path():
    costs, info, check = costmap()
    result = ElasticBandPlanner(DIFF, FootprintCheck(FOOTPRINT.points, check)).compute(
        (0.0, 0.0, 0.0), (0.1, 0.0, 0.0), costs, info, straight(10.0, 10.0, 12.0, 10.0))
    assert result.status == "no_path"
    assert np.allclose(result.cmd, [0.1 - DIFF.acc_lim_x / 20, 0.0, 0.0])
    assert result.trajectory.shape == (0, 3) and result.time_intervals.shape == (0,)


@BOTH
def test_closed_loop_along_an_l_shaped_path_past_an_obstacle(params):
    box = (-0.6, -0.1, -0.2, 0.3)   # just inside the corner, next to both legs
    costs, info, check = costmap(boxes=[box])
    path = np.concatenate([straight(-2.5, -0.5, 0.0, -0.5, n=51), straight(0.0, -0.5, 0.0, 2.5, n=61)[1:]])
    planner = ElasticBandPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    trace, results = drive(planner, costs, info, path, (-2.5, -0.5, 0.0), 1500)
    assert all(r.status == "ok" for r in results), {r.message for r in results}
    assert math.hypot(*(trace[-1, :2] - path[-1, :2])) < 0.03           # reached the end
    assert not any(footprint_hits_lethal(costs, info, p) for p in trace)
    assert min(distance_to_box(p, box) for p in trace) > 0.0
    assert sum(r.warm_started for r in results) > 0.9 * len(results)    # the band is reused


def test_warm_start_only_on_the_same_path():
    costs, info, check = costmap()
    planner = ElasticBandPlanner(DIFF, FootprintCheck(FOOTPRINT.points, check))
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    assert not planner.compute((-2.0, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, path).warm_started
    assert planner.compute((-1.98, 0.0, 0.0), (0.1, 0.0, 0.0), costs, info, path).warm_started
    other = straight(-2.5, 0.0, 2.5, 1.0, n=101)
    assert not planner.compute((-1.98, 0.0, 0.0), (0.1, 0.0, 0.0), costs, info, other).warm_started


WALKER = Movers(np.array([[-0.5, 0.1]]), np.array([[0.0, 0.1]]), np.array([0.25]), np.zeros((1, 3)))


@BOTH
@pytest.mark.parametrize("movers", [None, WALKER], ids=["static", "a mover"])
def test_the_banded_solver_reaches_scipy_least_squares_cost(params, movers):
    box = (-0.2, 0.25, 0.2, 0.8)
    costs, info, check = costmap(boxes=[box])
    params = replace(params, include_dynamic_obstacles=movers is not None)
    planner = ElasticBandPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    span, final = span_path(straight(-2.5, 0.0, 2.5, 0.0, n=101), (-1.5, 0.0, 0.0), info, 3.0)
    poses, intervals = initial_band(span, np.array([-1.5, 0.0, 0.0]), local_goal(span, final), params)
    poses[1:-1] += np.random.default_rng(5).normal(0.0, 0.02, poses[1:-1].shape)
    problem = BandProblem(planner, poses, intervals, (0.1, 0.0, 0.0), final, clearance_field(costs, info.resolution),
                          info, outer=1, movers=movers)
    jacobian = problem.jacobian(problem.x0)
    numeric = np.column_stack([(problem.residuals(problem.x0 + h) - problem.residuals(problem.x0)) / 1e-7
                               for h in np.eye(len(problem.x0)) * 1e-7])
    assert np.allclose(jacobian, numeric, atol=1e-5)
    reference = least_squares(problem.residuals, problem.x0, jac=problem.jacobian, method="lm")
    *_, cost = problem.solve(300)
    assert cost == pytest.approx(reference.cost, rel=1e-3)
    assert problem.cost() > 2 * reference.cost   # there was something to solve


def test_covering_circles_cover_the_footprint():
    rectangle = np.array([[0.416, 0.318], [-0.416, 0.318], [-0.416, -0.318], [0.416, -0.318]])
    offsets, radius = covering_circles(rectangle)
    assert len(offsets) == 2 and radius < math.hypot(0.416, 0.318)
    u, v = np.meshgrid(np.linspace(-0.416, 0.416, 50), np.linspace(-0.318, 0.318, 50))
    inside = np.min(np.hypot(u[..., None] - offsets, v[..., None]), axis=-1) <= radius + 1e-12
    assert inside.all()


def test_bad_parameters_name_the_problem():
    with pytest.raises(ValueError, match="max_vel_y"):
        ElasticBandParams(holonomic_robot=True)
    with pytest.raises(ValueError, match="inflation_dist"):
        ElasticBandParams(min_obstacle_dist=0.5, inflation_dist=0.4)
    with pytest.raises(ValueError, match="dt_hysteresis"):
        ElasticBandParams(dt_ref=0.1, dt_hysteresis=0.1)


def test_a_strafing_weight_has_a_holonomic_band_face_the_way_it_goes():
    costs, info, check = costmap()
    path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
    sideways = []
    for weight in (0.0, 2.0):
        planner = ElasticBandPlanner(replace(HOLO, weight_strafe=weight), FootprintCheck(FOOTPRINT.points, check))
        for _ in range(3):
            result = planner.compute((-1.5, 0.0, 0.8), (0.0, 0.0, 0.0), costs, info, path)   # facing 46° off the path
        assert result.status == "ok", result.message
        sideways.append(np.abs(band_twists(result.trajectory, result.time_intervals)[:, 1]).mean())
    assert sideways[1] < 0.5 * sideways[0]
