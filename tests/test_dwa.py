"""DWA / trajectory rollout: behaviour on inflated costmaps built by the costmap core."""
import math

import numpy as np
import pytest

from omninav.schemas.messages import MapMetaData, OccupancyGrid, Pose2D
from omninav.services.costmap.costmap import Costmap
from omninav.geometry.footprint import make_footprint
from omninav.services.costmap.params import CostmapParams, InflationLayerParams, StaticLayerParams
from omninav.services.local_planner.reference import reference_path_distance, reference_pose_cost, reference_rollout
from omninav.services.local_planner.dwa import DistanceCache, DwaPlanner, dynamic_window, path_maps, sample_velocities
from omninav.services.local_planner.footprint_check import FootprintCheck, footprint_check_cost
from omninav.services.local_planner.params import DwaParams
from omninav.geometry.se2 import integrate, wrap_angle
from omninav.geometry.grid import world_to_cell
from omninav.geometry.polygons import densify
from omninav.services.costmap.layers import INSCRIBED_INFLATED_OBSTACLE

RES = 0.05
SQUARE = ((0.2, 0.2), (-0.2, 0.2), (-0.2, -0.2), (0.2, -0.2))   # a small robot, 0.4 m square
FOOTPRINT = make_footprint(SQUARE, padding=0.0)
HOLO = DwaParams(min_vel_x=0.0, max_vel_y=0.5, min_vel_y=-0.5)
DIFF = DwaParams(min_vel_x=0.0, holonomic_robot=False)


def costmap(boxes=(), size_m=6.0, origin=(-3.0, -3.0), padding=0.0):
    """Inflated costs (static + inflation, ROS defaults) of a free map with lethal boxes (x0, y0, x1, y1),
    for the SQUARE robot padded by `padding`."""
    n = int(round(size_m / RES))
    info = MapMetaData(resolution=RES, width=n, height=n, origin=Pose2D(*origin, 0.0))
    data = np.zeros((n, n), np.int8)
    for x0, y0, x1, y1 in boxes:
        data[int((y0 - origin[1]) / RES):int((y1 - origin[1]) / RES),
             int((x0 - origin[0]) / RES):int((x1 - origin[0]) / RES)] = 100
    inflation = InflationLayerParams()
    cm = Costmap(CostmapParams(footprint=SQUARE, footprint_padding=padding,
                               layers=(StaticLayerParams(), inflation)),
                 OccupancyGrid(info=info, data=data))
    cm.update()
    padded = make_footprint(SQUARE, padding=padding)
    check = footprint_check_cost(padded.inscribed_radius, padded.circumscribed_radius,
                                 inflation.inflation_radius, inflation.cost_scaling_factor)
    return cm.costs.copy(), cm.info, check


def straight(x0, y0, x1, y1, n=60):
    t = np.linspace(0.0, 1.0, n)[:, None]
    xy = np.array([x0, y0]) + t * np.array([x1 - x0, y1 - y0])
    return np.column_stack([xy, np.full(n, math.atan2(y1 - y0, x1 - x0))])


def footprint_hits_lethal(costs, info, pose):
    """Whether any cell under the footprint at `pose` is lethal (brute force over the cells)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    u, v = np.meshgrid(np.linspace(-0.2, 0.2, 41), np.linspace(-0.2, 0.2, 41))
    x, y = pose[0] + c * u - s * v, pose[1] + s * u + c * v
    rows, cols = ((y - info.origin.y) / RES).astype(int), ((x - info.origin.x) / RES).astype(int)
    return bool((costs[rows, cols] >= 254).any())


def drive(planner, costs, info, path, pose, cycles, velocity=(0.0, 0.0, 0.0)):
    """Closed loop in a kinematic sim: each cycle's command is driven for one control period."""
    dt = 1.0 / planner.params.controller_frequency
    pose, velocity = np.array(pose, float), np.array(velocity, float)
    trace, results = [pose], []
    for _ in range(cycles):
        result = planner.compute(pose, velocity, costs, info, path)
        results.append(result)
        velocity = result.cmd
        pose = integrate(pose, velocity, dt)
        trace.append(pose)
    return np.array(trace), results


