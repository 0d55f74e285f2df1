"""The global_planner service: plan as a service (`get` with start and goal), clear error replies,
goals planned from the robot's pose and replanned in sim time, and `omninav get` against a running
map_server + costmap + global_planner."""
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import ndimage

from conftest import REPO, wait_until
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import (CancelGoal, Clock, Costmap as CostmapMsg, Goal, Header, MapMetaData,
                                      Odometry, Path, Pose2D, PoseWithCovariance, Transform)
from omninav.services.costmap.costmap import Costmap
from omninav.services.costmap.layers import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE
from omninav.services.costmap.params import load_costmap_params
from omninav.services.global_planner.node import PlannerNode, PlannerNodeParams
from omninav.services.global_planner.path_smoother import segment_max_cost
from omninav.services.map_server.mapio import save_map
from omninav.geometry.grid import cell_to_world, grid_coords, kernel_costs
from omninav.services.runtime.merge import order_key
from omninav.services.runtime.node import NS_PER_S, QueryError
from omninav.parameters.declare import ParamError
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client
from omninav.sim.world import load_world, world_path

KEYS = KeyLayout("r1")
PLAN = KEYS.robot("plan")
PARAMS = REPO / "compose" / "params"
ROOM_START = (1.2, 1.0)


def ns(seconds: float) -> int:
    return round(seconds * NS_PER_S)


def room_map():
    return load_world(world_path("room")).rasterize(0.05)


def room_costmap(stamp_ns: int = 0) -> CostmapMsg:
    """The room's global costmap as the costmap service makes it (static + inflation, the paper's footprint)."""
    params = load_costmap_params([PARAMS / "costmap_common_params.yaml", PARAMS / "costmap_global_params.yaml"],
                                 "global_costmap")
    core = Costmap(params, room_map())
    core.update()
    return CostmapMsg(header=Header(stamp_ns=stamp_ns, frame_id="map"), info=core.info, data=core.costs.copy())


def feed(node, messages) -> None:
    """Process (key, message) pairs as replay does: sorted by (stamp, input index, seq)."""
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    items = sorted(((order_key(m.header.stamp_ns, index[k], m.header.seq), index[k], m) for k, m in messages),
                   key=lambda item: item[0])
    for _, i, msg in items:
        node.process(i, msg)


def capture(node) -> list[Path]:
    out = []
    node.plan_pub.sink = lambda pub, payload, stamp: out.append(decode(payload, Path))
    return out


def worst_crossed(costmap: CostmapMsg, poses: np.ndarray) -> int:
    """The highest cost of any cell the path's straight segments cross."""
    u, v = grid_coords(costmap.info, poses[:, 0], poses[:, 1])
    costs = kernel_costs(costmap.data)      # as the smoother passes it: no second compiled variant of the kernel
    return max(int(segment_max_cost(costs, u[i], v[i], u[i + 1], v[i + 1])) for i in range(len(u) - 1))


def planner_with(costmap: CostmapMsg, **params) -> PlannerNode:
    node = PlannerNode(PlannerNodeParams(**params))
    feed(node, [(KEYS.robot("costmap/global"), costmap)])
    return node


def ask(node, **parameters):
    return node.answer(PLAN, parameters)


# ---------------------------------------------------------------- plan as a service

def test_planned_paths_never_touch_lethal_or_inscribed_cells():
    costmap = room_costmap()
    node = planner_with(costmap, use_dijkstra=False)
    # pairs from the largest 4-connected region of passable cells: all reachable
    labels, _ = ndimage.label(costmap.data < INSCRIBED_INFLATED_OBSTACLE)
    region = np.argmax(np.bincount(labels.ravel())[1:]) + 1
    free = np.argwhere((labels == region) & (costmap.data == 0))
    rng = np.random.default_rng(6)
    for _ in range(12):
        (r0, c0), (r1, c1) = free[rng.choice(len(free), 2, replace=False)]
        start, goal = (np.array(cell_to_world(costmap.info, r, c)) for r, c in ((r0, c0), (r1, c1)))
        path = ask(node, start=f"{start[0]},{start[1]},0.3", goal=f"{goal[0]},{goal[1]},-1.2")
        assert isinstance(path, Path) and path.header.frame_id == "map" and len(path.poses) >= 2
        np.testing.assert_allclose(path.poses[0, :2], start, atol=1e-9)
        np.testing.assert_allclose(path.poses[-1], [goal[0], goal[1], -1.2], atol=1e-9)
        assert worst_crossed(costmap, path.poses) < INSCRIBED_INFLATED_OBSTACLE
    assert node.counters["queries/ok"] == 12


