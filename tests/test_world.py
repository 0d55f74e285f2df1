"""World files: the shipped worlds, validation errors, geometry queries, movers, rasterizing."""
import math
import re

import numpy as np
import pytest
import yaml
from scipy import ndimage

from conftest import SHARED_DATA
from omninav.schemas.messages import MapMetaData, OccupancyGrid, Pose2D
from omninav.services.map_server.mapio import save_map
from omninav.geometry.grid import world_to_cell
from omninav.sim.world import DATA_ENV, WorldError, load_world, shipped_worlds, world_path
from omninav.geometry.polygons import point_segment_distance
from omninav.geometry.footprint import DEFAULT_FOOTPRINT

HAVE_WILLOW = (SHARED_DATA / "maps" / "willow-full-0.05.yaml").exists()


def shipped(name):
    if name == "willow" and not HAVE_WILLOW:
        pytest.skip("shared data not present")
    return load_world(world_path(name))


def write_world(tmp_path, doc, name="w.yaml"):
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))
    return path


def box_world(tmp_path, **extra):
    return load_world(write_world(tmp_path, {"bounds": [10.0, 8.0], "robot": {"start": [5.0, 4.0, 0.0]}, **extra}))


# ---------------------------------------------------------------- shipped worlds

def test_the_expected_worlds_ship():
    assert {"room", "corridor", "office", "warehouse", "willow", "paper"} <= set(shipped_worlds())


@pytest.mark.parametrize("name", shipped_worlds())
def test_shipped_world_loads_and_starts_collision_free(name):
    world = shipped(name)
    assert world.name == name and world.robot.drive in ("mecanum", "omni3", "diff")
    assert world.footprint_clearance(world.robot.start) > 0.1
    movers_now = world.movers.circles_at(0.0)
    assert world.footprint_clearance(world.robot.start, extra_circles=movers_now) > 0.1
    for goal in world.goals:
        assert world.footprint_clearance(goal) > 0.1


@pytest.mark.parametrize("name", shipped_worlds())
def test_shipped_world_free_space_is_connected(name):
    """Cells where a disk of the footprint's inscribed radius fits form one region holding the
    start and every goal, so the whole world can be driven (sideways through narrow gaps)."""
    world = shipped(name)
    grid = world.rasterize(0.1)
    clear = ndimage.distance_transform_edt(grid.data != 100) * 0.1 - 0.05
    footprint = world.robot.footprint
    inscribed = point_segment_distance(np.zeros(2), footprint, np.roll(footprint, -1, axis=0)).min()
    drivable = (grid.data == 0) & (clear > inscribed)
    labels, _ = ndimage.label(drivable)
    region = labels[world_to_cell(grid.info, *world.robot.start[:2])]
    assert region > 0
    share = (labels == region).sum() / drivable.sum()
    assert share > (0.95 if world.grid is not None else 0.999), f"{name}: only {share:.1%} reachable"
    for goal in world.goals:
        assert labels[world_to_cell(grid.info, *goal[:2])] == region


@pytest.mark.parametrize("name", shipped_worlds())
def test_movers_never_cross_static_obstacles(name):
    world = shipped(name)
    for t in np.linspace(0.0, 120.0, 601):
        for (x, y, r) in world.movers.circles_at(t):
            assert world.distance([x, y]) > r, f"{name}: a mover hits something at t={t}"


