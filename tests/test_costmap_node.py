"""The costmap service: both costmaps from the ROS sample files over the simulated room and
warehouse (walls lethal and inflated, a moving obstacle in the local window), scans placed through
odometry and map→odom, ROS 1 and ROS 2 files configuring it, a map costed at once without a clock,
clear refusals of bad configurations; and a live multi-process run with the global planner that
replays byte for byte into both services."""
import math
import signal

import numpy as np
import pytest
import zenoh
from scipy import ndimage

from launching import command_chain
from conftest import REPO, wait_until
from omninav.schemas import decode, encode
from omninav.schemas.attachment import pack_attachment
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import (ClearCostmaps, Clock, Costmap as CostmapMsg, Goal, Header, LaserScan, MapMetaData,
                                      OccupancyGrid, Odometry, Path, Pose2D, Transform)
from omninav.services.chassis.node import ChassisNode
from omninav.geometry.footprint import make_footprint
from omninav.services.costmap.layers import INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, inflation_cost
from omninav.services.costmap.node import CostmapNode, CostmapNodeParams
from omninav.services.lidar.node import LidarNode, LidarNodeParams
from omninav.services.map_server.mapio import save_map
from omninav.geometry.grid import cell_to_world, world_to_cell
from omninav.services.map_server.node import MapServerNode, MapServerParams
from omninav.services.recorder.mcap_io import read_records
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.merge import order_key
from omninav.services.runtime.node import NS_PER_S, QueryError
from omninav.parameters.declare import ParamError
from omninav.services.runtime.run import build_node
from omninav.services.runtime.zenoh_config import open_client
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.world import load_world, world_path

KEYS = KeyLayout("r1")
GLOBAL, LOCAL = KEYS.robot("costmap/global"), KEYS.robot("costmap/local")
SAMPLES = REPO / "compose" / "params"
COMMON = str(SAMPLES / "costmap_common_params.yaml")
SAMPLE_FILES = dict(global_costmap_files=(COMMON, str(SAMPLES / "costmap_global_params.yaml")),
                    local_costmap_files=(COMMON, str(SAMPLES / "costmap_local_params.yaml")))
PAPER_INSCRIBED = 0.328    # m: the samples' 0.832 x 0.636 m footprint padded by 0.01 m


def ns(seconds: float) -> int:
    return round(seconds * NS_PER_S)


def odometry(t: float, x: float, y: float) -> Odometry:
    return Odometry(header=Header(stamp_ns=ns(t), frame_id="odom"), pose=Pose2D(x, y, 0.0))


def feed(node, messages) -> None:
    """Process (key, message) pairs as replay does: sorted by (stamp, input index, seq)."""
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    for _, i, msg in sorted(((order_key(m.header.stamp_ns, index[k], m.header.seq), index[k], m) for k, m in messages),
                            key=lambda item: item[0]):
        node.process(i, msg)


def capture(node) -> list[tuple[str, CostmapMsg]]:
    out = []
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.append((p.key, decode(payload, CostmapMsg)))
    return out


def simulate(world_name: str, steps: int, map_yaml=None) -> tuple[CostmapNode, list]:
    """sim + chassis + lidar (+ map_server) + costmap with the sample ROS files, in lockstep."""
    world = load_world(world_path(world_name))
    x, y, yaw = (float(v) for v in world.robot.start)
    costmap = CostmapNode(CostmapNodeParams(**SAMPLE_FILES, initial_pose_x=x, initial_pose_y=y, initial_pose_a=yaw))
    nodes = [SimNode(SimNodeParams(world=world_name)), ChassisNode(), LidarNode(LidarNodeParams(world=world_name))]
    if map_yaml is not None:
        nodes.append(MapServerNode(MapServerParams(yaml_filename=str(map_yaml))))
    runner = InProcessRunner([*nodes, costmap])
    published = []
    runner.tap(lambda key, payload, stamp: published.append((key, decode(payload))) if key in (GLOBAL, LOCAL) else None)
    runner.run_until(lambda: False, steps)
    return costmap, published


def distance_to(mask: np.ndarray, resolution: float) -> np.ndarray:
    """Metres from every cell centre to the nearest True cell centre."""
    return ndimage.distance_transform_edt(~mask) * resolution