def test_free_space_drives_along_the_path_to_the_goal():
    costs, info, check = costmap()
    path = straight(-2.0, 0.0, 2.0, 0.0)
    planner = DwaPlanner(HOLO, FootprintCheck(FOOTPRINT.points, check))
    trace, results = drive(planner, costs, info, path, (-2.0, 0.0, 0.0), 300)
    assert all(r.status == "ok" for r in results)
    near = np.hypot(trace[:, 0] - 2.0, trace[:, 1]) < 0.10
    assert near.any(), "reaches the goal within 10 cm"
    # until then (a goal checker stops it there) it keeps on the path, never backing away
    approach = trace[:int(np.argmax(near)) + 1]
    assert np.max(np.abs(approach[:, 1])) < 0.05
    assert np.all(np.maximum.accumulate(approach[:, 0]) - approach[:, 0] < 0.01)
    assert np.max(np.abs([r.cmd[0] for r in results])) == HOLO.max_vel_x   # cruising at full speed on the way


@pytest.mark.parametrize("params", [HOLO, DIFF], ids=["holonomic", "diff"])
def test_an_obstacle_on_the_path_is_avoided_and_never_entered(params):
    costs, info, check = costmap(boxes=[(0.0, -0.3, 0.3, 0.3)])
    planner = DwaPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    # an obstacle that appeared on the path after planning: driving on would hit it
    through = straight(-2.5, 0.0, 2.5, 0.0)
    first = planner.compute((-1.0, 0.0, 0.0), (0.5, 0.0, 0.0), costs, info, through)
    straight_on = np.flatnonzero((np.abs(first.samples[:, 1]) < 1e-9) & (np.abs(first.samples[:, 2]) < 1e-9)
                                 & (first.samples[:, 0] >= 0.45))
    assert straight_on.size and not first.legal[straight_on].any()
    assert first.best >= 0 and first.legal[first.best]
    trace, results = drive(planner, costs, info, through, (-2.0, 0.0, 0.0), 120)
    # and once the global planner has bent the path around it, the robot follows it past
    around = np.concatenate([straight(-2.5, 0.0, -0.8, 0.0), straight(-0.8, 0.0, -0.4, 0.8),
                             straight(-0.4, 0.8, 0.7, 0.8), straight(0.7, 0.8, 1.1, 0.0), straight(1.1, 0.0, 2.5, 0.0)])
    detour, detour_results = drive(planner, costs, info, around, (-2.0, 0.0, 0.0), 240)
    for result in results + detour_results:
        if result.best >= 0:   # the chosen rollout never touches a lethal cell
            assert not any(footprint_hits_lethal(costs, info, p) for p in result.poses[result.best])
    assert not any(footprint_hits_lethal(costs, info, p) for p in np.concatenate([trace, detour]))
    # blocked, it stays short of the box, or, the path's distances flooded around the box (as ROS's
    # MapGrid's), passes it by itself (the holonomic robot does)
    assert trace[:, 0].max() < 0.0 or trace[-1, 0] > 0.3
    assert detour[-1, 0] > 1.0                # past the box


