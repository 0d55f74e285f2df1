"""The global planner core: optimal, safe, keepout-respecting paths; clear statuses; the smoother."""
import math

import numpy as np
import pytest
from scipy.sparse import csgraph

from omninav.schemas.messages import Header, MapMetaData, OccupancyGrid, Pose2D
from omninav.services.costmap.costmap import Costmap
from omninav.services.costmap.params import (CostmapParams, InflationLayerParams, KeepoutLayerParams,
                                             StaticLayerParams)
from omninav.services.global_planner.astar import (GOAL_IN_OBSTACLE, NO_PATH, OFF_MAP, OK, GlobalPlanner, Workspace,
                                                   orientations, search)
from omninav.services.global_planner.reference import graph
from omninav.services.global_planner.params import GlobalPlannerParams
from omninav.services.global_planner.path_smoother import segment_max_cost, smooth
from omninav.services.map_server.mapio import load_map
from omninav.geometry.grid import cell_to_world, grid_coords, kernel_costs
from omninav.parameters.declare import ParamError
from omninav.sim.world import WorldError, load_world, shipped_worlds, world_path

from conftest import SHARED_DATA

SQUARE = ((0.1, 0.1), (0.1, -0.1), (-0.1, -0.1), (-0.1, 0.1))
ASTAR = GlobalPlannerParams(use_dijkstra=False)


def info_for(costs, resolution=0.05, origin=(0.0, 0.0, 0.0)) -> MapMetaData:
    return MapMetaData(resolution=resolution, width=costs.shape[1], height=costs.shape[0], origin=Pose2D(*origin))


def random_costs(rng, shape=(40, 50)) -> np.ndarray:
    """Mostly free cells, some graded costs, walls, inscribed cells and unknown patches."""
    costs = np.where(rng.random(shape) < 0.6, 0, rng.integers(1, 200, shape)).astype(np.uint8)
    costs[rng.random(shape) < 0.15] = 254
    costs[rng.random(shape) < 0.05] = 253
    costs[rng.random(shape) < 0.05] = 255
    return costs


def inflated(data: np.ndarray, resolution=0.05, keepout=None) -> Costmap:
    """A global costmap (static + keepout + inflation) over an occupancy grid."""
    def grid(values):
        return OccupancyGrid(header=Header(frame_id="map"), info=info_for(values, resolution),
                             data=np.asarray(values, np.int8))
    layers = (StaticLayerParams(), KeepoutLayerParams(), InflationLayerParams(inflation_radius=0.3))
    costmap = Costmap(CostmapParams(footprint=SQUARE, footprint_padding=0.0, layers=layers), grid(data))
    if keepout is not None:
        costmap.set_masks(grid(keepout))
    costmap.update()
    return costmap


def centre(info, cell, yaw=0.0):
    x, y = cell_to_world(info, *cell)
    return float(x), float(y), yaw


def crossed_cells_max(costs, info, poses) -> int:
    """The largest cost of any cell the path's straight segments cross."""
    u, v = grid_coords(info, poses[:, 0], poses[:, 1])
    costs = kernel_costs(costs)     # as the smoother passes it: no second compiled variant of the kernel
    return max(int(segment_max_cost(costs, u[i], v[i], u[i + 1], v[i + 1])) for i in range(len(u) - 1))


# ---------------------------------------------------------------- optimality