def test_the_room_global_costmap_has_its_walls_lethal_and_inflated_and_both_costmaps_answer(tmp_path):
    world = load_world(world_path("room"))
    grid = world.rasterize(0.05)
    node, published = simulate("room", 75, save_map(grid, tmp_path / "room"))
    glob = node.answer(GLOBAL, {})
    assert glob.header.frame_id == "map" and glob.info == grid.info
    walls = grid.data == 100
    assert (glob.data[walls] == LETHAL_OBSTACLE).all()
    # at least the inflation of the map's walls everywhere (ROS's formula), 253 within the inscribed radius
    d = distance_to(walls, grid.info.resolution)
    near = d <= 0.55
    assert (glob.data[near] >= [inflation_cost(v, PAPER_INSCRIBED, 10.0) for v in d[near]]).all()
    assert (glob.data[(d > 0) & (d <= PAPER_INSCRIBED)] >= INSCRIBED_INFLATED_OBSTACLE).all()
    assert ((glob.data > 0) & (glob.data < INSCRIBED_INFLATED_OBSTACLE)).any()
    # the laser sees what the map holds: nothing costs anything far from the walls
    assert (glob.data[d > 0.55 + 2 * 0.05] == 0).all()

    local = node.answer(LOCAL, {})
    assert local.header.frame_id == "odom"
    assert (local.info.width, local.info.height, local.info.resolution) == (120, 120, 0.05)
    assert abs(local.info.origin.x + 3.0) <= 0.05 and abs(local.info.origin.y + 3.0) <= 0.05   # robot at odom 0
    rows, cols = np.nonzero(local.data == LETHAL_OBSTACLE)
    assert len(rows) > 50                                         # the walls within 3 m of the start
    x, y = cell_to_world(local.info, rows, cols)
    r, c = world_to_cell(grid.info, x + world.robot.start[0], y + world.robot.start[1])
    assert (d[r, c] <= 2 * 0.05).all()                            # where the map has walls

    keys = [key for key, _ in published]
    assert GLOBAL in keys and LOCAL in keys
    for key, msg in published:
        assert msg.header.frame_id == {GLOBAL: "map", LOCAL: "odom"}[key]
        assert key == LOCAL or (msg.info == grid.info and (msg.data[walls] == LETHAL_OBSTACLE).all())
    values = node.diagnostic().values
    for name in ("global/static_layer", "global/obstacle_layer", "global/inflation_layer", "local/obstacle_layer",
                 "local/inflation_layer", "global/total", "local/total"):
        assert values[f"update_ms/{name}"] >= 0.0
    assert values["updates/global"] >= 2 and values["updates/local"] >= 2


def test_a_moving_obstacle_shows_up_in_the_local_costmap_where_it_truly_is():
    world = load_world(world_path("warehouse"))
    node, _ = simulate("warehouse", 60)
    served = node.costmaps["local"]
    t = served.updated_ns / NS_PER_S
    assert t >= 0.4
    forklift = world.movers.circles_at(t)[0]          # from (3, 1.5), 2 m ahead of the robot, at 0.8 m/s
    local = node.answer(LOCAL, {})
    rows, cols = np.nonzero(local.data == LETHAL_OBSTACLE)
    x, y = cell_to_world(local.info, rows, cols)
    points = np.column_stack([x, y]) + world.robot.start[:2]          # odom → world: the robot started there
    on_it = np.hypot(*(points - forklift[:2]).T) < forklift[2] + 0.15  # the last scan is at most 0.1 s older
    assert on_it.sum() >= 3
    assert (world.distance(points[on_it]) > 0.3).all()                 # no wall there: it is the mover
    # its side facing the robot: within the inscribed radius of the lethal cells there
    towards_robot = (world.robot.start[:2] - forklift[:2]) / np.hypot(*(world.robot.start[:2] - forklift[:2]))
    x, y = forklift[:2] + towards_robot * (forklift[2] + 0.2) - world.robot.start[:2]
    assert local.data[world_to_cell(local.info, x, y)] >= INSCRIBED_INFLATED_OBSTACLE
    with pytest.raises(QueryError, match=r"costmap/global: no costmap yet, waiting for the map \(map key"):
        node.answer(GLOBAL, {})            # no map server here: a static layer waits for its map