def test_holonomic_mode_strafes_towards_a_goal_on_the_left():
    costs, info, check = costmap()
    result = DwaPlanner(HOLO, FootprintCheck(FOOTPRINT.points, check)).compute(
        (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, straight(0.0, 0.0, 0.0, 2.0))
    low, high = dynamic_window(HOLO, (0.0, 0.0, 0.0))
    assert result.status == "ok"
    assert result.cmd[1] >= 0.5 * high[1] > 0        # sideways, left
    assert abs(result.cmd[0]) < result.cmd[1]


def test_diff_mode_never_commands_vy():
    costs, info, check = costmap(boxes=[(0.8, -0.3, 1.1, 0.3)])
    planner = DwaPlanner(DIFF, FootprintCheck(FOOTPRINT.points, check))
    assert np.all(sample_velocities(DIFF, (0.2, 0.3, 0.1))[:, 1] == 0.0)
    for goal in ((0.0, 2.0), (2.0, 0.0), (-2.0, -1.0)):
        result = planner.compute((0.0, 0.0, 0.0), (0.1, 0.0, 0.0), costs, info, straight(0.0, 0.0, *goal))
        assert result.cmd[1] == 0.0 and np.all(result.samples[:, 1] == 0.0)


@pytest.mark.parametrize("velocity", [(0.0, 0.0, 0.0), (0.3, -0.2, 0.5), (0.5, 0.5, -1.0), (0.9, 0.0, 0.0)])
@pytest.mark.parametrize("dwa", [True, False])
def test_commands_stay_within_the_dynamic_window(velocity, dwa):
    params = DwaParams(min_vel_x=0.0, max_vel_y=0.5, min_vel_y=-0.5, dwa=dwa)
    costs, info, check = costmap()
    result = DwaPlanner(params, FootprintCheck(FOOTPRINT.points, check)).compute(
        (0.0, 0.0, 0.0), velocity, costs, info, straight(0.0, 0.0, 2.0, 1.0))
    period = 1.0 / params.controller_frequency if dwa else params.sim_time
    reach = np.array([params.acc_lim_x, params.acc_lim_y, params.acc_lim_theta]) * period + 1e-12
    assert np.all(np.abs(result.samples - velocity) <= reach)
    assert np.all(np.abs(result.cmd - velocity) <= reach)
    inside = [(params.min_vel_x, params.max_vel_x), (params.min_vel_y, params.max_vel_y),
              (params.min_vel_theta, params.max_vel_theta)]
    for axis, (low, high) in enumerate(inside):
        if low <= velocity[axis] <= high:   # starting inside the limits: every sample stays inside
            assert np.all((result.samples[:, axis] >= low - 1e-12) & (result.samples[:, axis] <= high + 1e-12))
    if velocity[0] - reach[0] > params.max_vel_x:   # too fast to get within the limits: brake fully
        assert np.allclose(result.samples[:, 0], velocity[0] - reach[0] + 1e-12)


def test_no_legal_trajectory_backs_up_or_brakes():
    costs, info, check = costmap(boxes=[(0.25, -1.0, 0.5, 1.0)])   # a wall just ahead
    planner = DwaPlanner(DwaParams(min_vel_x=0.1, holonomic_robot=False), FootprintCheck(FOOTPRINT.points, check))
    result = planner.compute((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, straight(0.0, 0.0, 2.0, 0.0))
    assert not result.legal.any()
    assert result.status == "escape" and result.cmd[0] < 0 and result.cmd[1] == 0
    no_escape = DwaPlanner(DwaParams(min_vel_x=0.1, holonomic_robot=False, escape_vel=0.0),
                           FootprintCheck(FOOTPRINT.points, check))
    result = no_escape.compute((0.0, 0.0, 0.0), (0.3, 0.0, 0.2), costs, info, straight(0.0, 0.0, 2.0, 0.0))
    assert result.status == "no_valid_trajectory"
    assert np.allclose(result.cmd, [0.3 - 2.5 / 20, 0.0, 0.2 - 3.2 / 20])   # braking as hard as allowed


def test_backing_up_goes_on_until_escape_reset_dist_before_forward_samples_come_back():
    # base_local_planner's escaping: a robot that backed out of a gap it did not fit would, a
    # centimetre back, see the gap's mouth legal again and creep in, back out, creep in...
    walled, info, check = costmap(boxes=[(0.25, -1.0, 0.5, 1.0)])   # a wall just ahead
    free, _, _ = costmap()
    params = DwaParams(min_vel_x=0.1, holonomic_robot=False)
    planner = DwaPlanner(params, FootprintCheck(FOOTPRINT.points, check))
    path = straight(0.0, 0.0, 2.0, 0.0)
    standing = (0.0, 0.0, 0.0)
    assert planner.compute((0.0, 0.0, 0.0), standing, walled, info, path).status == "escape"
    backed = planner.compute((-0.05, 0.0, 0.0), standing, free, info, path)
    assert backed.status == "ok" and np.all(backed.samples[:, 0] == 0.0), "turns only while escaping"
    beyond = planner.compute((-params.escape_reset_dist - 0.01, 0.0, 0.0), standing, free, info, path)
    assert beyond.status == "ok" and beyond.cmd[0] > 0, "forward again once escape_reset_dist is backed"
    assert planner.compute((0.0, 0.0, 0.0), standing, walled, info, path).status == "escape"
    turned = planner.compute((0.0, 0.0, params.escape_reset_theta + 0.01), standing, free, info, path)
    assert (turned.samples[:, 0] > 0).any(), "forward again once escape_reset_theta is turned"


def test_no_path_on_the_costmap_brakes():
    costs, info, check = costmap()
    result = DwaPlanner(HOLO, FootprintCheck(FOOTPRINT.points, check)).compute(
        (0.0, 0.0, 0.0), (0.1, 0.0, 0.0), costs, info, straight(10.0, 10.0, 12.0, 10.0))
    assert result.status == "no_path" and np.allclose(result.cmd, 0.0)


def test_path_maps_measure_metres_to_the_local_path_and_goal():
    costs, info, _ = costmap()
    path = straight(-5.0, 0.0, 5.0, 0.0, n=201)   # runs off both edges
    maps = path_maps(path, (0.5, 0.3, 0.0), info)
    assert np.isclose(maps.path[0, 0], 0.5, atol=0.05)            # starts at the point nearest the robot
    assert np.all(maps.path[:, 0] < 3.0)                          # ends where the path leaves the grid
    rows, cols = np.array([60 + 20]), np.array([60 + 20])         # (1.025, 1.025)
    assert np.isclose(maps.path_dist[rows, cols][0], 1.0, atol=0.051)
    goal_col = int((maps.local_goal[0] + 3.0) / RES)
    assert np.isclose(maps.goal_dist[60, goal_col - 30], 1.5, atol=0.051)


def test_path_distances_around_obstacles_are_dijkstras_over_the_same_moves():
    costs, info, _ = costmap(boxes=[(-1.0, -2.0, -0.6, 1.5), (0.5, -0.5, 0.9, 3.0), (-2.5, 1.8, -1.5, 2.2)])
    path = np.vstack([straight(-2.5, -2.5, -2.5, 2.5), straight(-2.5, 2.5, 2.5, -1.0)])   # bends round the boxes
    maps = path_maps(path, (-2.5, -2.5, 0.0), info, costs)
    points = densify(maps.path, RES / 2)
    rows, cols = world_to_cell(info, points[:, 0], points[:, 1])
    on_path = np.zeros(costs.shape, bool)
    on_path[rows, cols] = True
    expected = reference_path_distance(on_path, costs < INSCRIBED_INFLATED_OBSTACLE, RES)
    reached = np.isfinite(expected)
    assert 0.5 < reached.mean() < 1.0 and expected[reached].max() > 2.0      # obstacles and long ways round
    assert np.allclose(maps.path_dist[reached], expected[reached], rtol=1e-6, atol=1e-6)
    assert np.all(maps.path_dist[~reached] > 0)


def test_distance_cache_hands_out_the_maps_a_fresh_flood_gives():
    cache = DistanceCache()
    open_room, info, _ = costmap()
    with_box, _, _ = costmap(boxes=[(0.5, -0.5, 0.9, 0.5)])
    cycles = [(open_room, (-2.0, 0.0, 0.0)), (open_room, (-2.0, 0.0, 0.0)), (with_box, (-2.0, 0.0, 0.0)),
              (with_box, (-1.0, 0.0, 0.0)), (open_room, (-1.0, 0.0, 0.0))]
    previous = None
    for costs, pose in cycles:
        path = straight(-2.5, 0.0, 2.5, 0.0, n=101)
        fresh, cached = path_maps(path, pose, info, costs), path_maps(path, pose, info, costs, cache)
        assert np.array_equal(fresh.path_dist, cached.path_dist) and np.array_equal(fresh.goal_dist, cached.goal_dist)
        if previous is not None and previous[0] is costs and previous[1] == pose:
            assert cached.path_dist is previous[2].path_dist      # the same cycle again: not flooded again
        previous = (costs, pose, cached)
    assert not cached.path_dist.flags.writeable


def test_batch_rollout_matches_a_per_trajectory_python_loop():
    costs, info, check = costmap(boxes=[(0.4, -0.5, 0.7, 0.1), (-1.0, 0.6, 0.5, 0.9)])
    rng = np.random.default_rng(3)
    for dwa in (True, False):
        params = DwaParams(min_vel_x=-0.3, max_vel_y=0.5, min_vel_y=-0.5, dwa=dwa)
        planner = DwaPlanner(params, FootprintCheck(FOOTPRINT.points, check))
        samples = rng.uniform([-0.3, -0.5, -1.0], [0.5, 0.5, 1.0], size=(60, 3))
        velocity = np.array([0.2, -0.1, 0.3])
        poses, max_cost, legal = planner.rollout(samples, (0.0, 0.0, 0.2), velocity, costs, info)
        assert 0 < legal.sum() < len(samples)   # the case exercises both outcomes
        for i, twist in enumerate(samples):
            ref_poses, ref_cost, ref_legal = reference_rollout(planner, twist, planner.n_steps(samples),
                                                               (0.0, 0.0, 0.2), velocity, costs, info)
            assert ref_legal == legal[i]
            assert ref_cost == max_cost[i]
            ours = poses[i, :len(ref_poses)]
            assert np.allclose(ref_poses[:, :2], ours[:, :2], atol=1e-9)
            assert np.allclose(wrap_angle(ref_poses[:, 2] - ours[:, 2]), 0.0, atol=1e-9)


def test_pose_checks_match_looking_at_every_outline_point_near_obstacles_and_the_grid_edge():
    # the rollout looks at only some outline points (those not ruled out by their neighbours'
    # clearance); obstacles scattered up to the grid's edge, poses everywhere: the same verdicts
    boxes = [(x, y, x + 0.1, y + 0.1) for x in np.arange(-2.9, 2.9, 0.7) for y in np.arange(-2.9, 2.9, 0.9)]
    costs, info, check_cost = costmap(boxes=boxes)
    rng = np.random.default_rng(5)
    poses = np.column_stack([rng.uniform(-3.0, 3.0, 3000), rng.uniform(-3.0, 3.0, 3000), rng.uniform(-4.0, 4.0, 3000)])
    poses[0] = (-2.55, -2.45, 0.0)     # a start clear of the stop zone
    for stop_padding in (0.0, 0.05):
        planner = DwaPlanner(HOLO, FootprintCheck(FOOTPRINT.points, check_cost, stop_padding=stop_padding))
        legal = planner.footprint_check.legal_poses(poses, costs, info)
        check = planner.footprint_check.setup(poses[0], costs, info)
        expected = np.array([reference_pose_cost(planner.footprint_check, check, pose, costs, info) >= 0
                             for pose in poses])
        assert np.array_equal(legal, expected)
        # both verdicts, and poses whose centre cell is fine but whose outline leaves the grid
        rows, cols = (((poses[:, 1::-1] + 3.0) / RES).astype(int).clip(0, info.width - 1)).T
        off_edge = (np.abs(poses[:, :2]).max(axis=1) > 3.0 - 0.2) & (costs[rows, cols] < 253)
        assert legal.any() and not legal.all() and (off_edge & ~legal).any()


@pytest.mark.parametrize("params", [DwaParams(), HOLO], ids=["ros_defaults", "holonomic"])
def test_a_robot_facing_a_wall_3_cm_away_leaves_it_for_a_goal_behind_it(params):
    # the path turns back round the wall's end: straight-line distances would pull the robot into
    # the wall, and with min_vel_x > 0 no sample of the window backs or slides away from it
    costs, info, check = costmap(boxes=[(0.25, -3.0, 0.5, 1.0)])   # round its upper end only
    planner = DwaPlanner(params, FootprintCheck(FOOTPRINT.points, check, stop_padding=0.05))
    start = (0.02, 0.0, 0.0)    # the front 3 cm from the wall
    around = np.concatenate([straight(0.02, 0.0, 0.02, 1.6), straight(0.02, 1.6, 1.2, 1.6),
                             straight(1.2, 1.6, 1.2, -1.0)])
    trace, results = drive(planner, costs, info, around, start, 600)
    assert not any(footprint_hits_lethal(costs, info, p) for p in trace)
    assert np.hypot(trace[:, 0] - 1.2, trace[:, 1]).min() < 0.1      # behind the wall


@pytest.mark.parametrize("params", [HOLO, DIFF], ids=["holonomic", "diff"])
def test_a_robot_pushed_within_its_padding_of_a_wall_drives_on_with_its_own_outline(params):
    # a corridor 0.7 m wide: the robot (0.4 m) fits, its padded footprint (0.6 m) only on the centre
    # line; off it by 10 cm (a tracking error) the centre stands on an inscribed cell and the padded
    # outline on the wall: every rollout of the padded footprint is illegal, the robot's own is not
    padding = 0.1
    costs, info, check = costmap(boxes=[(-3.0, 0.35, 3.0, 0.7), (-3.0, -0.7, 3.0, -0.35)], padding=padding)
    padded = make_footprint(SQUARE, padding=padding)
    planner = DwaPlanner(params, FootprintCheck(padded.points, check, stop_padding=0.02,
                                                footprint_padding=padding))
    start = (-2.0, 0.1, 0.0)
    assert costs[int((start[1] - info.origin.y) / RES), int((start[0] - info.origin.x) / RES)] == 253
    trace, results = drive(planner, costs, info, straight(-2.5, 0.0, 2.5, 0.0), start, 200)
    assert not any(footprint_hits_lethal(costs, info, p) for p in trace)
    assert trace[-1, 0] > 1.5, "drove along the corridor"


def test_the_stop_zone_is_not_stacked_on_a_padding_that_already_holds_it():
    # the monitor's stop zone lies around the robot's own outline: a footprint padded by 0.1 m
    # already keeps a 0.05 m zone clear, so a robot 0.06 m from a wall gets no extra 0.05 m
    padding = 0.1
    costs, info, check = costmap(boxes=[(0.25, -1.0, 0.5, 1.0)], padding=padding)
    padded = make_footprint(SQUARE, padding=padding)
    poses = np.array([[-1.0, 0.0, 0.0], [-0.075, 0.0, 0.0], [0.0, 0.0, 0.0]])
    thick = FootprintCheck(padded.points, check, stop_padding=0.05, footprint_padding=padding)
    thin = FootprintCheck(padded.points, check, stop_padding=0.15, footprint_padding=padding)
    def legal_from_afar(check):   # each pose checked as from the first, a metre clear of the wall
        return [bool(check.legal_poses(poses[[0, i]], costs, info)[1]) for i in range(len(poses))]
    assert legal_from_afar(thick) == [True, True, False]
    assert legal_from_afar(thin) == [True, False, False]


def test_a_post_inside_the_padded_outline_is_not_passed_over_by_the_outline_check():
    # a post one cell thick 5 cm beside the robot's own outline lies inside its outline padded by the
    # monitor's zone (and a quarter cell): that outline touches nothing, and a check set up with it
    # let the robot move onto the post, the outline stepping over it; the padding is one that holds
    # nothing (building-diff-84 stood 20 s in a door, every neighbouring pose illegal by such a check)
    padding = 0.01
    costs, info, check_cost = costmap(boxes=[(-0.05, 0.25, 0.05, 0.31)], padding=padding)
    footprint_check = FootprintCheck(make_footprint(SQUARE, padding=padding).points, check_cost,
                                     stop_padding=0.05, footprint_padding=padding)
    start = (0.0, 0.0, 0.0)
    check = footprint_check.setup(start, costs, info)
    assert np.abs(check.outline[:, 1]).max() < 0.25
    towards_the_post = np.array([start, (0.0, 0.05, 0.0)])
    assert footprint_check.check_poses(check, towards_the_post, costs, info).tolist() == [True, False]


def test_a_padding_wider_than_the_stop_zone_does_not_keep_the_robot_from_turning_round():
    # a wall 0.35 m ahead of the centre: the padded corners (0.42 m out) would sweep it, the robot's
    # own grown by the monitor's 0.02 m zone (0.31 m) do not; the path leads back the way it came,
    # so the robot turns on the spot instead of backing away from the wall for good
    padding = 0.1
    costs, info, check = costmap(boxes=[(0.35, -1.0, 0.6, 1.0)], padding=padding)
    padded = make_footprint(SQUARE, padding=padding)
    planner = DwaPlanner(DwaParams(min_vel_x=0.0, holonomic_robot=False),
                         FootprintCheck(padded.points, check, stop_padding=0.02, footprint_padding=padding))
    back = straight(0.0, 0.0, -2.5, 0.0)
    first = planner.compute((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, back)
    assert first.status == "ok" and first.cmd[0] == 0.0 and first.cmd[2] != 0.0, "turns on the spot"
    trace, results = drive(planner, costs, info, back, (0.0, 0.0, 0.0), 200)
    assert not any(footprint_hits_lethal(costs, info, p) for p in trace)
    assert trace[-1, 0] < -1.5, "drove back along the path"
    wide_zone = DwaPlanner(DwaParams(min_vel_x=0.0, holonomic_robot=False),
                           FootprintCheck(padded.points, check, stop_padding=0.15, footprint_padding=padding))
    assert wide_zone.compute((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), costs, info, back).status == "escape"


def test_a_footprint_check_set_up_again_gives_what_a_fresh_one_gives_as_the_grid_changes():
    open_room, info, check = costmap()
    with_box, _, _ = costmap(boxes=[(0.3, -0.4, 0.7, 0.4)])
    reused = FootprintCheck(FOOTPRINT.points, check, stop_padding=0.05)
    for costs in (open_room, open_room, with_box, with_box, open_room):
        got = reused.setup((0.0, 0.0, 0.0), costs, info)
        fresh = FootprintCheck(FOOTPRINT.points, check, stop_padding=0.05).setup((0.0, 0.0, 0.0), costs, info)
        assert np.array_equal(got.near, fresh.near) and np.array_equal(got.skips, fresh.skips)
        assert np.array_equal(got.outline, fresh.outline) and got.centre_limit == fresh.centre_limit
    assert not np.array_equal(reused.setup((0.0, 0.0, 0.0), with_box, info).near,
                              reused.setup((0.0, 0.0, 0.0), open_room, info).near)     # the grids differ where it matters


def _wedged_against_a_wall(padding):
    """A robot whose own front edge lies 3 cm into the first lethal column of a wall (the wall's
    face is somewhere in that cell): as it stands after braking for an obstacle seen late."""
    costs, info, check = costmap(boxes=[(0.22, -1.0, 0.6, 1.0)], padding=padding)
    padded = make_footprint(SQUARE, padding=padding)
    start = (0.03, 0.0, 0.0)
    assert footprint_hits_lethal(costs, info, start)
    return costs, info, FootprintCheck(padded.points, check, stop_padding=0.02, footprint_padding=padding), start


@pytest.mark.parametrize("padding", [0.0, 0.1])
def test_a_robot_whose_own_outline_lies_on_a_lethal_cell_may_drive_away_but_not_onto_another(padding):
    costs, info, footprint_check, start = _wedged_against_a_wall(padding)
    check = footprint_check.setup(start, costs, info)
    poses = np.array([start, (-0.03, 0.0, 0.0), (0.08, 0.0, 0.0), (0.03, 0.0, 0.3), (0.03, 0.0, -0.3)])
    assert check.wedged and not footprint_check.check_poses(check, poses[:1], costs, info)[0]
    legal = footprint_check.check_poses(footprint_check.escape_check(check, start, costs, info), poses, costs, info)
    # where it stands and 6 cm back are legal; 5 cm on, its edge lies on the wall's next column,
    # and turned by 0.3 rad a corner does too
    assert legal.tolist() == [True, True, False, False, False]


@pytest.mark.parametrize("params", [DwaParams(min_vel_x=-0.3, max_vel_y=0.5, min_vel_y=-0.5), DIFF],
                         ids=["holonomic reversing", "diff by escape"])
def test_a_robot_wedged_against_a_wall_backs_away_along_its_path(params):
    costs, info, footprint_check, start = _wedged_against_a_wall(0.1)
    planner = DwaPlanner(params, footprint_check)
    trace, results = drive(planner, costs, info, straight(0.03, 0.0, -2.5, 0.0), start, 200)
    assert results[0].status != "no_valid_trajectory", "the first cycle already finds a way off the wall"
    on_wall = [footprint_hits_lethal(costs, info, p) for p in trace]
    off = on_wall.index(False)
    assert not any(on_wall[off:]), "once off the wall, never on a lethal cell again"
    assert trace[:, 0].max() <= start[0] + 1e-9, "never further into the wall"
    assert trace[-1, 0] < -1.5, "drove back along the path"


@pytest.mark.parametrize("person_at, drives_off", [((-0.5, 0.6), False), ((-2.0, 2.0), True)],
                         ids=["person at hand", "person walked on"])
def test_a_wedged_robot_brakes_with_a_person_at_hand_and_drives_off_once_they_walk_on(person_at, drives_off):
    # people shove a robot against a wall: with a tracked person within wedged_mover_distance DWA
    # holds the wedged robot to its own outline, as before the escape check; 2.6 m off, walking
    # away, the person has walked on and the robot drives off the wall as it does alone
    from omninav.geometry.movers import Movers
    costs, info, footprint_check, start = _wedged_against_a_wall(0.1)
    person = Movers(np.array([person_at]), np.array([[-0.5, 0.0]]), np.array([0.25]), np.zeros((1, 3)))
    path = straight(0.03, 0.0, -2.5, 0.0)
    with_person = DwaPlanner(DIFF, footprint_check).compute(start, (0.0, 0.0, 0.0), costs, info, path, movers=person)
    alone = DwaPlanner(DIFF, footprint_check).compute(start, (0.0, 0.0, 0.0), costs, info, path)
    assert alone.status != "no_valid_trajectory" and alone.cmd.any()
    if drives_off:
        assert with_person.status != "no_valid_trajectory" and with_person.cmd.any()
    else:
        assert with_person.status == "no_valid_trajectory" and not with_person.cmd.any()


def test_a_wedged_robot_is_forgiven_the_cells_where_it_became_wedged_not_new_ones_each_cycle():
    # forgiven afresh every cycle, a robot creeping along a wall could creep on (generated
    # doorway-65: 15 robot-fault contacts sliding along a door's jamb); anchored, the robot moved 6 cm
    # along the wall lies on cells it was not forgiven and brakes, where a planner that has just
    # met it there (wedged there first) drives off
    costs, info, footprint_check, start = _wedged_against_a_wall(0.1)
    path = straight(0.03, 0.0, -2.5, 0.0)
    slid = (start[0], start[1] + 0.06, start[2])
    planner = DwaPlanner(DIFF, footprint_check)
    assert planner.compute(start, (0.0, 0.0, 0.0), costs, info, path).status != "no_valid_trajectory"
    assert planner.compute(slid, (0.0, 0.0, 0.0), costs, info, path).status == "no_valid_trajectory"
    assert DwaPlanner(DIFF, footprint_check).compute(slid, (0.0, 0.0, 0.0), costs, info, path).status != "no_valid_trajectory"


def test_a_wedged_robot_drives_off_clear_of_the_wall_not_along_it():
    # the escape forgives the cells the robot is wedged on; a holonomic robot whose path runs along
    # the wall would strafe along it, touching it all the way (generated doorway-7048, -7068: the
    # simulator counts each renewed touch to the robot); a way off must end clear of the wall
    costs, info, footprint_check, start = _wedged_against_a_wall(0.1)
    along = straight(0.03, 0.0, 0.03, 2.5)
    along[:, 2] = 0.0          # the robot keeps facing the wall
    planner = DwaPlanner(DwaParams(max_vel_y=0.5, min_vel_y=-0.5), footprint_check)
    result = planner.compute(start, (0.0, 0.0, 0.0), costs, info, along)
    assert result.status != "no_valid_trajectory" and result.cmd.any()
    held = np.array(start) + result.cmd * planner.params.sim_time    # the command held for a rollout (facing +x)
    assert not footprint_hits_lethal(costs, info, held), f"{result.cmd} does not end clear of the wall"