def test_astar_cost_equals_dijkstra_and_scipy_on_random_maps():
    rng = np.random.default_rng(11)
    checked = 0
    for trial in range(30):
        costs = random_costs(rng)
        params = GlobalPlannerParams(allow_unknown=bool(trial % 2), outline_map=bool(trial % 3))
        free = np.argwhere(costs < 200)
        start, goal = (tuple(int(v) for v in free[i]) for i in rng.integers(len(free), size=2))
        astar = search(costs, start, goal, params, use_dijkstra=False)
        astar_cost = astar.cost(goal) if astar.found else math.inf
        dijkstra = search(costs, start, goal, params, use_dijkstra=True)
        dijkstra_cost = dijkstra.cost(goal) if dijkstra.found else math.inf
        # the reference: scipy's Dijkstra over the same graph (the start cell is always enterable
        # from nowhere, so leaving it is all that matters)
        reference = csgraph.dijkstra(graph(costs, params), indices=start[0] * costs.shape[1] + start[1])
        expected = reference[goal[0] * costs.shape[1] + goal[1]] if start != goal else 0.0
        if not np.isfinite(expected):
            assert not astar.found and not dijkstra.found
            continue
        assert astar_cost == pytest.approx(dijkstra_cost, rel=1e-12)
        assert astar_cost == pytest.approx(expected, rel=1e-12)
        checked += 1
    assert checked >= 10


def test_a_reused_workspace_answers_as_a_fresh_one_also_after_its_stamps_run_out():
    # the workspace's one-byte stamps last about 127 searches, then it clears them: searches past
    # that must not see the cells of earlier ones as reached
    rng = np.random.default_rng(3)
    costs = random_costs(rng, (20, 24))
    free = np.argwhere(costs < 200)
    workspace = Workspace()
    for _ in range(300):
        start, goal = (tuple(int(v) for v in free[i]) for i in rng.integers(len(free), size=2))
        reused = search(costs, start, goal, ASTAR, workspace=workspace)
        fresh = search(costs, start, goal, ASTAR)
        assert reused.found == fresh.found and reused.expanded == fresh.expanded
        np.testing.assert_array_equal(reused.cost_to_come(), fresh.cost_to_come())
        np.testing.assert_array_equal(reused.expanded_mask(), fresh.expanded_mask())


def test_the_path_is_a_chain_of_allowed_steps_that_adds_up_to_its_cost():
    rng = np.random.default_rng(5)
    costs = random_costs(rng, (30, 30))
    costs[0, :] = costs[:, 0] = 0
    params = GlobalPlannerParams(use_dijkstra=False, outline_map=False, allow_unknown=False)
    result = search(costs, (0, 0), (0, 29), params)
    cells = result.path((0, 29))
    assert tuple(cells[0]) == (0, 0) and tuple(cells[-1]) == (0, 29)
    total = 0.0
    for (r0, c0), (r1, c1) in zip(cells[:-1], cells[1:]):
        assert max(abs(r1 - r0), abs(c1 - c0)) == 1
        assert costs[r1, c1] < 253
        if r1 != r0 and c1 != c0:            # no squeezing between two blocked cells
            assert costs[r0, c1] < 253 and costs[r1, c0] < 253
        total += (50 + 3.0 * costs[r1, c1]) * (math.sqrt(2) if r1 != r0 and c1 != c0 else 1.0)
    assert total == pytest.approx(result.cost((0, 29)))


def test_a_path_is_asked_only_to_a_reached_cell():
    costs = np.zeros((5, 7), np.uint8)
    costs[:, 3] = 254                                   # a wall: the right half is out of reach
    result = search(costs, (2, 1), (2, 5), GlobalPlannerParams(outline_map=False))
    assert not result.found and tuple(result.path((2, 0))[-1]) == (2, 0)
    with pytest.raises(ValueError, match="not reached"):
        result.path((2, 5))


# ---------------------------------------------------------------- safety

def test_paths_never_enter_lethal_or_inscribed_cells():
    rng = np.random.default_rng(2)
    planned = 0
    for trial in range(12):
        data = np.where(rng.random((60, 80)) < 0.03, 100, 0).astype(np.int8)
        data[rng.integers(0, 60), :] = 100            # a wall with a gap
        data[:, rng.integers(0, 80)] = 100
        costmap = inflated(data)
        costs, info = costmap.costs, costmap.info
        free = np.argwhere(costs[1:-1, 1:-1] == 0) + 1
        a, b = (tuple(int(v) for v in free[i]) for i in rng.integers(len(free), size=2))
        for params in (ASTAR, GlobalPlannerParams(use_grid_path=True)):
            result = GlobalPlanner(params).plan(costs, info, centre(info, a), centre(info, b, 1.0))
            assert result.status in (OK, NO_PATH)
            if result.ok:
                planned += 1
                assert (costs[result.cells[1:, 0], result.cells[1:, 1]] < 253).all()
                assert crossed_cells_max(costs, info, result.poses) < 253
    assert planned >= 8


