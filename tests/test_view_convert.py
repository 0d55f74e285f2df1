"""services/view/convert.py: each omninav message kind → a decodable Foxglove message with its fields."""
import json
import math

import numpy as np
import pytest

from omninav.schemas import messages as m
from omninav.schemas.keys import KeyLayout
from omninav.services.view import convert
from omninav.services.view.convert import Converter, RouteTable, ViewParams

from view_fixtures import S, decode_foxglove



def header(frame: str, stamp_s: float = 2.5) -> m.Header:
    return m.Header(stamp_ns=round(stamp_s * S), frame_id=frame, seq=7)


def yaw_of(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def occupancy(stamp_s: float = 2.5, cell: int = 100) -> m.OccupancyGrid:
    data = np.full((2, 3), -1, np.int8)
    data[1, 2] = cell
    return m.OccupancyGrid(header(("map"), stamp_s), m.MapMetaData(0.05, 3, 2, m.Pose2D(-1.0, 2.0, 0.0)), data)


def test_occupancy_grid_keeps_cells_in_row_major_order_with_origin_and_resolution():
    grid = decode_foxglove(convert.occupancy_grid(occupancy()))
    assert (grid.timestamp.seconds, grid.timestamp.nanos) == (2, 500_000_000)
    assert grid.frame_id == "map" and grid.column_count == 3
    assert (grid.cell_size.x, grid.cell_size.y) == (0.05, 0.05)
    assert (grid.pose.position.x, grid.pose.position.y) == (-1.0, 2.0)
    assert (grid.row_stride, grid.cell_stride) == (3, 1)
    assert [f.name for f in grid.fields] == ["occupancy"]
    cells = np.frombuffer(grid.data, np.int8).reshape(2, 3)
    assert cells[1, 2] == 100 and (cells.ravel()[:5] == -1).all()


def test_costmap_grid_keeps_raw_costs():
    data = np.array([[0, 253], [254, 255]], np.uint8)
    grid = decode_foxglove(convert.costmap_grid(m.Costmap(header("odom"), m.MapMetaData(0.1, 2, 2), data)))
    assert grid.frame_id == "odom" and [f.name for f in grid.fields] == ["cost"]
    assert list(grid.data) == [0, 253, 254, 255]


def test_laser_scan_spans_the_beams_and_keeps_no_return_as_infinity():
    ranges = np.array([1.0, np.inf, 2.5, np.nan], np.float32)
    msg = m.LaserScan(header("laser"), angle_min=-0.3, angle_max=0.3, angle_increment=0.2, range_max=10.0,
                      ranges=ranges)
    scan = decode_foxglove(convert.laser_scan(msg))
    assert scan.frame_id == "laser"
    assert scan.start_angle == pytest.approx(-0.3) and scan.end_angle == pytest.approx(0.3)
    assert scan.ranges[0] == 1.0 and math.isinf(scan.ranges[1]) and math.isnan(scan.ranges[3])
    mount = decode_foxglove(convert.laser_mount(msg, ViewParams(laser_mount=(0.2, 0.0, math.pi))))
    (tf,) = mount.transforms
    assert (tf.parent_frame_id, tf.child_frame_id, tf.translation.x) == ("base_link", "laser", 0.2)
    assert abs(yaw_of(tf.rotation)) == pytest.approx(math.pi)


def test_transforms_make_the_tree_map_odom_base_link():
    map_odom = decode_foxglove(convert.transform(m.Transform(header("map"), "odom", m.Pose2D(1.0, -2.0, 0.5))))
    odom = m.Odometry(header("odom"), "base_link", m.Pose2D(3.0, 4.0, -1.0))
    odom_base = decode_foxglove(convert.odometry_transform(odom))
    (a,), (b,) = map_odom.transforms, odom_base.transforms
    assert (a.parent_frame_id, a.child_frame_id, a.translation.x, a.translation.y) == ("map", "odom", 1.0, -2.0)
    assert yaw_of(a.rotation) == pytest.approx(0.5)
    assert (b.parent_frame_id, b.child_frame_id, b.translation.y) == ("odom", "base_link", 4.0)
    assert yaw_of(b.rotation) == pytest.approx(-1.0)


def test_truth_draws_the_footprint_at_the_true_pose_and_roots_the_map_in_the_world():
    truth = m.Odometry(header("world"), "base_link", m.Pose2D(2.0, 1.0, math.pi / 2))
    scene = decode_foxglove(convert.truth_robot(truth, ViewParams(footprint=((0.5, 0.2), (-0.5, 0.2), (-0.5, -0.2)))))
    (entity,) = scene.entities
    assert entity.frame_id == "world" and entity.id == "truth"
    outline = entity.lines[0]
    # (0.5, 0.2) in the robot turned a quarter: (-0.2, 0.5) from (2, 1)
    assert (outline.points[0].x, outline.points[0].y) == pytest.approx((1.8, 1.5))
    assert len(outline.points) == 3
    (root,) = decode_foxglove(convert.world_is_map(truth)).transforms
    assert (root.parent_frame_id, root.child_frame_id, root.translation.x) == ("world", "map", 0.0)


def test_pose_particles_plans_and_goals_become_poses_in_their_frame():
    pose = decode_foxglove(convert.pose_in_frame(m.PoseWithCovariance(header("map"), m.Pose2D(1.0, 2.0, 0.3))))
    assert (pose.frame_id, pose.pose.position.x, pose.pose.position.y) == ("map", 1.0, 2.0)
    assert yaw_of(pose.pose.orientation) == pytest.approx(0.3)
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 1.0], [2.0, 1.0, -1.0]])
    cloud = decode_foxglove(convert.particle_cloud(m.ParticleCloud(header("map"), poses, np.full(3, 1 / 3))))
    assert [p.position.x for p in cloud.poses] == [0.0, 1.0, 2.0]
    local = decode_foxglove(convert.path(m.Path(header("odom"), poses[:2], goal_id="g")))
    assert local.frame_id == "odom" and yaw_of(local.poses[1].orientation) == pytest.approx(1.0)
    goal = decode_foxglove(convert.goal(m.Goal(header("map"), "g", m.Pose2D(5.0, 6.0, 0.0), waypoints=poses[1:2])))
    assert [(p.position.x, p.position.y) for p in goal.poses] == [(1.0, 0.5), (5.0, 6.0)]


