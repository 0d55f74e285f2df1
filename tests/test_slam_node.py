"""The slam node in a whole in-process pipeline (sim, chassis, lidar, slam, a route driver) against
the room's ground truth; malformed input; determinism; `omninav map --world`; and a live
multi-process run replayed into slam byte for byte."""
import math
import signal

import numpy as np
import pytest
import yaml

from omninav.cli.main import main as omninav
from omninav.schemas import decode
from omninav.schemas.messages import Header, LaserScan, OccupancyGrid, Odometry, Pose2D, PoseWithCovariance, Transform
from omninav.services.chassis.node import ChassisNode, ChassisNodeParams
from omninav.services.lidar.node import LidarNode, LidarNodeParams
from omninav.experiments.localize_eval import HarnessParams, Route
from omninav.services.map_server.mapio import load_map
from omninav.geometry.grid import world_to_cell
from omninav.services.recorder.mcap_io import read_records
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.geometry.se2 import compose
from omninav.experiments.mapping import RouteDriver, compare_with_truth, slam_params_for
from omninav.services.slam.node import SlamNode
from omninav.sim.node import SimNode, SimNodeParams, open_world
from launching import command_chain
from conftest import wait_until

ROUTE = ((1.3, 0.8), (4.5, 0.8))     # along the bottom wall and back
SHORT_ROUTE = "1.3,0.8;4.5,0.8"


def run_room(seed: int = 0, overrides: dict | None = None):
    """Drive the short route once; returns the slam node, the world and per-scan (estimate, truth)."""
    sim = SimNode(SimNodeParams(world="room", seed=seed))
    slam = SlamNode(slam_params_for(sim.world, overrides or {"particles": 10}, seed))
    driver = RouteDriver(HarnessParams(route=Route(ROUTE)))
    runner = InProcessRunner([sim, ChassisNode(ChassisNodeParams(drive=sim.sim.drive)),
                              LidarNode(LidarNodeParams(world="room", seed=seed + 1)), slam, driver])
    truth, pairs, tfs, maps = {}, [], [], []
    truth_key, pose_key = slam.keys.resolve("sim/truth"), slam.keys.resolve("pose")

    def tap(key, payload, stamp_ns):
        if key == truth_key:
            p = decode(payload, Odometry).pose
            truth[stamp_ns] = (p.x, p.y, p.theta)
        elif key == pose_key:
            p = decode(payload, PoseWithCovariance).pose
            pairs.append(((p.x, p.y, p.theta), truth[stamp_ns]))
        elif key == slam.keys.resolve("tf/map_odom"):
            tfs.append(decode(payload, Transform))
        elif key == slam.keys.resolve("map"):
            maps.append(decode(payload, OccupancyGrid))

    runner.tap(tap)
    runner.run_until(lambda: driver.laps >= 1, 4000)
    runner.close()
    return slam, sim.world, pairs, tfs, maps


@pytest.fixture(scope="module")
def room_run():
    return run_room()


def test_map_matches_the_room(room_run):
    slam, world, _, _, maps = room_run
    assert slam.counters["filter_updates"] > 5
    assert maps, "no map published on the timer"
    grid = slam.answer(slam.keys.resolve("map"), {})
    assert grid.header.frame_id == "map"
    c = compare_with_truth(grid, world)
    assert c.known_both > 5000 and c.occupied > 200
    assert c.agreement > 0.95
    assert c.within_one_cell > 0.95
    assert c.wall_mean_cells < 1.0


def test_pose_follows_the_truth(room_run):
    slam, _, pairs, tfs, _ = room_run
    assert len(pairs) > 50
    errors = [math.hypot(e[0] - t[0], e[1] - t[1]) for e, t in pairs]
    headings = [abs(math.remainder(e[2] - t[2], math.tau)) for e, t in pairs]
    assert max(errors) < 0.10 and max(headings) < 0.05
    # the map frame is the world frame: the first scan is at the world's start (the robot has moved
    # by at most one sim step's creep when the lidar's first scan comes)
    assert errors[0] < 0.01
    assert len(tfs) == len(pairs) and all(t.child_frame_id == "odom" and t.header.frame_id == "map" for t in tfs)
    assert slam.answer(slam.keys.resolve("pose"), {}) is slam.last_pose


HECTOR = {"method": "hector", "map_resolution": 0.05, "map_size": 512}