def test_the_readme_query_plans_through_the_room_from_the_robots_start():
    costmap = room_costmap()
    node = planner_with(costmap)
    path = ask(node, start="1.2,1.0", goal="8,7")
    assert worst_crossed(costmap, path.poses) < INSCRIBED_INFLATED_OBSTACLE
    length = np.hypot(*np.diff(path.poses[:, :2], axis=0).T).sum()
    assert np.hypot(8 - 1.2, 7 - 1.0) <= length < 1.5 * np.hypot(8 - 1.2, 7 - 1.0)


def test_unreachable_goals_get_an_error_naming_the_reason():
    costmap = room_costmap()
    node = planner_with(costmap)
    with pytest.raises(QueryError, match=r"^goal_in_obstacle: the goal cell .* has cost 254"):
        ask(node, start="1.2,1.0", goal="5,4")            # the pillar
    with pytest.raises(QueryError, match=r"^no_path: no path from cell"):
        ask(node, start="1.2,1.0", goal="50,4")           # unknown space beyond the room's walls (allow_unknown)
    known_only = planner_with(costmap, allow_unknown=False)
    with pytest.raises(QueryError, match=r"^off_map: the goal \(50.00, 4.00\) is off the costmap"):
        ask(known_only, start="1.2,1.0", goal="50,4")
    with pytest.raises(QueryError, match=r"^off_map: the start"):
        ask(known_only, start="-3,1", goal="8,7")
    # a free pocket walled in on every side
    walled = room_costmap()
    u, v = grid_coords(walled.info, 3.0, 7.0)
    r, c = int(v), int(u)
    walled.data[r - 10:r + 11, c - 10:c + 11] = LETHAL_OBSTACLE
    walled.data[r - 8:r + 9, c - 8:c + 9] = 0
    node = planner_with(walled)
    with pytest.raises(QueryError, match=r"^no_path: no path from cell"):
        ask(node, start="1.2,1.0", goal="3.0,7.0")
    assert node.counters["queries/no_path"] == 1


def test_a_goal_the_map_itself_walls_off_is_unreachable_and_one_only_marked_off_is_not():
    """After a failed plan the planner asks the map: a goal in a wall or in a pocket no free cell of
    the map joins to the start is `unreachable` (the navigator ends it at once); a way closed only
    by what the sensors marked on the costmap stays `no_path`, for the recoveries."""
    grid = room_map()
    grid.header = Header(stamp_ns=0, frame_id="map")
    u, v = grid_coords(grid.info, 3.0, 7.0)
    r, c = int(v), int(u)
    grid.data[r - 10:r + 11, c - 10:c + 11] = 100       # a walled pocket on the map itself
    grid.data[r - 8:r + 9, c - 8:c + 9] = 0
    costmap = room_costmap()
    costmap.data[r - 10:r + 11, c - 10:c + 11] = LETHAL_OBSTACLE
    costmap.data[r - 8:r + 9, c - 8:c + 9] = 0
    node = PlannerNode(PlannerNodeParams())
    feed(node, [(KEYS.robot("costmap/global"), costmap), (KEYS.robot("map"), grid)])
    with pytest.raises(QueryError, match=r"^unreachable: the goal \(3.00, 7.00\) lies in a part of the map no way "
                                         r"through free cells joins to the robot's \(1.20, 1.00\) \(no_path: "):
        ask(node, start="1.2,1.0", goal="3.0,7.0")
    with pytest.raises(QueryError, match=r"^unreachable: the goal \(5.00, 4.00\) lies on no free cell of the map "
                                         r"\(goal_in_obstacle: "):
        ask(node, start="1.2,1.0", goal="5,4")            # the pillar
    # a wall of marks across the room (people, a cart) on the costmap only: the map joins them
    marked = room_costmap()
    u, _ = grid_coords(marked.info, 6.0, 0.0)
    marked.data[:, int(u) - 2:int(u) + 3] = LETHAL_OBSTACLE
    node = PlannerNode(PlannerNodeParams())
    feed(node, [(KEYS.robot("costmap/global"), marked), (KEYS.robot("map"), room_map())])
    with pytest.raises(QueryError, match=r"^no_path: no path from cell"):
        ask(node, start="1.2,1.0", goal="8,4")
    # beyond the map lies unknown space the planner may cross: the map cannot say no
    with pytest.raises(QueryError, match=r"^no_path: "):
        ask(node, start="1.2,1.0", goal="50,4")