def test_movers_are_cylinders_of_their_radius():
    circles = np.array([[1.0, 2.0, 0.3], [4.0, -1.0, 0.5]])
    scene = decode_foxglove(convert.movers(m.Obstacles(header("world"), circles, np.zeros((2, 2)))))
    (entity,) = scene.entities
    assert [(c.pose.position.x, c.size.x) for c in entity.cylinders] == [(1.0, 0.6), (4.0, 1.0)]


def test_tracks_are_cylinders_of_their_radius_with_an_arrow_along_their_velocity():
    states = np.array([[1.0, 2.0, 0.0, -0.5], [4.0, -1.0, 0.0, 0.0]])
    msg = m.Tracks(header("odom"), np.array([3, 9]), states, np.tile(np.eye(4), (2, 1, 1)), np.array([0.3, 0.2]))
    (entity,) = decode_foxglove(convert.tracks(msg)).entities
    assert entity.frame_id == "odom" and entity.id == "tracks"
    assert [(c.pose.position.x, c.pose.position.y, c.size.x) for c in entity.cylinders] == [(1.0, 2.0, 0.6),
                                                                                           (4.0, -1.0, 0.4)]
    (arrow,) = entity.arrows            # a standing track has no arrow
    assert (arrow.pose.position.x, arrow.pose.position.y) == (1.0, 2.0)
    assert yaw_of(arrow.pose.orientation) == pytest.approx(-math.pi / 2)
    assert arrow.shaft_length == pytest.approx(0.5 * convert.ARROW_SECONDS)
    empty = decode_foxglove(convert.tracks(m.Tracks(header("odom"))))
    assert list(empty.entities[0].cylinders) == []       # every track lost: the old ones are cleared


def test_diagnostic_is_json_with_its_values():
    diag = m.Diagnostic(header("", 3.0), "costmap", 1, "late", {"received/x": 4, "params": "{}"})
    message = convert.diagnostic(diag)
    assert message.schema_name == "omninav.Diagnostic" and "values" in message.schema["properties"]
    assert json.loads(json.dumps(message.value)) == {
        "timestamp": {"sec": 3, "nsec": 0}, "name": "costmap", "level": 1, "message": "late",
        "values": {"received/x": 4, "params": "{}"}}


def test_a_stamp_foxglove_cannot_hold_is_clamped_not_refused():
    assert decode_foxglove(convert.pose_in_frame(m.PoseWithCovariance(m.Header(stamp_ns=-5)))).timestamp.seconds == 0


def test_grids_pass_only_when_changed_and_at_most_once_per_period():
    table = RouteTable(KeyLayout("r1"))
    route = table.route_for("omninav/r1/map")
    converter = Converter(grid_period_s=1.0)
    sent = [bool(converter.outputs(route, grid)) for grid in
            (occupancy(0.0), occupancy(0.5, cell=50), occupancy(2.0, cell=50), occupancy(3.5, cell=50),
             occupancy(4.0, cell=0))]
    assert sent == [True, False, True, False, True]


def test_every_route_has_a_key_and_every_diagnostics_key_finds_its_route():
    table = RouteTable(KeyLayout("r2"))
    for route in convert.ROUTES:
        assert table.key_expr(route).startswith("omninav/")
    assert table.route_for("omninav/r2/diagnostics/costmap").source == convert.DIAGNOSTICS
    assert table.route_for("omninav/r1/diagnostics/costmap") is None     # another robot
    assert table.route_for("omninav/sim/r2/truth").source == "sim/truth"
    assert table.route_for("omninav/r2/cmd_vel") is None


def test_a_goal_pose_from_the_foxglove_app_becomes_a_navigator_goal():
    stamped = {"header": {"stamp": {"sec": 1, "nsec": 0}, "frame_id": "map"},
               "pose": {"position": {"x": 1.5, "y": -2.0, "z": 0.0},
                        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(0.4), "w": math.cos(0.4)}}}
    goal = convert.goal_from_client(json.dumps(stamped).encode(), 7 * S, "foxglove-1")
    assert (goal.goal_id, goal.header.stamp_ns, goal.header.frame_id) == ("foxglove-1", 7 * S, "map")
    assert (goal.pose.x, goal.pose.y, goal.pose.theta) == pytest.approx((1.5, -2.0, 0.8))
    in_frame = {"frame_id": "", "pose": stamped["pose"]}
    assert convert.goal_from_client(json.dumps(in_frame).encode(), 0, "g").pose.x == 1.5


@pytest.mark.parametrize("payload, reason", [
    (b"{", "not JSON"),
    (b'{"pose": {"position": {"x": 1}}}', "missing or wrong"),
    (json.dumps({"frame_id": "odom", "pose": {"position": {"x": 1, "y": 2}, "orientation": {}}}).encode(), "odom"),
    (b'{"pose": {"position": {"x": NaN, "y": 0}, "orientation": {}}}', "finite"),
])
def test_a_bad_goal_from_a_client_is_refused_naming_why(payload, reason):
    with pytest.raises(ValueError, match=reason):
        convert.goal_from_client(payload, 0, "g")