def test_keepout_zones_are_respected():
    data = np.zeros((40, 80), np.int8)
    mask = np.zeros((40, 80), np.int8)
    mask[5:35, 38:42] = 100                           # a keepout band across the middle, open at the ends
    costmap = inflated(data, keepout=mask)
    info = costmap.info
    result = GlobalPlanner(ASTAR).plan(costmap.costs, info, centre(info, (20, 10)), centre(info, (20, 70)))
    assert result.ok
    rows, cols = result.cells.T
    assert not (mask[rows, cols] == 100).any()
    assert (costmap.costs[rows, cols] < 253).all()
    assert not ((rows >= 5) & (rows < 35) & (cols >= 36) & (cols < 44)).any()   # nor within the inscribed radius
    free = inflated(data)                             # without the keepout: straight across
    direct = GlobalPlanner(ASTAR).plan(free.costs, info, centre(info, (20, 10)), centre(info, (20, 70)))
    assert direct.length < result.length


# ---------------------------------------------------------------- failures and tolerance

def test_unreachable_and_invalid_goals_get_a_status():
    data = np.zeros((40, 40), np.int8)
    data[:, 20] = 100                                 # a wall with no gap
    costmap = inflated(data)
    costs, info = costmap.costs, costmap.info
    planner = GlobalPlanner(ASTAR)
    unreachable = planner.plan(costs, info, centre(info, (20, 5)), centre(info, (20, 35)))
    assert unreachable.status == NO_PATH and not unreachable.ok and "no path" in unreachable.message
    assert len(unreachable.poses) == 0 and unreachable.expanded > 0
    in_wall = planner.plan(costs, info, centre(info, (20, 5)), centre(info, (20, 20)))
    assert in_wall.status == GOAL_IN_OBSTACLE and "has cost 254" in in_wall.message
    on_border = planner.plan(costs, info, centre(info, (20, 5)), centre(info, (0, 5)))
    assert on_border.status == GOAL_IN_OBSTACLE and "border" in on_border.message
    known_only = GlobalPlanner(GlobalPlannerParams(use_dijkstra=False, allow_unknown=False))
    off = known_only.plan(costs, info, centre(info, (20, 5)), (50.0, 1.0, 0.0))
    assert off.status == OFF_MAP and "goal" in off.message
    off = known_only.plan(costs, info, (-1.0, 1.0, 0.0), centre(info, (20, 5)))
    assert off.status == OFF_MAP and "start" in off.message
    same = planner.plan(costs, info, centre(info, (20, 5)), centre(info, (20, 5), 2.0))
    assert same.ok and same.poses[-1, 2] == 2.0 and same.cost == 0.0