def test_bad_parameters_and_missing_inputs_get_clear_errors():
    node = PlannerNode()
    with pytest.raises(QueryError, match=r"no global costmap yet \(on omninav/r1/costmap/global\)"):
        ask(node, start="1,1", goal="2,2")
    assert ask(node) is None                            # no plan published yet: "no value yet"
    feed(node, [(KEYS.robot("costmap/global"), room_costmap())])
    for parameters, error in (({"start": "1,1"}, r"goal=x,y\[,yaw\] is required"),
                              ({"start": "1;1", "goal": "2,2"}, r"start='1;1': expected x,y or x,y,yaw"),
                              ({"start": "1,1", "goal": "2"}, r"goal='2': expected x,y or x,y,yaw"),
                              ({"start": "1,1", "goal": "2,2,3,4"}, r"goal='2,2,3,4'"),
                              ({"start": "1,nan", "goal": "2,2"}, r"start='1,nan'"),
                              ({"goal": "2,2", "tolerance": "1"}, r"unknown parameter\(s\) \['tolerance'\]"),
                              ({"goal": "8,7"}, r"no start= given and the robot's pose is not known yet")):
        with pytest.raises(QueryError, match=error):
            ask(node, **parameters)


def test_node_parameters_are_the_ros_names_and_are_checked():
    node = build_node("global_planner", overrides={"use_dijkstra": False, "neutral_cost": 66, "planner_frequency": 2.0})
    assert node.planner.params.neutral_cost == 66 and not node.planner.params.use_dijkstra
    assert node.inputs[0].key == KEYS.sim("clock")        # replanning runs on the sim clock
    assert all(i.key != KEYS.sim("clock") for i in build_node("global_planner").inputs)
    with pytest.raises(ParamError, match=r"lethal_cost must be in \[1, 255\], got 300"):
        build_node("global_planner", overrides={"lethal_cost": 300})
    with pytest.raises(ParamError, match="request_delay_s must be ≥ 0, got -1.0"):
        build_node("global_planner", overrides={"request_delay_s": -1.0})


# ---------------------------------------------------------------- goals, replanning, the robot's pose

def odometry(t: float, x: float) -> Odometry:
    return Odometry(header=Header(stamp_ns=ns(t), frame_id="odom"), pose=Pose2D(x, 0.0, 0.0))


def test_a_goal_is_planned_from_the_robot_and_replanned_on_the_sim_clock_until_canceled():
    node = planner_with(room_costmap(), planner_frequency=2.0, request_delay_s=0.3,
                        initial_pose_x=ROOM_START[0], initial_pose_y=ROOM_START[1])
    plans = capture(node)
    steps = [0.1 * k for k in range(1, 25)]
    messages = [(KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(t)))) for t in steps]
    messages += [(KEYS.robot("odom"), odometry(t, 0.1 * t)) for t in steps]            # driving along x
    messages += [(KEYS.robot("goal"), Goal(header=Header(stamp_ns=ns(0.5), frame_id="map"), goal_id="g1",
                                           pose=Pose2D(8.0, 7.0, 1.0))),
                 (KEYS.robot("cancel"), CancelGoal(header=Header(stamp_ns=ns(1.25)), goal_id="g1"))]
    feed(node, messages)
    # the goal takes effect 0.3 s after its stamp (at 0.9 s), then every 0.5 s on the clock (1.1 s);
    # the cancel at 1.55 s: nothing at 1.6 s or later
    assert [p.header.stamp_ns for p in plans] == [ns(0.9), ns(1.1)]
    # from the odometry before each: at 0.9 s the goal took effect at the odometry stamped 0.9 s, the
    # tick at 1.1 s comes before the odometry stamped 1.1 s
    for plan, x in zip(plans, (0.09, 0.10)):
        np.testing.assert_allclose(plan.poses[0, :2], [ROOM_START[0] + x, ROOM_START[1]], atol=1e-9)
        np.testing.assert_allclose(plan.poses[-1], [8.0, 7.0, 1.0])
    assert ask(node).header.stamp_ns == ns(1.1)         # `get` without parameters: the plan published last
    assert node.counters["plans/ok"] == 2 and node.counters["goals_canceled"] == 1