def test_scans_are_placed_through_the_laser_mount_odometry_and_map_to_odom(tmp_path):
    (tmp_path / "global.yaml").write_text("""
global_costmap:
  global_frame: map
  width: 10.0
  height: 10.0
  robot_radius: 0.1
  plugins:
    - {name: obstacles, type: "costmap_2d::ObstacleLayer"}
  obstacles:
    observation_sources: laser
    laser: {topic: scan, marking: true, clearing: false, obstacle_range: 5.0}
""")
    node = CostmapNode(CostmapNodeParams(global_costmap_files=(str(tmp_path / "global.yaml"),),
                                         local_costmap_files=(), laser_x=0.1, laser_yaw=math.pi / 2))
    scan = LaserScan(header=Header(stamp_ns=ns(0.1), frame_id="laser"), angle_min=-math.pi / 2, angle_max=0.0,
                     angle_increment=math.pi / 2, range_min=0.1, range_max=10.0,
                     ranges=np.array([1.03, np.inf], np.float32))     # one return, to the laser's right
    feed(node, [(KEYS.robot("tf/map_odom"), Transform(header=Header(stamp_ns=ns(0.05), frame_id="map"),
                                                      child_frame_id="odom", transform=Pose2D(2.02, 3.0, math.pi / 2))),
                (KEYS.robot("odom"), odometry(0.1, 1.0, 0.0)),
                (KEYS.robot("scan"), scan), (KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(0.2))))])
    glob = node.answer(GLOBAL, {})
    # laser (0, -1.03) → base: the laser turned left, so straight ahead (1.03, 0), + mount (0.1, 0) →
    # odom: the robot at (1, 0) → (2.13, 0) → map: odom turned left at (2.02, 3) → (2.02, 5.13)
    rows, cols = np.nonzero(glob.data == LETHAL_OBSTACLE)
    assert list(zip(rows, cols)) == [tuple(int(v) for v in world_to_cell(glob.info, 2.02, 5.13))]


def test_a_clear_forgets_obstacles_outside_the_square_around_the_robot_in_both_costmaps(tmp_path):
    layer = """
  robot_radius: 0.1
  update_frequency: 10.0
  plugins:
    - {name: obstacles, type: "costmap_2d::ObstacleLayer"}
  obstacles:
    observation_sources: laser
    laser: {topic: scan, marking: true, clearing: false, obstacle_range: 5.0}
"""
    (tmp_path / "global.yaml").write_text("global_costmap:\n  global_frame: map\n  width: 10.0\n  height: 10.0\n"
                                          "  origin_x: -5.0\n  origin_y: -5.0" + layer)
    (tmp_path / "local.yaml").write_text("local_costmap:\n  global_frame: odom\n  rolling_window: true\n"
                                         "  width: 6.0\n  height: 6.0" + layer)
    node = CostmapNode(CostmapNodeParams(global_costmap_files=(str(tmp_path / "global.yaml"),),
                                         local_costmap_files=(str(tmp_path / "local.yaml"),), request_delay_s=0.3))

    def scan(t, ranges):   # straight ahead and to the left
        return LaserScan(header=Header(stamp_ns=ns(t), frame_id="laser"), angle_min=0.0, angle_max=math.pi / 2,
                         angle_increment=math.pi / 2, range_min=0.1, range_max=10.0,
                         ranges=np.array(ranges, np.float32))

    def lethal(key):
        costmap = node.answer(key, {})
        rows, cols = np.nonzero(costmap.data == LETHAL_OBSTACLE)
        return {(round(float(x), 1), round(float(y), 1)) for x, y in zip(*cell_to_world(costmap.info, rows, cols))}

    messages = [(KEYS.robot("odom"), odometry(t, 0.0, 0.0)) for t in (0.05, 0.15, 0.25)]
    messages += [(KEYS.robot("scan"), scan(0.05, [1.0, 2.5])),            # a hit 1 m ahead, one 2.5 m left
                 (KEYS.robot("scan"), scan(0.15, [1.0, np.inf])),         # then only the near one is seen
                 (KEYS.robot("costmap/clear"), ClearCostmaps(header=Header(stamp_ns=ns(0.25)), reset_distance=3.0))]
    messages += [(KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(t)))) for t in (0.1, 0.2, 0.3, 0.4, 0.5)]
    feed(node, messages)
    seen = {(1.0, 0.0), (0.0, 2.5)}
    assert lethal(GLOBAL) == lethal(LOCAL) == seen
    feed(node, [(KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(0.6))))])   # the first cycle after 0.25 + 0.3 s
    assert lethal(GLOBAL) == lethal(LOCAL) == {(1.0, 0.0)}                     # within ±1.5 m of the robot
    assert node.counters["clears/global"] == node.counters["clears/local"] == 1
    feed(node, [(KEYS.robot("costmap/clear"), ClearCostmaps(header=Header(stamp_ns=ns(0.6)), reset_distance=-1.0))])
    assert node.counters[f"malformed/{KEYS.robot('costmap/clear')}"] == 1