def test_paper_world_has_the_experiment_in_world_coordinates():
    world = shipped("paper")
    np.testing.assert_array_equal(world.robot.start, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(world.goals, [[4.0, -3.0, math.pi / 2]])
    assert world.extent == (-3.0, -5.0, 7.0, 3.0)


@pytest.mark.skipif(not HAVE_WILLOW, reason="shared data not present")
def test_willow_takes_its_extent_from_the_map():
    world = shipped("willow")
    assert world.grid.info.width == 1165 and world.grid.info.height == 945
    assert world.extent == pytest.approx((0.0, 0.0, 1165 * 0.05, 945 * 0.05))


# ---------------------------------------------------------------- errors

GOOD = {"name": "t", "bounds": [10.0, 8.0], "robot": {"start": [1.0, 1.0, 0.0]}}


@pytest.mark.parametrize("change, message", [
    ({"bounds": None}, r"bounds: missing"),
    ({"bounds": "ten by eight"}, r"bounds: expected \[width, height\]"),
    ({"bounds": [10.0, -8.0]}, r"bounds: expected \[width, height\]"),
    ({"origin": [1.0]}, r"origin: expected \[x, y\]"),
    ({"name": 7}, r"name: expected a non-empty string"),
    ({"walls": [[0, 0, 1, 1], [0, 0, 1]]}, r"walls\[1\]: expected \[x1, y1, x2, y2\]"),
    ({"walls": [[2, 2, 2, 2]]}, r"walls\[0\]: has zero length"),
    ({"walls": {"a": 1}}, r"walls: expected a list"),
    ({"boxes": [{"center": [1, 1], "size": [1, 1]}, {"center": [1, 1], "size": [1, 1]},
                {"center": [1, 1], "size": [1, -2]}]}, r"boxes\[2\]\.size: expected two positive numbers"),
    ({"boxes": [{"size": [1, 1]}]}, r"boxes\[0\]\.center: missing"),
    ({"boxes": [{"center": [1, 1], "size": [1, 1], "yaw": "north"}]}, r"boxes\[0\]\.yaw: expected a number"),
    ({"boxes": ["crate"]}, r"boxes\[0\]: expected a mapping"),
    ({"circles": [{"center": [1, 1], "radius": "big"}]}, r"circles\[0\]\.radius: expected a number"),
    ({"circles": [{"center": [1, 1], "radius": 0}]}, r"circles\[0\]\.radius: expected a positive number"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1]]}]}, r"movers\[0\]\.path: expected at least 2 points"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], [1, 1]]}]}, r"movers\[0\]\.path: all points are the same"),
    ({"movers": [{"radius": 0.3, "speed": -1, "path": [[1, 1], [2, 1]]}]}, r"movers\[0\]\.speed: expected a number ≥ 0"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], [2, 1]], "loop": "yes"}]}, r"movers\[0\]\.loop"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], ["a", 1]]}]}, r"movers\[0\]\.path\[1\]: expected a point"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], [2, 1]], "yield_distance": 0}]},
     r"movers\[0\]\.yield_distance: expected a positive number, got 0"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], [2, 1]], "yield_distance": -1.5}]},
     r"movers\[0\]\.yield_distance: expected a positive number"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], [2, 1]], "yield_distance": "near"}]},
     r"movers\[0\]\.yield_distance: expected a number, got 'near'"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1]]}]}, r"movers\[0\]\.keyframes: expected at least 2 keyframes"),
    ({"movers": [{"radius": 0.3, "keyframes": "soon"}]}, r"movers\[0\]\.keyframes: expected a list"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [2, 1, 2], [2, 2, 2]]}]},
     r"movers\[0\]\.keyframes\[2\]: time 2 does not come after 2 \(times must increase\)"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [3, 1, 2], [1, 2, 2]]}]},
     r"movers\[0\]\.keyframes\[2\]: time 1 does not come after 3"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0.5, 1, 1], [1, 1, 2]]}]},
     r"movers\[0\]\.keyframes\[0\]: the first keyframe's time must be 0, got 0.5"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [1, "x", 2]]}]},
     r"movers\[0\]\.keyframes\[1\]: expected a keyframe \[t, x, y\] \(three numbers\)"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [1, 1]]}]}, r"movers\[0\]\.keyframes\[1\]: expected a keyframe"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [1, 1, 2]], "interpolation": "cubic"}]},
     r"movers\[0\]\.interpolation: expected linear or gazebo, got 'cubic'"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [1, 1, 2]], "yield_distance": 1.0}]},
     r"movers\[0\]\.yield_distance: a mover on keyframes never yields"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [1, 1, 2]], "speed": 1.0}]},
     r"movers\[0\]\.speed: a mover has speed and path, or keyframes, not both"),
    ({"movers": [{"radius": 0.3, "keyframes": [[0, 1, 1], [1, 1, 2]], "loop": "yes"}]}, r"movers\[0\]\.loop"),
    ({"movers": [{"radius": 0.3, "path": [[1, 1], [2, 1]]}]}, r"movers\[0\]\.speed: missing \(a mover needs speed and path, or keyframes\)"),
    ({"movers": [{"radius": 0.3, "speed": 1, "path": [[1, 1], [2, 1]], "interpolation": "gazebo"}]},
     r"movers\[0\]\.interpolation: only for a mover on keyframes"),
    ({"robot": None}, r"robot: missing"),
    ({"robot": {"drive": "mecanum"}}, r"robot\.start: missing"),
    ({"robot": {"start": [1.0, 1.0]}}, r"robot\.start: expected \[x, y, yaw\]"),
    ({"robot": {"start": [1.0, 1.0, 0.0], "drive": "tank"}}, r"robot\.drive: expected one of mecanum \| omni3 \| diff"),
    ({"robot": {"start": [12.0, 1.0, 0.0]}}, r"robot\.start: \(12\.0, 1\.0\) lies outside the bounds"),
    ({"robot": {"start": [1.0, 1.0, 0.0], "footprint": [[0, 0], [1, 1], [2, 2]]}}, r"robot\.footprint: encloses no area"),
    ({"goals": [[1.0, 2.0]]}, r"goals\[0\]: expected \[x, y, yaw\]"),
    ({"map": {"yaml": "nowhere.yaml"}}, r"map\.yaml: .*nowhere\.yaml: no such file"),
    ({"map": {"path": "nowhere.yaml"}}, r"map: unknown key 'path'"),
    ({"map": {}}, r"map\.yaml: missing"),
    ({"map": {"yaml": "m.yaml", "relative_to": "home"}}, r"map\.relative_to: expected 'world' or 'data'"),
])
def test_broken_world_files_name_file_and_key(tmp_path, change, message):
    doc = {**GOOD, **change}
    doc = {k: v for k, v in doc.items() if v is not None}
    with pytest.raises(WorldError, match=rf"^{re.escape(str(tmp_path / 'w.yaml'))}: {message}"):
        load_world(write_world(tmp_path, doc))