def test_without_planner_frequency_a_goal_is_planned_once_when_costmap_and_pose_are_there():
    node = PlannerNode(PlannerNodeParams(request_delay_s=0.0))
    plans = capture(node)
    feed(node, [(KEYS.robot("goal"), Goal(header=Header(stamp_ns=ns(0.1), frame_id="map"), pose=Pose2D(8.0, 7.0))),
                (KEYS.robot("odom"), odometry(0.2, 0.0)),                             # no costmap yet
                (KEYS.robot("costmap/global"), room_costmap(ns(0.25))),
                (KEYS.robot("tf/map_odom"), Transform(header=Header(stamp_ns=ns(0.25), frame_id="map"),
                                                      child_frame_id="odom", transform=Pose2D(1.5, 1.2, 0.0))),
                *[(KEYS.robot("odom"), odometry(t, 0.0)) for t in (0.3, 0.4, 0.5)]])
    assert len(plans) == 1 and plans[0].header.stamp_ns == ns(0.3)
    np.testing.assert_allclose(plans[0].poses[0, :2], [1.5, 1.2])                   # odometry through map→odom


def test_a_localizer_pose_newer_than_the_odometry_is_the_start_and_failures_publish_an_empty_path():
    node = planner_with(room_costmap(), request_delay_s=0.0, planner_frequency=10.0,
                        initial_pose_x=ROOM_START[0], initial_pose_y=ROOM_START[1])
    plans = capture(node)
    pose = PoseWithCovariance(header=Header(stamp_ns=ns(0.15), frame_id="map"), pose=Pose2D(2.0, 1.5, 0.0))
    feed(node, [(KEYS.robot("pose"), pose),
                (KEYS.robot("goal"), Goal(header=Header(stamp_ns=ns(0.15), frame_id="map"), pose=Pose2D(8.0, 7.0))),
                (KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(0.2)))),
                (KEYS.robot("odom"), odometry(0.25, 0.0)),
                (KEYS.robot("goal"), Goal(header=Header(stamp_ns=ns(0.25), frame_id="map", seq=2),
                                          pose=Pose2D(5.0, 4.0))),
                (KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(0.3))))])
    assert [p.header.stamp_ns for p in plans] == [ns(0.2), ns(0.3)]
    np.testing.assert_allclose(plans[0].poses[0, :2], [2.0, 1.5])    # the localizer's pose
    assert plans[1].poses.shape == (0, 3)                             # the pillar: no plan
    assert node.counters["plans/goal_in_obstacle"] == 1 and node.counters["plans/ok"] == 1
    np.testing.assert_allclose(ask(node, goal="8,7").poses[0, :2], ROOM_START)   # now the newer odometry