def test_a_goal_off_the_costmap_is_planned_to_through_unknown_space():
    # the costmap knows a 2 m x 2 m square: a wall across it with a gap at the top, unknown beyond
    data = np.zeros((40, 40), np.int8)
    data[:32, 20] = 100
    costmap = inflated(data)
    costs, info = costmap.costs, costmap.info
    start, goal = centre(info, (20, 5)), (3.0, 1.0, 0.0)          # the goal lies 1 m beyond the right edge
    plan = GlobalPlanner(ASTAR).plan(costs, info, start, goal)
    assert plan.ok, plan.message
    assert plan.poses[0, :2].tolist() == pytest.approx(start[:2]) and plan.poses[-1, :2].tolist() == pytest.approx(goal[:2])
    steps = np.hypot(*np.diff(plan.poses[:, :2], axis=0).T)
    assert steps.max() < 2 * info.resolution                        # one connected path
    # on the known grid it keeps out of the wall and its inflation
    on_grid = plan.poses[(plan.poses[:, 0] < 2.0) & (plan.poses[:, 1] < 2.0)]
    u, v = grid_coords(info, on_grid[:, 0], on_grid[:, 1])
    assert (costs[v.astype(int), u.astype(int)] < 253).all()
    # known free space is cheaper than unknown: the path goes through the gap, not around the wall's far end
    assert on_grid[:, 1].max() > 32 * info.resolution
    assert plan.poses[:, 1].min() > -0.1


def test_goal_in_an_obstacle_moves_to_the_nearest_reachable_cell():
    data = np.zeros((60, 60), np.int8)
    data[20:40, 20:40] = 100                          # a block; the goal lies inside it
    data[40:50, 45:58] = 100                          # a closed box: the cells inside are unreachable
    data[41:49, 46:57] = 0
    costmap = inflated(data)
    costs, info = costmap.costs, costmap.info
    goal_xy = cell_to_world(info, 30, 37)             # 3 cells inside the block's right edge
    tolerance = 0.6
    planner = GlobalPlanner(GlobalPlannerParams(use_dijkstra=False, default_tolerance=tolerance))
    result = planner.plan(costs, info, centre(info, (5, 5)), (float(goal_xy[0]), float(goal_xy[1]), 0.5))
    assert result.ok and result.goal_adjusted
    # brute force: the passable cell nearest the goal, among those the start reaches (a search
    # towards a cell inside the block never ends early, so it expands every reachable cell)
    reachable = search(costs, (5, 5), (30, 30), ASTAR).expanded_mask()
    rows, cols = np.nonzero(reachable & (costs < 253))
    d = np.hypot(*(np.array(cell_to_world(info, rows, cols)) - np.array(goal_xy)[:, None]))
    assert d.min() <= tolerance
    assert tuple(result.cells[-1]) == (rows[d.argmin()], cols[d.argmin()])
    assert result.poses[-1, 2] == 0.5                 # the goal's yaw at the end
    # a free goal inside the closed box: the nearest reachable cell is outside, 7 cells below
    inside = (45, 51)
    assert costs[inside] < 253
    inside_xy = cell_to_world(info, *inside)
    boxed = planner.plan(costs, info, centre(info, (5, 5)), (float(inside_xy[0]), float(inside_xy[1]), 0.0))
    d_box = np.hypot(*(np.array(cell_to_world(info, rows, cols)) - np.array(inside_xy)[:, None]))
    assert boxed.ok and boxed.goal_adjusted and tuple(boxed.cells[-1]) == (52, 51)
    assert (rows[d_box.argmin()], cols[d_box.argmin()]) == (52, 51)
    unreachable = GlobalPlanner(GlobalPlannerParams(use_dijkstra=False, default_tolerance=0.2)).plan(
        costs, info, centre(info, (5, 5)), (float(inside_xy[0]), float(inside_xy[1]), 0.0))
    assert unreachable.status == NO_PATH and "0.2 m" in unreachable.message
    # without tolerance the goal in the block is refused
    strict = GlobalPlanner(ASTAR).plan(costs, info, centre(info, (5, 5)), (float(goal_xy[0]), float(goal_xy[1]), 0.0))
    assert strict.status == GOAL_IN_OBSTACLE


# ---------------------------------------------------------------- smoothing and orientations