@pytest.mark.parametrize("text, message", [
    ("bounds: [10, 8\nrobot: {start: [1, 1, 0]}\n", "not valid YAML"),
    ("- just\n- a list\n", "expected a mapping"),
    ("\x00\x01binary", "not valid YAML"),
])
def test_not_a_world_file(tmp_path, text, message):
    with pytest.raises(WorldError, match=rf"w\.yaml: {message}"):
        load_world(write_world(tmp_path, text))


def test_missing_world_file(tmp_path):
    with pytest.raises(WorldError, match=r"gone\.yaml: no such file"):
        load_world(tmp_path / "gone.yaml")


def test_unknown_keys_are_refused_not_ignored(tmp_path):
    with pytest.raises(WorldError, match="top level: unknown key 'lights'"):
        box_world(tmp_path, lights={"ceiling": 3})
    with pytest.raises(WorldError, match="robot: unknown key 'wheel_radius'"):
        box_world(tmp_path, robot={"start": [5.0, 4.0, 0.0], "wheel_radius": 0.076})


# ---------------------------------------------------------------- maps in worlds

def small_map(tmp_path, origin=Pose2D(0.0, 0.0, 0.0)):
    data = np.zeros((40, 60), np.int8)
    data[[0, -1], :] = 100
    data[:, [0, -1]] = 100
    data[10:30, 20] = 100
    data[35:, 50:] = -1
    grid = OccupancyGrid(info=MapMetaData(resolution=0.1, width=60, height=40, origin=origin), data=data)
    save_map(grid, tmp_path / "maps" / "small")
    return grid