def test_plans_name_the_request_they_answer_and_failures_say_why():
    node = planner_with(room_costmap(), request_delay_s=0.0, goal_topic="plan_request",
                        initial_pose_x=ROOM_START[0], initial_pose_y=ROOM_START[1])
    assert all(i.key != KEYS.robot("goal") for i in node.inputs)     # the navigator's requests only
    plans = capture(node)
    feed(node, [(KEYS.robot("plan_request"), Goal(header=Header(stamp_ns=ns(0.1), frame_id="map"), goal_id="g1#1",
                                                  pose=Pose2D(8.0, 7.0))),
                (KEYS.robot("odom"), odometry(0.2, 0.0)),
                (KEYS.robot("plan_request"), Goal(header=Header(stamp_ns=ns(0.25), frame_id="map", seq=2),
                                                  goal_id="g1#2", pose=Pose2D(5.0, 4.0))),   # the pillar
                (KEYS.robot("odom"), odometry(0.3, 0.0))])
    assert [(p.goal_id, len(p.poses) > 0) for p in plans] == [("g1#1", True), ("g1#2", False)]
    assert plans[0].error == ""
    assert plans[1].error.startswith("goal_in_obstacle: the goal cell") and "cost 254" in plans[1].error


def test_the_goal_topic_must_carry_goals():
    with pytest.raises(ParamError, match="goal_topic must be a topic of Goal messages, got 'scan'"):
        build_node("global_planner", overrides={"goal_topic": "scan"})
    with pytest.raises(ParamError, match="goal_topic must be a robot topic: 'nowhere': unknown robot topic"):
        build_node("global_planner", overrides={"goal_topic": "nowhere"})


def test_inputs_in_the_wrong_frame_are_rejected_and_counted():
    node = PlannerNode()
    feed(node, [(KEYS.robot("goal"), Goal(header=Header(stamp_ns=1, frame_id="odom"))),
                (KEYS.robot("pose"), PoseWithCovariance(header=Header(stamp_ns=1, frame_id="world"))),
                (KEYS.robot("costmap/global"), CostmapMsg(header=Header(frame_id="map"),
                                                          info=MapMetaData(width=3, height=2),
                                                          data=np.zeros((3, 3), np.uint8))),
                (KEYS.robot("tf/map_odom"), Transform(header=Header(frame_id="odom"), child_frame_id="map"))])
    assert {k for k in node.counters if k.startswith("malformed/")} == {
        f"malformed/{KEYS.robot(t)}" for t in ("goal", "pose", "costmap/global", "tf/map_odom")}
    assert len(node.pending) == 0 and node.newest_costmap is None


# ---------------------------------------------------------------- over the bus

def _replies(session, selector):
    return [(r.ok is not None, r.ok.payload.to_bytes() if r.ok is not None else r.err.payload.to_bytes().decode())
            for r in session.get(selector, timeout=2.0)]


def test_omninav_get_plans_with_running_map_server_costmap_and_planner(processes, router_endpoint, tmp_path):
    map_yaml = save_map(room_map(), tmp_path / "room")
    processes.omninav("run", "costmap")    # the sample ROS files of compose/params
    processes.omninav("run", "global_planner", "--set", "use_dijkstra=false")
    with open_client(router_endpoint) as session:
        # both are listening once they answer (their subscribers are declared before their queryables);
        # the map server publishes its map once, at start
        wait_until(lambda: _replies(session, KEYS.robot("costmap/global")), timeout=60, what="the costmap service")
        wait_until(lambda: _replies(session, PLAN), timeout=60, what="the planner service")
        processes.omninav("run", "map_server", "--set", f"yaml_filename={map_yaml}")
        wait_until(lambda: any(ok for ok, _ in _replies(session, f"{PLAN}?start=1.2,1.0;goal=8,7")), timeout=60,
                   what="a plan from the running services")
    env = {**os.environ, "OMNINAV_ROUTER": router_endpoint}
    ok = subprocess.run([sys.executable, "-m", "omninav.cli.main", "get", "omninav/r1/plan;start=1.2,1.0;goal=8,7"],
                        capture_output=True, text=True, timeout=60, cwd=REPO, env=env)
    assert ok.returncode == 0, ok.stderr
    assert "omninav/r1/plan (Path)" in ok.stdout and 'frame_id: "map"' in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "omninav.cli.main", "get", "omninav/r1/plan;start=1.2,1.0;goal=5,4"],
                         capture_output=True, text=True, timeout=60, cwd=REPO, env=env)
    assert bad.returncode == 1
    assert "error reply: unreachable: the goal (5.00, 4.00) lies on no free cell of the map (goal_in_obstacle: " in bad.stderr