@pytest.mark.parametrize("odometry", [False, True], ids=["no-odometry", "odometry-guess"])
def test_hector_maps_the_room(odometry):
    """method: hector with no odometry at all (slam does not subscribe to it, publishes no map →
    odom), or with it as the first guess: the pose follows the truth (measured: within 3.7 cm and
    0.7°) and the walls land where the room's are."""
    slam, world, pairs, tfs, maps = run_room(overrides={**HECTOR, "use_tf_pose_start_estimate": odometry})
    subscribed = {inp.key for inp in slam.inputs}
    assert (slam.keys.resolve("odom") in subscribed) == odometry
    assert len(pairs) > 50 and len(tfs) == (len(pairs) if odometry else 0) and maps
    errors = [math.hypot(e[0] - t[0], e[1] - t[1]) for e, t in pairs]
    headings = [abs(math.remainder(e[2] - t[2], math.tau)) for e, t in pairs]
    assert max(errors) < 0.10 and max(headings) < 0.05
    c = compare_with_truth(slam.answer(slam.keys.resolve("map"), {}), world)
    assert c.occupied > 200 and c.agreement > 0.95 and c.within_one_cell > 0.95


def test_deterministic(room_run):
    slam, _, pairs, _, _ = room_run
    again, _, pairs2, _, _ = run_room()
    assert pairs2 == pairs
    np.testing.assert_array_equal(again.current_map().data, slam.current_map().data)


def scan(stamp_ns, n=90, angle_increment=2 * math.pi / 90):
    return LaserScan(header=Header(stamp_ns=stamp_ns), angle_min=-math.pi, angle_increment=angle_increment,
                     range_min=0.1, range_max=10.0, ranges=np.full(n, 3.0, np.float32))


def odom(stamp_ns, x=0.0):
    return Odometry(header=Header(stamp_ns=stamp_ns), pose=Pose2D(x, 0.0, 0.0))


def feed(node, topic, msg):
    index = next(i for i, inp in enumerate(node.inputs) if inp.key == node.keys.resolve(topic))
    node.process(index, msg)


def test_malformed_input_is_counted():
    node = SlamNode(slam_params_for(SimNode(SimNodeParams(world="room")).world, {"particles": 2}))
    feed(node, "odom", odom(0))
    feed(node, "scan", scan(0))
    feed(node, "scan", scan(1, angle_increment=0.0))           # no usable geometry
    feed(node, "scan", scan(2, n=45))                          # another beam count than the laser's
    feed(node, "odom", odom(-5))                               # odometry back in time
    assert node.counters[f"malformed/{node.keys.resolve('scan')}"] == 2
    assert node.counters[f"malformed/{node.keys.resolve('odom')}"] == 1
    assert node.counters["scans"] == 1


def test_scan_waits_for_odometry_and_is_interpolated():
    node = SlamNode(slam_params_for(SimNode(SimNodeParams(world="room")).world, {"particles": 1}))
    feed(node, "odom", odom(0, x=0.0))
    feed(node, "scan", scan(0))
    feed(node, "scan", scan(10))           # between two odometry messages: waits for the next
    assert node.counters["scans"] == 1
    feed(node, "odom", odom(20, x=0.2))
    assert node.counters["scans"] == 2
    # 0.1 m driven by the scan's stamp (below linearUpdate: moved by odometry only)
    start = np.array([node.params.initial_pose_x, node.params.initial_pose_y, node.params.initial_pose_a])
    pose = node.last_pose.pose
    np.testing.assert_allclose((pose.x, pose.y, pose.theta), compose(start, (0.1, 0.0, 0.0)), atol=1e-9)