def test_map_world_relative_to_the_world_file(tmp_path):
    grid = small_map(tmp_path)
    world = load_world(write_world(tmp_path, {"map": {"yaml": "maps/small.yaml"}, "robot": {"start": [1.0, 1.0, 0.0]}}))
    np.testing.assert_array_equal(world.grid.data, grid.data)
    assert world.extent == pytest.approx((0.0, 0.0, 6.0, 4.0))
    raster = world.rasterize(0.1)  # same cells, plus a margin of 1 cell for the outer walls
    np.testing.assert_array_equal(raster.data[1:-1, 1:-1], grid.data)
    # a wall of map cells at column 20 (x 2.0..2.1) for rows 10..29 (y 1.0..3.0)
    assert world.distance([1.5, 2.0]) == pytest.approx(0.5)
    assert world.distance([2.05, 2.0]) == 0.0
    assert world.footprint_clearance([1.2, 2.0, 0.0]) == pytest.approx(2.0 - 1.2 - 0.416, abs=0.05)
    assert world.footprint_clearance([2.0, 2.0, 0.0]) == 0.0


def test_map_world_with_a_yawed_map_takes_the_rotated_extent(tmp_path):
    small_map(tmp_path, origin=Pose2D(10.0, 5.0, math.pi / 2))
    world = load_world(write_world(tmp_path, {"map": {"yaml": "maps/small.yaml"}, "robot": {"start": [8.0, 6.0, 0.0]}}))
    assert world.extent == pytest.approx((6.0, 5.0, 10.0, 11.0))
    # the map's column 20 wall now runs along y = 7.0..7.1, for x = 7.0..9.0
    assert world.distance([8.0, 6.5]) == pytest.approx(0.5)


def test_map_relative_to_the_shared_data_folder(tmp_path, monkeypatch):
    small_map(tmp_path / "data")
    world_dir = tmp_path / "elsewhere"
    world_dir.mkdir()
    path = write_world(world_dir, {"map": {"yaml": "maps/small.yaml", "relative_to": "data"},
                                   "robot": {"start": [1.0, 1.0, 0.0]}})
    monkeypatch.setenv(DATA_ENV, str(tmp_path / "data"))
    assert load_world(path).grid.info.width == 60
    monkeypatch.setenv(DATA_ENV, str(tmp_path / "empty"))
    with pytest.raises(WorldError, match=rf"w\.yaml: map\.yaml: .*empty/maps/small\.yaml does not exist.*{DATA_ENV}"):
        load_world(path)
    monkeypatch.delenv(DATA_ENV)  # not inside a checkout: the error says to set the variable
    with pytest.raises(WorldError, match=rf"w\.yaml: map\.yaml: .*set {DATA_ENV}"):
        load_world(path)


@pytest.mark.skipif(not HAVE_WILLOW, reason="shared data not present")
def test_willow_found_beside_the_checkout_without_the_variable(monkeypatch):
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert load_world(world_path("willow")).grid is not None


# ---------------------------------------------------------------- geometry

def test_distance_to_walls_boxes_and_circles(tmp_path):
    world = box_world(tmp_path, boxes=[{"center": [2.0, 2.0], "size": [2.0, 1.0], "yaw": math.pi / 2}],
                      circles=[{"center": [8.0, 6.0], "radius": 0.5}], walls=[[5.0, 6.0, 5.0, 8.0]])
    points = np.array([[5.0, 4.0], [2.0, 2.0], [2.0, 3.5], [8.0, 4.5], [5.2, 7.0], [5.0, 5.0], [-1.0, 4.0]])
    expected = [1.95, 0.0, 0.5, 1.0, 0.15, 0.95, 0.0]  # the wall is 0.1 thick, extended 0.05 at its ends
    np.testing.assert_allclose(world.distance(points), expected, atol=1e-12)
    assert world.distance(points.reshape(7, 1, 2)).shape == (7, 1)
    movers = np.array([[5.0, 3.0, 0.4]])
    assert world.distance([5.0, 4.0], extra_circles=movers) == pytest.approx(0.6)