def _room_grid() -> OccupancyGrid:
    data = np.zeros((60, 80), np.int8)
    data[[0, -1], :] = data[:, [0, -1]] = 100
    info = MapMetaData(resolution=0.05, width=80, height=60, origin=Pose2D(-1.0, -1.0, 0.0))
    return OccupancyGrid(header=Header(stamp_ns=ns(0.05), frame_id="map"), info=info, data=data)


def test_ros1_and_ros2_costmap_files_configure_it(tmp_path):
    (tmp_path / "costmap_common_params.yaml").write_text("""
robot_radius: 0.2
footprint_padding: 0.0
inflation_radius: 0.3
cost_scaling_factor: 5.0
observation_sources: scan
scan: {data_type: LaserScan, topic: /scan, marking: true, clearing: true}
""")
    (tmp_path / "global_costmap_params.yaml").write_text("""
global_costmap:
  global_frame: map
  update_frequency: 2.0
  publish_frequency: 0.0
  plugins:
    - {name: static_layer, type: "costmap_2d::StaticLayer"}
    - {name: inflation_layer, type: "costmap_2d::InflationLayer"}
""")
    (tmp_path / "local_costmap_params.yaml").write_text("""
local_costmap:
  global_frame: odom
  rolling_window: true
  width: 4.0
  height: 3.0
  resolution: 0.1
  publish_frequency: 1.0
""")
    common = str(tmp_path / "costmap_common_params.yaml")
    node = build_node("costmap", overrides={
        "global_costmap_files": [common, str(tmp_path / "global_costmap_params.yaml")],
        "local_costmap_files": [common, str(tmp_path / "local_costmap_params.yaml")]})
    out = capture(node)
    feed(node, [(KEYS.robot("map"), _room_grid()),
                (KEYS.robot("odom"), odometry(0.1, 0.5, 0.2)),
                (KEYS.sim("clock"), Clock(header=Header(stamp_ns=ns(0.2))))])
    assert [i.key for i in node.inputs] == [KEYS.sim("clock"), KEYS.robot("odom"), KEYS.robot("scan"),
                                            KEYS.robot("map"), KEYS.robot("tf/map_odom"), KEYS.robot("costmap/clear")]
    glob, local = node.answer(GLOBAL, {}), node.answer(LOCAL, {})
    assert [key for key, _ in out] == [LOCAL]           # publish_frequency 0: the global one only answers
    assert glob.info == _room_grid().info
    d = distance_to(_room_grid().data == 100, 0.05)
    inscribed = make_footprint((), 0.2, 0.0).inscribed_radius
    assert (glob.data[(d > 0) & (d <= inscribed)] == INSCRIBED_INFLATED_OBSTACLE).all()
    assert (glob.data[d > 0.3 + 1e-9] == 0).all() and (glob.data[(d > inscribed) & (d <= 0.3)] > 0).all()
    cell = (glob.data > 0) & (glob.data < INSCRIBED_INFLATED_OBSTACLE)
    assert (glob.data[cell] == [inflation_cost(v, inscribed, 5.0) for v in d[cell]]).all()
    assert local.header.frame_id == "odom"
    assert (local.info.width, local.info.height, local.info.resolution) == (40, 30, 0.1)
    assert (local.info.origin.x, local.info.origin.y) == pytest.approx((0.5 - 2.0, 0.2 - 1.5), abs=0.1)

    # Nav2: one file, both costmaps under `<name>: <name>: ros__parameters:`
    (tmp_path / "nav2_params.yaml").write_text("""
global_costmap:
  global_costmap:
    ros__parameters:
      global_frame: map
      robot_radius: 0.25
      resolution: 0.05
      plugins: ["static_layer", "inflation_layer"]
      static_layer: {plugin: "nav2_costmap_2d::StaticLayer"}
      inflation_layer: {plugin: "nav2_costmap_2d::InflationLayer", inflation_radius: 0.4}
local_costmap:
  local_costmap:
    ros__parameters:
      global_frame: odom
      rolling_window: true
      width: 3
      height: 3
      plugins: ["obstacle_layer"]
      obstacle_layer:
        plugin: "nav2_costmap_2d::ObstacleLayer"
        observation_sources: scan
        scan: {topic: /scan, data_type: LaserScan, obstacle_max_range: 2.0, raytrace_max_range: 2.5}
""")
    nav2 = str(tmp_path / "nav2_params.yaml")
    node = build_node("costmap", overrides={"global_costmap_files": [nav2], "local_costmap_files": [nav2]})
    glob_params, local_params = (node.costmaps[n].core.params for n in ("global", "local"))
    assert glob_params.robot_radius == 0.25 and glob_params.layers[1].inflation_radius == 0.4
    assert local_params.rolling_window and local_params.layers[0].observation_sources[0].obstacle_range == 2.0