def test_map_world_writes_and_scores_the_map(tmp_path, capsys):
    out = tmp_path / "room"
    assert omninav(["map", "--world", "sim/worlds/room.yaml", "-o", str(out),
                    "--waypoints", SHORT_ROUTE, "--set", "particles=10", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("drove the route in ")     # --quiet: no progress lines before the summary
    assert (tmp_path / "room.yaml").is_file() and (tmp_path / "room.pgm").is_file()
    assert yaml.safe_load((tmp_path / "room.yaml").read_text())["resolution"] == pytest.approx(0.05)
    agreement = float(text.split("agreement ")[1].split(" %")[0])
    assert agreement > 90.0
    assert load_map(tmp_path / "room.yaml").data.shape[0] > 50
    # existing files are kept unless --force
    assert omninav(["map", "--world", "room", "-o", str(out), "--waypoints", SHORT_ROUTE]) == 2
    assert "already exist" in capsys.readouterr().err
    # the actions keep their own arguments: -o after `save` is save's, the map file is show's
    assert omninav(["map", "show", str(tmp_path / "room.yaml"), "-o", str(tmp_path / "room.png")]) == 0
    assert (tmp_path / "room.png").is_file()


def test_map_world_user_errors(tmp_path, capsys):
    for args, words in ((["--world", "nowhere"], "no such file"), (["--world", "room", "--waypoints", "1,2"], "waypoints"),
                        (["--world", "room", "--set", "particles=0"], "particles"),
                        (["--world", "corridor", "--route"], "no mapping route")):
        assert omninav(["map", "-o", str(tmp_path / "m"), *args]) == 2
        assert words in capsys.readouterr().err
    assert omninav(["map", "--world", "room"]) == 2
    assert "-o PATH" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
    with pytest.raises(SystemExit):     # the old spelling is gone: `build` is no action
        omninav(["map", "build", "--world", "room", "-o", str(tmp_path / "m")])
    assert "invalid choice: 'build'" in capsys.readouterr().err


# ---------------------------------------------------------------- live, then replayed byte for byte

LIVE_SLAM = ["--set", "particles=10", "--set", "linearUpdate=0.2", "--set", "angularUpdate=0.2",
             "--set", "map_update_interval=1.0", "--set", "xmin=-15", "--set", "ymin=-15", "--set", "xmax=15",
             "--set", "ymax=15"]


def test_a_live_run_replays_into_slam_byte_for_byte(processes, tmp_path):
    recording = tmp_path / "run.mcap"
    recorder = processes.omninav("record", "-o", str(recording))
    wait_until(lambda: "recording" in processes.log_of(recorder), 60, what="the recorder to start")
    # in lockstep (services/runtime/lockstep.py), slam and teleop included: exactly replayable at any load
    processes.in_lockstep("slam", "chassis", "lidar", "cmd_vel_mux", "velocity_smoother", "collision_monitor",
                          "teleop")
    services = [processes.omninav("run", "sim", "--set", "rate=0"), processes.omninav("run", "chassis"),
                processes.omninav("run", "lidar"), *command_chain(processes)]
    for proc in services:
        wait_until(lambda: "started" in processes.log_of(proc), 60, what="the sim, chassis and lidar to start")
    slam = processes.omninav("run", "slam", *LIVE_SLAM)
    wait_until(lambda: "started" in processes.log_of(slam), 60, what="slam to start")
    teleop = processes.omninav("teleop", "--script", "0.3,0,0,3;0,0,0.5,2;0,-0.15,0,2")
    assert teleop.wait(180) == 0, processes.log_of(teleop)
    for proc in [slam, *reversed(services)]:    # slam's last diagnostic gets recorded
        assert processes.stop(proc, signal.SIGINT) == 0, processes.log_of(proc)
    assert processes.stop(recorder, signal.SIGINT) == 0, processes.log_of(recorder)

    maps = list(read_records(recording, ["omninav/r1/map"]))
    assert len(maps) >= 3 and len(list(read_records(recording, ["omninav/r1/pose"]))) >= 20
    replay = processes.omninav("replay", str(recording), "--into", "slam", "--compare", *LIVE_SLAM)
    assert replay.wait(180) == 0, processes.log_of(replay)
    log = processes.log_of(replay)
    assert "omninav/r1/map" in log and "omninav/r1/tf/map_odom" in log


def test_the_comparison_counts_the_movers_lanes_apart():
    world = open_world("warehouse")
    truth = world.rasterize(0.05)
    data = truth.data.copy()
    exact = compare_with_truth(OccupancyGrid(header=Header(frame_id="map"), info=truth.info, data=data.copy()), world)
    assert exact.agreement == 1.0 and exact.within_one_cell == 1.0 and exact.occupied_in_lanes == 0
    for x, y in ((8.0, 1.5), (1.0, 4.0)):      # on the forklift's lane; in free space off every lane
        r, c = (int(v) for v in world_to_cell(truth.info, x, y))
        data[r - 2:r + 3, c - 2:c + 3] = 100
    result = compare_with_truth(OccupancyGrid(header=Header(frame_id="map"), info=truth.info, data=data), world)
    assert result.occupied_in_lanes == 25
    assert result.occupied == exact.occupied + 25 and result.wall_max_cells > 10
    assert result.known_both == exact.known_both and result.agreement == pytest.approx(1.0 - 25 / exact.known_both)