def test_footprint_clearance(tmp_path):
    world = box_world(tmp_path, boxes=[{"center": [8.0, 2.0], "size": [1.0, 1.0]}],
                      circles=[{"center": [2.0, 6.0], "radius": 0.05}, {"center": [5.0, 7.0], "radius": 0.3}])
    half_l, half_w = DEFAULT_FOOTPRINT[:, 0].max(), DEFAULT_FOOTPRINT[:, 1].max()
    poses = np.array([[5.0, 4.0, 0.0], [5.0, 4.0, math.pi / 2], [6.5, 2.0, 0.0], [7.2, 2.0, 0.0],
                      [2.0, 6.0, 0.3], [8.0, 2.0, 0.0], [5.0, 6.0, 0.0], [0.3, 4.0, 0.0]])
    expected = [7.0 - 0.3 - (4.0 + half_w),  # nearest: the circle at (5, 7) above
                7.0 - 0.3 - (4.0 + half_l),  # turned: the long side faces it
                7.5 - 6.5 - half_l,          # the box's left face ahead
                0.0,                         # overlapping the box
                0.0,                         # a small circle entirely inside the footprint
                0.0,                         # the footprint entirely inside the box
                1.0 - 0.3 - half_w,
                0.0]                         # through the outer wall
    np.testing.assert_allclose(world.footprint_clearance(poses), expected, atol=1e-12)
    assert world.footprint_clearance(poses[0]) == pytest.approx(expected[0])


def test_footprint_inside_a_big_box_has_no_clearance(tmp_path):
    world = box_world(tmp_path, boxes=[{"center": [5.0, 4.0], "size": [4.0, 4.0]}])
    assert world.footprint_clearance([5.0, 4.0, 0.2]) == 0.0


def test_segments_are_the_solids_edges(tmp_path):
    world = box_world(tmp_path, boxes=[{"center": [3.0, 3.0], "size": [2.0, 1.0], "yaw": 0.5}])
    assert world.segments.shape == (4 * len(world.solids), 4)
    box = world.solids[0]
    lengths = np.hypot(*(box - np.roll(box, -1, axis=0)).T)
    np.testing.assert_allclose(sorted(lengths), [1.0, 1.0, 2.0, 2.0])
    np.testing.assert_allclose(box.mean(axis=0), [3.0, 3.0])


# ---------------------------------------------------------------- rasterize

def test_rasterize_marks_the_cells_shapes_overlap(tmp_path):
    world = box_world(tmp_path, boxes=[{"center": [3.0, 2.5], "size": [2.0, 1.0]}],
                      circles=[{"center": [7.0, 5.0], "radius": 1.0}])
    grid = world.rasterize(0.5)
    info = grid.info
    assert (info.width, info.height) == (22, 18) and (info.origin.x, info.origin.y) == (-0.5, -0.5)
    data = grid.data
    assert (data[[0, -1], :] == 100).all() and (data[:, [0, -1]] == 100).all()  # the outer walls
    inner = data[1:-1, 1:-1]                                                     # the 10 × 8 bounds
    box = np.zeros_like(inner, bool)
    box[4:6, 4:8] = True                                                         # x 2..4, y 2..3
    rows, cols = np.indices(inner.shape)
    gap_x = np.maximum(np.abs((cols + 0.5) * 0.5 - 7.0) - 0.25, 0)
    gap_y = np.maximum(np.abs((rows + 0.5) * 0.5 - 5.0) - 0.25, 0)
    disk = np.hypot(gap_x, gap_y) < 1.0
    np.testing.assert_array_equal(inner == 100, box | disk)
    assert set(np.unique(data)) == {0, 100}


def test_rasterize_thin_walls_never_leak(tmp_path):
    world = box_world(tmp_path, walls=[[0.0, 4.0, 10.0, 4.0]])
    grid = world.rasterize(0.25)  # cells larger than the wall's thickness
    labels, count = ndimage.label(grid.data == 0)
    assert count == 2


# ---------------------------------------------------------------- movers