def test_without_a_clock_a_map_is_costed_and_published_when_it_comes():
    node = CostmapNode(CostmapNodeParams(**SAMPLE_FILES))
    out = capture(node)
    with pytest.raises(QueryError, match="waiting for the map"):
        node.answer(GLOBAL, {})
    feed(node, [(KEYS.robot("map"), _room_grid())])
    assert [(key, msg.header.stamp_ns) for key, msg in out] == [(GLOBAL, ns(0.05))]
    assert (out[0][1].data[0, :] == LETHAL_OBSTACLE).all()
    with pytest.raises(QueryError, match=r"costmap/local: no costmap yet, waiting for odometry"):
        node.answer(LOCAL, {})
    republished = _room_grid()
    republished.header.stamp_ns = ns(1.05)
    upside_down = Transform(header=Header(stamp_ns=ns(1.1), frame_id="odom"), child_frame_id="map")
    feed(node, [(KEYS.robot("map"), republished), (KEYS.robot("tf/map_odom"), upside_down)])
    assert len(out) == 1 and node.counters["maps_unchanged"] == 1
    assert node.counters[f"malformed/{KEYS.robot('tf/map_odom')}"] == 1


def test_bad_configurations_are_refused_naming_what_is_wrong(tmp_path):
    missing = tmp_path / "nowhere.yaml"
    with pytest.raises(ParamError, match=f"{missing}: no such file"):
        build_node("costmap", overrides={"global_costmap_files": [str(missing)]})
    typo = tmp_path / "typo.yaml"
    typo.write_text("global_costmap:\n  inflation_raduis: 0.5\n")
    with pytest.raises(ParamError, match=r"typo.yaml: global_costmap: unknown parameter 'inflation_raduis' \(did you mean 'inflation_radius'\?\)"):
        build_node("costmap", overrides={"global_costmap_files": [str(typo)]})
    frame = tmp_path / "frame.yaml"
    frame.write_text("local_costmap:\n  global_frame: base_link\n")
    with pytest.raises(ValueError, match="local_costmap: global_frame: frame 'base_link' is neither the map frame"):
        build_node("costmap", overrides={"local_costmap_files": [str(frame)]})
    topic = tmp_path / "topic.yaml"
    topic.write_text("observation_sources: front\nfront: {topic: base_scan}\n")
    with pytest.raises(ValueError, match="observation source topic 'base_scan': unknown robot topic"):
        build_node("costmap", overrides={"global_costmap_files": [str(topic)]})
    with pytest.raises(ValueError, match=f"parameter 'map_file': {missing}: no such file"):
        build_node("costmap", overrides={**{k: list(v) for k, v in SAMPLE_FILES.items()}, "map_file": str(missing)})


# ---------------------------------------------------------------- live, recorded, replayed

ROOM_START = ["--set", "initial_pose_x=1.2", "--set", "initial_pose_y=1.0"]
PLANNER = ["--set", "planner_frequency=2.0", "--set", "use_dijkstra=false", *ROOM_START]