def test_the_smoother_never_increases_the_cost_of_any_point():
    rng = np.random.default_rng(9)
    moved = 0
    for trial in range(10):
        data = np.where(rng.random((50, 60)) < 0.02, 100, 0).astype(np.int8)
        costs = inflated(data).costs
        free = np.argwhere(costs < 253)
        a, b = (tuple(int(v) for v in free[i]) for i in rng.integers(len(free), size=2))
        result = search(costs, a, b, ASTAR)
        if not result.found:
            continue
        cells = result.path(b)
        points = np.column_stack([cells[:, 1] + 0.5, cells[:, 0] + 0.5])
        smoothed = smooth(points, costs, max_iterations=200)
        assert smoothed.shape == points.shape
        np.testing.assert_array_equal(smoothed[[0, -1]], points[[0, -1]])
        before = costs[cells[:, 0], cells[:, 1]]
        after = costs[np.floor(smoothed[:, 1]).astype(int), np.floor(smoothed[:, 0]).astype(int)]
        assert (after <= before).all()
        for i in range(len(smoothed) - 1):            # nor do the segments between points
            bound = max(before[i], before[i + 1])
            assert segment_max_cost(kernel_costs(costs), *smoothed[i], *smoothed[i + 1]) <= bound
        moved += int(np.abs(smoothed - points).max() > 0.1)
    assert moved >= 3                                 # it does smooth


def test_smoothing_shortens_a_staircase():
    costs = np.zeros((30, 30), np.uint8)
    info = info_for(costs, 0.1)
    grid_path = GlobalPlanner(GlobalPlannerParams(use_grid_path=True, outline_map=False)).plan(
        costs, info, centre(info, (2, 2)), centre(info, (27, 12)))
    smooth_path = GlobalPlanner(GlobalPlannerParams(outline_map=False)).plan(
        costs, info, centre(info, (2, 2)), centre(info, (27, 12)))
    straight = math.hypot(2.5, 1.0)
    assert straight <= smooth_path.length < grid_path.length


def test_orientations_follow_ros_modes():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [2.0, 2.0]])
    forward = orientations(xy, 0.3, 1.0, 1, 1)
    np.testing.assert_allclose(forward, [0.0, 0.0, math.atan2(1, 1), math.pi / 2, 1.0])
    backward = orientations(xy, 0.3, 1.0, 4, 1)
    np.testing.assert_allclose(backward[:2], [-math.pi, -math.pi])
    np.testing.assert_allclose(orientations(xy, 0.3, 1.0, 5, 1)[0], -math.pi / 2)
    np.testing.assert_allclose(orientations(xy, 0.3, 1.0, 0, 1), [0, 0, 0, 0, 1.0])
    interpolated = orientations(xy, 0.2, 1.0, 2, 1)
    np.testing.assert_allclose(interpolated, [0.2, 0.4, 0.6, 0.8, 1.0])
    # forward, then a blend over the last straight stretch (turns under 0.35 rad) into the goal's yaw
    bend = np.vstack([xy, [[2.0, 3.0]]])
    then = orientations(bend, 0.3, 1.0, 3, 1)
    np.testing.assert_allclose(then, [0.3, 0.0, math.pi / 4, math.pi / 2, (math.pi / 2 + 1.0) / 2, 1.0])
    wrapped = orientations(xy[:3], 3.0, -3.0, 2, 1)   # the short way round, through ±π
    assert abs(abs(wrapped[1]) - math.pi) < 0.2


def test_plans_on_real_building_maps():
    for name in ("willow-full-0.05.yaml", "basement_fixed.yaml"):
        path = SHARED_DATA / "maps" / name
        if not path.is_file():
            pytest.skip(f"{path} not present")
        costmap = Costmap(CostmapParams(footprint=((0.416, 0.318), (0.416, -0.318), (-0.416, -0.318), (-0.416, 0.318)),
                                        layers=(StaticLayerParams(), InflationLayerParams())), load_map(path))
        costmap.update()
        costs, info = costmap.costs, costmap.info
        rng = np.random.default_rng(4)
        free = np.argwhere(costs == 0)
        for _ in range(3):
            a, b = (tuple(int(v) for v in free[i]) for i in rng.integers(len(free), size=2))
            result = GlobalPlanner(ASTAR).plan(costs, info, centre(info, a), centre(info, b, -1.0))
            assert result.status in (OK, NO_PATH)
            if result.ok:
                np.testing.assert_allclose(result.poses[0, :2], centre(info, a)[:2])
                np.testing.assert_allclose(result.poses[-1], centre(info, b, -1.0))
                assert crossed_cells_max(costs, info, result.poses) < 253