def test_movers_loop_at_constant_speed(tmp_path):
    world = box_world(tmp_path, movers=[
        {"radius": 0.2, "speed": 1.0, "path": [[1, 1], [3, 1], [3, 3], [1, 3]]},
        {"radius": 0.3, "speed": 0.5, "path": [[5, 5], [7, 5]], "loop": False},
        {"radius": 0.3, "speed": 0.0, "path": [[8, 1], [8, 2]]}])
    np.testing.assert_allclose(world.movers.pose_at(0.0), [[1, 1], [5, 5], [8, 1]])
    np.testing.assert_allclose(world.movers.pose_at(3.0), [[3, 2], [6.5, 5], [8, 1]])
    np.testing.assert_allclose(world.movers.pose_at(7.5), [[1, 1.5], [5.25, 5], [8, 1]])  # 2nd: on its way back
    np.testing.assert_allclose(world.movers.pose_at(3.0 + 8.0), world.movers.pose_at(3.0))  # both loops take 8 s
    np.testing.assert_allclose(world.movers.velocity_at(3.0), [[0, 1], [0.5, 0], [0, 0]])
    np.testing.assert_allclose(world.movers.velocity_at(5.0), [[-1, 0], [-0.5, 0], [0, 0]])
    np.testing.assert_allclose(world.movers.circles_at(3.0)[:, 2], [0.2, 0.3, 0.3])


def test_a_movers_way_ahead_follows_its_turns_and_reversals(tmp_path):
    world = box_world(tmp_path, movers=[
        {"radius": 0.2, "speed": 1.0, "path": [[1, 1], [3, 1], [3, 3], [1, 3]], "yield_distance": 1.5},
        {"radius": 0.3, "speed": 0.5, "path": [[5, 5], [7, 5]], "loop": False, "yield_distance": 1.0},
        {"radius": 0.3, "speed": 0.5, "path": [[5, 6], [7, 6]]}])
    np.testing.assert_allclose(world.movers.yield_distance, [1.5, 1.0, 0.0])          # absent: never yields
    np.testing.assert_allclose(world.movers.way_ahead(0, 0.0), [[1.2, 1], [2.5, 1]])   # from a radius ahead
    np.testing.assert_allclose(world.movers.way_ahead(0, 1.5), [[2.7, 1], [3, 1], [3, 2]])         # a corner
    np.testing.assert_allclose(world.movers.way_ahead(0, 7.5), [[1, 1.3], [1, 1], [2, 1]])         # the loop's end
    np.testing.assert_allclose(world.movers.way_ahead(1, 3.0), [[6.8, 5], [7, 5], [6.5, 5]])       # turning back
    np.testing.assert_allclose(world.movers.pose_after([1.0, 3.0, 0.0]), [[2, 1], [6.5, 5], [5, 6]])


def test_shipped_warehouse_movers_yield_and_the_crossing_people_do_not():
    assert np.all(shipped("warehouse").movers.yield_distance > 0)
    assert np.all(shipped("crossing").movers.yield_distance == 0)   # the dynamic-obstacle avoidance test


def test_no_movers(tmp_path):
    world = box_world(tmp_path)
    assert world.movers.pose_at(1.0).shape == (0, 2) and world.movers.circles_at(1.0).shape == (0, 3)


@pytest.mark.parametrize("text,problem", [
    ("boxs: []\n", "unknown key 'boxs' (did you mean 'boxes'?)"),
    ("robot: {start: [1, 1, 0], drve: diff}\n", "robot: unknown key 'drve' (did you mean 'drive'?)"),
    ("boxes: [{center: [2, 2], size: [1, 1], yaww: 1}]\n", "boxes[0]: unknown key 'yaww' (did you mean 'yaw'?)"),
    ("movers: [{radius: 0.3, speed: 1, path: [[1, 1], [2, 2]], yield: 1}]\n", "movers[0]: unknown key 'yield'"),
])
def test_a_misspelt_key_is_an_error_naming_it_and_the_closest_known_one(tmp_path, text, problem):
    path = tmp_path / "w.yaml"
    base = "bounds: [5, 5]\n" + ("" if text.startswith("robot") else "robot: {start: [1, 1, 0]}\n")
    path.write_text(base + text)
    with pytest.raises(WorldError) as err:
        load_world(path)
    assert problem in str(err.value) and str(path) in str(err.value)