def _send_goal(session, x: float, y: float) -> None:
    """What a navigator does: a Goal stamped with the sim's time (read from the sim's truth)."""
    truth = next(iter(session.get(KEYS.sim_robot("truth"), timeout=5.0)))
    stamp = decode(truth.ok.payload.to_bytes()).header.stamp_ns
    goal = Goal(header=Header(stamp_ns=stamp, frame_id="map", seq=1), goal_id="g1", pose=Pose2D(x, y, 0.0))
    session.put(KEYS.robot("goal"), encode(goal), attachment=pack_attachment(1, stamp, "Goal"),
                congestion_control=zenoh.CongestionControl.BLOCK)


def _plan_published(session) -> bool:
    return any(r.ok is not None and len(decode(r.ok.payload.to_bytes(), Path).poses) > 0
               for r in session.get(KEYS.robot("plan"), timeout=2.0))


def test_a_live_run_replays_byte_for_byte_into_the_costmap_and_the_planner(processes, router_endpoint, tmp_path):
    recording = tmp_path / "nav.mcap"
    recorder = processes.omninav("record", "-o", str(recording))
    wait_until(lambda: "recording" in processes.log_of(recorder), 60, what="the recorder to start")
    # in lockstep at real time (services/runtime/lockstep.py): the goal this test puts comes at a
    # wall-clock moment, but no service falls behind the sim however loaded the machine is
    processes.in_lockstep("chassis", "lidar", "cmd_vel_mux", "velocity_smoother", "collision_monitor",
                          "map_server", "costmap", "global_planner")
    services = [processes.omninav("run", "sim"), processes.omninav("run", "chassis"),
                processes.omninav("run", "lidar"), *command_chain(processes),
                processes.omninav("run", "map_server", "--set", "yaml_filename=compose/maps/room.yaml",
                                  "--set", "publish_period_s=1.0"),
                processes.omninav("run", "costmap", *ROOM_START),
                processes.omninav("run", "global_planner", *PLANNER)]
    with open_client(router_endpoint) as session:
        wait_until(lambda: any(r.ok is not None for r in session.get(f"{KEYS.robot('plan')}?start=1.2,1.0;goal=8,7",
                                                                      timeout=2.0)),
                   timeout=90, what="the planner to plan on the costmap of the map")
        _send_goal(session, 8.0, 7.0)
        proc = processes.omninav("teleop", "--script", "0.3,0,0,2;0,0,0.5,1")     # the local window rolls
        assert proc.wait(90) == 0, processes.log_of(proc)
        wait_until(lambda: _plan_published(session), timeout=30, what="a plan for the goal")
    for proc in reversed(services):      # their last outputs and diagnostics get recorded
        assert processes.stop(proc, signal.SIGINT) == 0, processes.log_of(proc)
    assert processes.stop(recorder, signal.SIGINT) == 0, processes.log_of(recorder)

    published = {rec.key for rec in read_records(recording, [GLOBAL, LOCAL, KEYS.robot("plan")])}
    assert published == {GLOBAL, LOCAL, KEYS.robot("plan")}
    for service, extra in (("costmap", ROOM_START), ("global_planner", PLANNER)):
        proc = processes.omninav("replay", str(recording), "--into", service, "--compare", *extra)
        assert proc.wait(120) == 0, processes.log_of(proc)
        assert "replay reproduces the recorded outputs byte for byte" in processes.log_of(proc)


def test_the_default_parameter_files_are_found_from_any_folder_and_a_missing_one_is_named(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)     # no compose/params here: the checkout's samples are read
    node = build_node("costmap")
    assert node.params.global_costmap_files[0] == "compose/params/costmap_common_params.yaml"   # recorded as given
    assert (node.costmaps["global"].frame, node.costmaps["local"].frame) == ("map", "odom")
    (tmp_path / "compose" / "params").mkdir(parents=True)
    (tmp_path / "compose" / "params" / "costmap_common_params.yaml").write_text("robot_radius: 0.1\n")
    with pytest.raises(ParamError, match="costmap_global_params.yaml: no such file"):
        build_node("costmap", overrides={"global_costmap_files": ["compose/params/costmap_common_params.yaml",
                                                                  "costmap_global_params.yaml"]})