def test_visualize_potential_returns_the_cost_to_come():
    costs = np.zeros((10, 12), np.uint8)
    info = info_for(costs, 1.0)
    result = GlobalPlanner(GlobalPlannerParams(visualize_potential=True, outline_map=False)).plan(
        costs, info, (0.5, 0.5, 0.0), (11.5, 0.5, 0.0))
    assert result.potential.shape == (10, 12)
    assert result.potential[0, 0] == 0 and result.potential[0, 11] == pytest.approx(550.0)


# ---------------------------------------------------------------- parameters

def test_ros_global_planner_files_load(tmp_path):
    from omninav.services.runtime.params import read_yaml, unwrap_ros
    path = tmp_path / "global_planner_params.yaml"
    path.write_text("""GlobalPlanner:
  old_navfn_behavior: false
  use_quadratic: true
  use_dijkstra: false
  use_grid_path: false
  allow_unknown: true
  planner_window_x: 0.0
  planner_window_y: 0.0
  default_tolerance: 0.5
  publish_scale: 100
  planner_costmap_publish_frequency: 0.0
  lethal_cost: 253
  neutral_cost: 66
  cost_factor: 0.55
  publish_potential: true
  orientation_mode: 3
""")
    params = GlobalPlannerParams.from_mapping(unwrap_ros(read_yaml(path), "GlobalPlanner"), str(path))
    assert (params.use_dijkstra, params.default_tolerance, params.neutral_cost, params.cost_factor,
            params.orientation_mode) == (False, 0.5, 66, 0.55, 3)
    with pytest.raises(ParamError, match="unknown parameter"):
        GlobalPlannerParams.from_mapping({"use_dijkstr": True})
    with pytest.raises(ParamError, match="orientation_mode"):
        GlobalPlannerParams.from_mapping({"orientation_mode": 9})


PAPER_FOOTPRINT = ((0.416, 0.318), (0.416, -0.318), (-0.416, -0.318), (-0.416, 0.318))


@pytest.mark.parametrize("name", shipped_worlds())
def test_plans_in_every_sim_world_are_safe_and_optimal(name):
    """From the robot's start to its goals and to far free cells: A* finds a path that never crosses
    an inscribed or lethal cell of the paper's footprint, at the same cost as Dijkstra."""
    try:
        world = load_world(world_path(name))
    except WorldError as exc:          # willow needs ../shared/data beside the checkout
        pytest.skip(str(exc))
    costmap = Costmap(CostmapParams(footprint=PAPER_FOOTPRINT, layers=(StaticLayerParams(), InflationLayerParams())),
                      world.rasterize(0.05))
    costmap.update()
    costs, info = costmap.costs, costmap.info
    start = tuple(float(v) for v in world.robot.start)
    free = np.argwhere(costs == 0)
    rng = np.random.default_rng(11)
    targets = [tuple(float(v) for v in goal) for goal in world.goals]
    targets += [centre(info, tuple(int(v) for v in free[i])) for i in rng.integers(len(free), size=3)]
    for goal in targets:
        astar = GlobalPlanner(ASTAR).plan(costs, info, start, goal)
        assert astar.ok, f"{name}: {astar.message}"
        assert crossed_cells_max(costs, info, astar.poses) < 253
        dijkstra = GlobalPlanner(GlobalPlannerParams(use_dijkstra=True)).plan(costs, info, start, goal)
        assert dijkstra.ok and math.isclose(astar.cost, dijkstra.cost, rel_tol=1e-9)
