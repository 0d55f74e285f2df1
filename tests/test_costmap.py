"""The costmap core: ROS parameter files, footprint radii, the layers' values, incremental updates."""
import math

import numpy as np
import pytest

from omninav.schemas.messages import Header, LaserScan, MapMetaData, OccupancyGrid, Pose2D
from omninav.services.costmap.costmap import Costmap, occupancy_values
from omninav.geometry.footprint import cells_inside, make_footprint, transform
from omninav.services.costmap.layers import (INSCRIBED_INFLATED_OBSTACLE, LETHAL_OBSTACLE, NO_INFORMATION,
                                             interpret_map)
from omninav.services.costmap.params import (CostmapParams, InflationLayerParams, KeepoutLayerParams,
                                             ObservationSource, ObstacleLayerParams, StaticLayerParams,
                                             load_costmap_params)
from omninav.services.map_server.mapio import load_map
from omninav.geometry.grid import cell_to_world
from omninav.parameters.declare import ParamError

from conftest import REPO, SHARED_DATA

PARAMS = REPO / "compose" / "params"
SQUARE = ((0.1, 0.1), (0.1, -0.1), (-0.1, -0.1), (-0.1, 0.1))   # inscribed radius 0.1 m with no padding


def grid(data, resolution=0.05, origin=(0.0, 0.0, 0.0)) -> OccupancyGrid:
    data = np.asarray(data, np.int8)
    return OccupancyGrid(header=Header(frame_id="map"), info=MapMetaData(
        resolution=resolution, width=data.shape[1], height=data.shape[0], origin=Pose2D(*origin)), data=data)


def scan(ranges, angle_min=-math.pi, increment=None, range_max=10.0, stamp_ns=0) -> LaserScan:
    ranges = np.asarray(ranges, np.float32)
    increment = 2 * math.pi / len(ranges) if increment is None else increment
    return LaserScan(header=Header(stamp_ns=stamp_ns, frame_id="laser"), angle_min=angle_min,
                     angle_max=angle_min + increment * (len(ranges) - 1), angle_increment=increment,
                     range_min=0.05, range_max=range_max, ranges=ranges)


# ---------------------------------------------------------------- parameter files

def test_the_mecanum_style_ros1_files_load_unchanged(tmp_path):
    """The three move_base files, under their ROS names, as the paper's robot would ship them."""
    common = tmp_path / "costmap_common_params.yaml"
    common.write_text((PARAMS / "costmap_common_params.yaml").read_text())
    (tmp_path / "global_costmap_params.yaml").write_text((PARAMS / "costmap_global_params.yaml").read_text())
    (tmp_path / "local_costmap_params.yaml").write_text((PARAMS / "costmap_local_params.yaml").read_text())
    glob = load_costmap_params([common, tmp_path / "global_costmap_params.yaml"], "global_costmap")
    local = load_costmap_params([common, tmp_path / "local_costmap_params.yaml"], "local_costmap")
    assert glob.global_frame == "map" and not glob.rolling_window and glob.publish_frequency == 1.0
    assert [type(l) for l in glob.layers] == [StaticLayerParams, ObstacleLayerParams, InflationLayerParams]
    assert local.global_frame == "odom" and local.rolling_window and (local.width, local.height) == (6.0, 6.0)
    assert [type(l) for l in local.layers] == [ObstacleLayerParams, InflationLayerParams]   # static_map: false
    for params in (glob, local):
        assert params.footprint == ((0.416, 0.318), (0.416, -0.318), (-0.416, -0.318), (-0.416, 0.318))
        assert params.transform_tolerance == 0.5
        source, = params.layer(ObstacleLayerParams).observation_sources
        assert (source.name, source.topic, source.marking, source.clearing) == ("laser_scan_sensor", "scan", True, True)
        assert (source.obstacle_range, source.raytrace_range) == (2.5, 3.0)
        assert params.layer(InflationLayerParams).inflation_radius == 0.55


def test_the_sample_plugin_file_loads_after_the_common_file():
    params = load_costmap_params([PARAMS / "costmap_common_params.yaml", PARAMS / "costmap_global_plugins_params.yaml"])
    assert [l.name for l in params.layers] == ["static_layer", "obstacle_layer", "keepout_layer", "inflation_layer"]
    assert isinstance(params.layers[2], KeepoutLayerParams)
    assert params.layer(ObstacleLayerParams).observation_sources[0].clearing


def test_hydro_plugins_ros1_quirks(tmp_path):
    path = tmp_path / "costmap.yaml"
    path.write_text("""
global_costmap:
  inflation_radius: 0.8          # costmap level: copied into the inflation plugin, and wins
  obstacle_range: 4.0
  footprint: "[[0.3, 0.2], [0.3, -0.2], [-0.3, -0.2], [-0.3, 0.2]]"   # ROS 1 also takes a string
  plugins:
    - {name: obstacles, type: "costmap_2d::VoxelLayer"}
    - {name: inflater, type: "costmap_2d::InflationLayer"}
  obstacles:
    z_voxels: 2                  # a voxel setting: accepted, no effect in 2-D
    raytrace_range: 5.0          # layer level
    observation_sources: near far
    near: {data_type: LaserScan, obstacle_range: 1.0, clearing: true}
    far: {data_type: LaserScan, topic: /scan2}
  inflater: {inflation_radius: 0.3, cost_scaling_factor: 3.0}
""")
    params = load_costmap_params(path, "global_costmap")
    obstacles, inflater = params.layers
    near, far = obstacles.observation_sources
    assert (near.obstacle_range, near.raytrace_range, near.clearing) == (1.0, 5.0, True)   # source, then layer
    assert (far.obstacle_range, far.raytrace_range, far.topic) == (4.0, 5.0, "/scan2")      # costmap, then layer
    assert (inflater.inflation_radius, inflater.cost_scaling_factor) == (0.8, 3.0)
    assert params.footprint[0] == (0.3, 0.2)


def test_ros2_nav2_layout_loads(tmp_path):
    path = tmp_path / "nav2.yaml"
    path.write_text("""
local_costmap:
  local_costmap:
    ros__parameters:
      use_sim_time: true
      global_frame: odom
      rolling_window: true
      width: 3
      height: 3
      robot_radius: 0.22
      plugins: ["voxel_layer", "inflation_layer"]
      inflation_layer: {plugin: "nav2_costmap_2d::InflationLayer", cost_scaling_factor: 3.0}
      voxel_layer:
        plugin: "nav2_costmap_2d::VoxelLayer"
        observation_sources: scan
        scan: {topic: /scan, clearing: true, marking: true, data_type: "LaserScan", raytrace_max_range: 3.0,
               obstacle_max_range: 2.5}
""")
    params = load_costmap_params(path, "local_costmap")
    assert params.rolling_window and params.width == 3.0 and params.robot_radius == 0.22
    source = params.layers[0].observation_sources[0]
    assert (source.obstacle_range, source.raytrace_range) == (2.5, 3.0)


@pytest.mark.parametrize("text,needle", [
    ("global_costmap: {inflation_radus: 0.5}", "unknown parameter 'inflation_radus' (did you mean 'inflation_radius'?)"),
    ("global_costmap: {update_frequency: fast}", "'update_frequency' must be a number"),
    ("global_costmap: {plugins: [{name: x, type: 'costmap_2d::FancyLayer'}]}",
     "'costmap_2d::FancyLayer' is not supported"),
    ("observation_sources: s\ns: {data_type: PointCloud2}", "data_type must be one of 'LaserScan', got 'PointCloud2'"),
    ("observation_sources: s\n", "observation source 's' has no section"),
    ("inflation_radius: -1", "inflation_radius must be ≥ 0"),
    ("footprint: [[0, 0], [1, 0]]", "footprint must be empty or at least 3 items"),
])
def test_bad_files_name_the_key_and_the_file(tmp_path, text, needle):
    path = tmp_path / "costmap_common_params.yaml"
    path.write_text(text)
    with pytest.raises(ParamError) as err:
        load_costmap_params(path, "global_costmap")
    assert needle in str(err.value) and str(path) in str(err.value)


# ---------------------------------------------------------------- footprint

def test_footprint_radii():
    paper = make_footprint(((0.416, 0.318), (0.416, -0.318), (-0.416, -0.318), (-0.416, 0.318)), padding=0.01)
    assert paper.inscribed_radius == pytest.approx(0.328)             # half the padded width
    assert paper.circumscribed_radius == pytest.approx(math.hypot(0.426, 0.328))
    circle = make_footprint((), robot_radius=0.2, padding=0.0)        # ROS: a 16-gon on the circle
    assert len(circle.points) == 16
    assert circle.inscribed_radius == pytest.approx(0.2 * math.cos(math.pi / 16))
    assert circle.circumscribed_radius == pytest.approx(0.2)
    # an off-centre polygon: the nearest edge and the farthest vertex
    tri = make_footprint(((0.5, 0.0), (-0.1, 0.3), (-0.1, -0.3)), padding=0.0)
    assert tri.inscribed_radius == pytest.approx(0.1)
    assert tri.circumscribed_radius == pytest.approx(0.5)


def test_cells_inside_a_footprint_follow_the_pose():
    info = MapMetaData(resolution=0.1, width=40, height=40)
    rows, cols = cells_inside(info, transform(np.array(SQUARE) * 2, (2.0, 1.0, 0.0)))   # 0.4 m square
    assert sorted(set(rows)) == [8, 9, 10, 11] and sorted(set(cols)) == [18, 19, 20, 21]


# ---------------------------------------------------------------- static and inflation layers

def test_static_layer_interprets_the_map_as_ros():
    data = np.array([[-1, 0, 50, 99, 100]], np.int8)
    assert interpret_map(data, StaticLayerParams()).tolist() == [[255, 0, 0, 0, 254]]
    assert interpret_map(data, StaticLayerParams(track_unknown_space=False)).tolist() == [[0, 0, 0, 0, 254]]
    # not trinary: value / lethal_cost_threshold × 254, truncated
    assert interpret_map(data, StaticLayerParams(trinary_costmap=False)).tolist() == [[255, 0, 127, 251, 254]]


def _single_obstacle_costmap(**inflation) -> Costmap:
    data = np.zeros((41, 41), np.int8)
    data[20, 20] = 100
    params = CostmapParams(footprint=SQUARE, footprint_padding=0.0,
                           layers=(StaticLayerParams(), InflationLayerParams(**inflation)))
    costmap = Costmap(params, grid(data))
    costmap.update()
    return costmap


def test_inflation_values_follow_the_ros_formula():
    """resolution 0.05 m, inscribed radius 0.1 m, cost_scaling_factor 10, inflation_radius 0.3 m:
    252·exp(−10·(d − 0.1)) truncated, hand-computed for cells at distance d from the obstacle."""
    costs = _single_obstacle_costmap(inflation_radius=0.3, cost_scaling_factor=10.0).costs
    at = lambda dr, dc: int(costs[20 + dr, 20 + dc])   # noqa: E731
    assert at(0, 0) == 254                     # the obstacle
    assert at(0, 1) == at(1, 1) == 253         # 0.05, 0.0707 m: inside the inscribed radius
    assert at(0, 2) == 253                     # 0.1 m: on it
    assert at(1, 2) == 223                     # 0.1118 m: 252·exp(−0.118) = 223.9
    assert at(2, 2) == 166                     # 0.1414 m: 252·exp(−0.414) = 166.5
    assert at(0, 3) == 152                     # 0.15 m: 252·exp(−0.5) = 152.8
    assert at(2, 3) == 112                     # 0.1803 m: 252·exp(−0.803) = 112.9
    assert at(0, 4) == 92                      # 0.2 m: 252·exp(−1) = 92.7
    assert at(3, 4) == 56                      # 0.25 m: 252·exp(−1.5) = 56.2
    assert at(0, 6) == 34                      # 0.3 m: 252·exp(−2) = 34.1, the last cell inflated
    assert at(1, 6) == 0                       # 0.304 m: beyond ceil(0.3 / 0.05) = 6 cells
    assert at(-6, 0) == at(0, -6) == at(6, 0) == 34   # the same in every direction


def test_inflation_uses_the_nearest_obstacle_everywhere():
    """On random obstacle fields, every cell's cost is the formula at the exact distance to its
    nearest lethal cell (scipy's Euclidean distance transform as the oracle)."""
    from scipy.ndimage import distance_transform_edt
    rng = np.random.default_rng(3)
    for density in (0.002, 0.02, 0.2):
        data = np.where(rng.random((60, 70)) < density, 100, 0).astype(np.int8)
        data[20:40, 30] = 100
        params = CostmapParams(footprint=SQUARE, footprint_padding=0.0,
                               layers=(StaticLayerParams(), InflationLayerParams(inflation_radius=0.3)))
        costmap = Costmap(params, grid(data))
        costmap.update()
        d = distance_transform_edt(data != 100)           # cells
        expected = np.zeros(d.shape, np.int64)
        near = (d > 0) & (d <= 6)
        m = d[near] * 0.05
        expected[near] = np.where(m <= 0.1, 253, (252 * np.exp(-10.0 * (m - 0.1))).astype(np.int64))
        expected[d == 0] = 254
        np.testing.assert_array_equal(costmap.costs, expected)


def test_inflation_of_unknown_cells():
    data = np.full((30, 30), -1, np.int8)
    data[15, 10:20] = 100
    params = CostmapParams(footprint=SQUARE, footprint_padding=0.0, layers=(StaticLayerParams(),
                           InflationLayerParams(inflation_radius=0.3)))
    costmap = Costmap(params, grid(data))
    costmap.update()
    assert costmap.costs[17, 15] == INSCRIBED_INFLATED_OBSTACLE    # unknown, but inside the inscribed radius
    assert costmap.costs[19, 15] == NO_INFORMATION                 # unknown stays unknown below 253
    params = CostmapParams(footprint=SQUARE, footprint_padding=0.0, layers=(StaticLayerParams(),
                           InflationLayerParams(inflation_radius=0.3, inflate_unknown=True)))
    costmap = Costmap(params, grid(data))
    costmap.update()
    assert costmap.costs[19, 15] == 92                             # inflate_unknown: 0.2 m from the wall


def test_no_inflation_radius_means_no_inflation():
    costs = _single_obstacle_costmap(inflation_radius=0.0).costs
    assert costs[20, 20] == LETHAL_OBSTACLE and np.count_nonzero(costs) == 1


def test_a_yawed_map_keeps_its_geometry():
    """The Stata basement map has origin yaw π: costs at world points land on the right cells."""
    path = SHARED_DATA / "maps" / "basement_fixed.yaml"
    if not path.is_file():
        pytest.skip(f"{path} not present")
    grid_msg = load_map(path)
    costmap = Costmap(CostmapParams(robot_radius=0.2, layers=(StaticLayerParams(), InflationLayerParams())), grid_msg)
    costmap.update()
    assert costmap.info.origin.theta == grid_msg.info.origin.theta
    rows, cols = np.nonzero(grid_msg.data == 100)
    x, y = cell_to_world(grid_msg.info, rows[:50], cols[:50])
    assert (costmap.cost_at(x, y) == LETHAL_OBSTACLE).all()


def test_occupancy_grid_translation_is_ros_costmap_publishers():
    table = occupancy_values()
    # 1..252 map to 1 + 97·(cost − 1) // 251: 128 → 1 + 12319 // 251 = 50
    assert [table[i] for i in (0, 1, 128, 252, 253, 254, 255)] == [0, 1, 50, 98, 99, 100, -1]


# ---------------------------------------------------------------- obstacle layer

def _obstacle_costmap(source: ObservationSource, size=80, track_unknown=False, inflation=False) -> Costmap:
    layers = (ObstacleLayerParams(observation_sources=(source,), footprint_clearing_enabled=False),)
    if inflation:
        layers += (InflationLayerParams(),)
    params = CostmapParams(width=size * 0.05, height=size * 0.05, resolution=0.05, robot_radius=0.2,
                           track_unknown_space=track_unknown, layers=layers)
    return Costmap(params)


def test_marking_respects_obstacle_range():
    costmap = _obstacle_costmap(ObservationSource("scan", obstacle_range=2.5), size=120)
    # from cell (59, 59): west 2.55 m (beyond obstacle_range), south 2.45 m, east 1.0 m, north no return
    costmap.add_scan(scan([2.55, 2.45, 1.0, np.inf], angle_min=-math.pi, increment=math.pi / 2),
                     (2.975, 2.975, 0.0))
    costmap.update()
    assert set(zip(*np.nonzero(costmap.costs == LETHAL_OBSTACLE))) == {(10, 59), (59, 79)}


def test_marking_and_clearing_per_beam():
    costmap = _obstacle_costmap(ObservationSource("scan", obstacle_range=2.5, raytrace_range=3.0, clearing=True))
    layer = costmap.layers[0]
    layer.costs[39, 45:80] = LETHAL_OBSTACLE                        # stale obstacles east of the sensor
    costmap.add_scan(scan([1.0], angle_min=0.0, increment=0.1), (1.975, 1.975, 0.0))   # one beam east, 1 m
    costmap.update()
    row = costmap.costs[39]
    assert (row[45:59] == 0).all()                                  # cleared up to the hit
    assert row[59] == LETHAL_OBSTACLE                               # the hit itself
    assert (row[60:80] == LETHAL_OBSTACLE).all()                    # beyond the hit: untouched


def test_skip_tracked_leaves_a_moving_tracks_hits_unmarked_where_the_track_puts_it_at_the_scan():
    """Four hits 1 m from the sensor: east on a track moving north at 2 m/s (whose tracks, 0.2 s
    after the scan, put it 0.4 m further north), north on a track standing still (slower than
    skip_tracked_min_speed: the costmap's), west and south on no track. Without skip_tracked every
    hit is marked."""
    from omninav.geometry.movers import Movers
    tracks = Movers(np.array([[3.0, 2.375], [1.975, 3.0]]), np.array([[0.0, 2.0], [0.0, 0.0]]),
                    np.array([0.05, 0.05]), np.zeros((2, 3)))
    marked = {}
    for skip in (False, True):
        layers = (ObstacleLayerParams(observation_sources=(ObservationSource("scan", obstacle_range=2.5),),
                                      footprint_clearing_enabled=False, skip_tracked=skip),)
        costmap = Costmap(CostmapParams(width=4.0, height=4.0, resolution=0.05, robot_radius=0.2, layers=layers))
        assert costmap.needs_tracks == skip
        costmap.add_scan(scan([1.0] * 4, angle_min=-math.pi, increment=math.pi / 2, stamp_ns=1_000_000_000),
                         (1.975, 1.975, 0.0))
        costmap.set_movers(tracks, 1_200_000_000)
        costmap.update()
        marked[skip] = set(zip(*np.nonzero(costmap.costs == LETHAL_OBSTACLE)))
    assert marked[False] == {(39, 19), (19, 39), (39, 59), (59, 39)}
    assert marked[True] == {(39, 19), (19, 39), (59, 39)}         # east, on the walking track, is not


def test_clearing_stops_at_raytrace_range_and_needs_the_clearing_flag():
    # a hit at 3.5 m lies beyond obstacle_range (not marked); clearing reaches 2.0 m only
    costmap = _obstacle_costmap(ObservationSource("scan", raytrace_range=2.0, clearing=True), size=120)
    costmap.layers[0].costs[39, 40:110] = LETHAL_OBSTACLE
    costmap.add_scan(scan([3.5], angle_min=0.0, increment=0.1), (1.975, 1.975, 0.0))
    costmap.update()
    row = costmap.costs[39]
    assert (row[39:80] == 0).all()                                  # the sensor's cell + 40 cells = 2.0 m
    assert (row[80:110] == LETHAL_OBSTACLE).all()
    # a marking-only source never clears
    costmap = _obstacle_costmap(ObservationSource("scan", clearing=False), size=120)
    costmap.layers[0].costs[39, 45:50] = LETHAL_OBSTACLE
    costmap.add_scan(scan([1.0], angle_min=0.0, increment=0.1), (1.975, 1.975, 0.0))
    costmap.update()
    assert (costmap.costs[39, 45:50] == LETHAL_OBSTACLE).all() and costmap.costs[39, 59] == LETHAL_OBSTACLE


def test_clearing_only_source_does_not_mark_and_inf_clears_only_when_valid():
    source = ObservationSource("scan", marking=False, clearing=True, raytrace_range=3.0)
    costmap = _obstacle_costmap(source, track_unknown=True)
    costmap.add_scan(scan([1.0, np.inf], angle_min=0.0, increment=math.pi / 2, range_max=2.0), (1.975, 1.975, 0.0))
    costmap.update()
    assert (costmap.costs[39, 39:60] == 0).all() and costmap.costs[39, 60] == NO_INFORMATION
    assert (costmap.costs[40:60, 39] == NO_INFORMATION).all()      # +inf: no return, nothing cleared
    costmap = _obstacle_costmap(ObservationSource("scan", marking=False, clearing=True, inf_is_valid=True),
                                track_unknown=True)
    costmap.add_scan(scan([1.0, np.inf], angle_min=0.0, increment=math.pi / 2, range_max=2.0), (1.975, 1.975, 0.0))
    costmap.update()
    assert (costmap.costs[40:79, 39] == 0).all()                    # cleared out to range_max


def test_scans_go_to_the_sources_of_their_topic():
    costmap = _obstacle_costmap(ObservationSource("front", topic="/scan_front"))
    assert costmap.add_scan(scan([1.0]), (2.0, 2.0, 0.0), topic="scan_front") == 1
    assert costmap.add_scan(scan([1.0]), (2.0, 2.0, 0.0), topic="scan_rear") == 0


def test_footprint_clearing_and_clear():
    costmap = Costmap(CostmapParams(width=4.0, height=4.0, footprint=SQUARE, footprint_padding=0.0,
                                    layers=(ObstacleLayerParams(observation_sources=(ObservationSource("scan"),)),)))
    costmap.add_scan(scan([0.5, 0.5], angle_min=0.0, increment=math.pi), (2.0, 2.0, 0.0))
    costmap.update(robot_pose=(0.5, 0.5, 0.0))
    assert costmap.cost_at(2.5, 2.0) == LETHAL_OBSTACLE
    costmap.update(robot_pose=(2.5, 2.0, 0.0))                      # the robot now stands on that hit
    assert costmap.cost_at(2.5, 2.0) == 0 and costmap.cost_at(1.5, 2.0) == LETHAL_OBSTACLE
    costmap.clear()
    costmap.update(robot_pose=(0.5, 0.5, 0.0))
    assert (costmap.costs == 0).all()


def test_footprint_clearing_spares_what_lies_within_the_padding():
    # the robot (a 0.2 m square, padded by 0.15 m) stands with a hit 0.1 m off its side, inside the
    # padded footprint but not under the robot: that is an obstacle, and it stays one
    costmap = Costmap(CostmapParams(width=4.0, height=4.0, footprint=SQUARE, footprint_padding=0.15,
                                    layers=(ObstacleLayerParams(observation_sources=(ObservationSource("scan"),)),)))
    costmap.add_scan(scan([0.72, 0.5], angle_min=0.0, increment=math.pi), (2.0, 2.0, 0.0))
    costmap.update(robot_pose=(2.5, 2.0, 0.0))
    assert costmap.cost_at(2.72, 2.0) == LETHAL_OBSTACLE                        # 0.22 m ahead of the centre
    assert costmap.cost_at(1.5, 2.0) == LETHAL_OBSTACLE
    costmap.update(robot_pose=(1.5, 2.0, 0.0))                                  # standing on the other hit
    assert costmap.cost_at(1.5, 2.0) == 0 and costmap.cost_at(2.72, 2.0) == LETHAL_OBSTACLE


# ---------------------------------------------------------------- incremental updates

def _random_scan(rng, beams=90, stamp_ns=0):
    ranges = rng.uniform(0.2, 4.0, beams)
    ranges[rng.random(beams) < 0.1] = np.inf
    return scan(ranges, angle_min=rng.uniform(-math.pi, math.pi), stamp_ns=stamp_ns)


@pytest.mark.parametrize("rolling", [False, True])
def test_incremental_updates_equal_full_recomputes(rolling):
    """Random scans from random poses (seeded): after every update, the incrementally updated
    costs equal those of a full recompute of the same layers."""
    rng = np.random.default_rng(7)
    data = np.zeros((120, 140), np.int8)
    data[rng.integers(0, 120, 60), rng.integers(0, 140, 60)] = 100
    data[:, 70] = 100
    data[30:50, 70] = 0
    sources = (ObservationSource("a", clearing=True, raytrace_range=2.0),
               ObservationSource("b", topic="b", clearing=False, obstacle_range=1.5))
    if rolling:
        layers = (ObstacleLayerParams(observation_sources=sources), InflationLayerParams(inflation_radius=0.4))
        params = CostmapParams(rolling_window=True, width=8.0, height=6.5, footprint=SQUARE, layers=layers)
        costmap = Costmap(params)
    else:
        layers = (StaticLayerParams(), ObstacleLayerParams(observation_sources=sources),
                  InflationLayerParams(inflation_radius=0.4))
        costmap = Costmap(CostmapParams(footprint=SQUARE, track_unknown_space=True, layers=layers), grid(data))
    pose = np.array([3.0, 3.0, 0.0])
    windows = []
    for step in range(25):
        pose = pose + [rng.normal(0, 0.08), rng.normal(0, 0.08), rng.normal(0, 0.3)]
        costmap.add_scan(_random_scan(rng, stamp_ns=step), pose, topic="a" if step % 3 else "b")
        window = costmap.update(robot_pose=pose)
        windows.append(window)
        incremental = costmap.costs.copy()
        costmap.recompute(robot_pose=pose)
        np.testing.assert_array_equal(incremental, costmap.costs, err_msg=f"step {step}")
    whole = (0, 0, costmap.info.height, costmap.info.width)
    assert any(w is not None and w != whole for w in windows[1:])     # updates really were partial


def test_rolling_window_follows_the_robot_in_whole_cells():
    params = CostmapParams(rolling_window=True, width=2.0, height=2.0, resolution=0.1, robot_radius=0.1,
                           layers=(ObstacleLayerParams(observation_sources=(ObservationSource("scan"),),
                                                       footprint_clearing_enabled=False),))
    costmap = Costmap(params)
    costmap.add_scan(scan([0.55], angle_min=0.0, increment=0.1), (5.0, 5.0, 0.0))
    costmap.update(robot_pose=(5.0, 5.0, 0.0))
    assert (costmap.info.origin.x, costmap.info.origin.y) == pytest.approx((4.0, 4.0))
    assert costmap.cost_at(5.55, 5.0) == LETHAL_OBSTACLE
    costmap.layers[0]._buffers["scan"].clear()
    costmap.update(robot_pose=(5.33, 4.81, 0.0))
    assert (costmap.info.origin.x, costmap.info.origin.y) == pytest.approx((4.3, 3.9))   # ROS truncates
    assert costmap.cost_at(5.55, 5.0) == LETHAL_OBSTACLE             # kept while inside the window
    costmap.update(robot_pose=(8.0, 8.0, 0.0))
    assert (costmap.costs == 0).all()                                 # out of the window: forgotten


# ---------------------------------------------------------------- keepout and speed limits

def test_keepout_cells_are_lethal_and_speed_limits_are_looked_up():
    free = grid(np.zeros((40, 60), np.int8))
    mask = np.zeros((40, 60), np.int8)
    mask[10:20, 30:40] = 100
    speed = np.zeros((40, 60), np.int8)
    speed[:, :20] = 40
    layers = (StaticLayerParams(), KeepoutLayerParams(), InflationLayerParams(inflation_radius=0.2))
    costmap = Costmap(CostmapParams(footprint=SQUARE, footprint_padding=0.0, layers=layers), free)
    costmap.set_masks(grid(mask), grid(speed))
    costmap.update()
    assert (costmap.costs[10:20, 30:40] == LETHAL_OBSTACLE).all()
    assert costmap.costs[15, 41] == INSCRIBED_INFLATED_OBSTACLE      # keepout zones are inflated too
    assert costmap.costs[30, 10] == 0
    assert costmap.speed_limit_at(0.5, 0.5) == pytest.approx(40.0)    # percent, base 0 + 1 × 40
    assert costmap.speed_limit_at(2.5, 0.5) == np.inf


def test_keepout_masks_from_files_in_a_rolling_window(tmp_path):
    from omninav.services.map_server.mapio import save_map
    mask = np.zeros((40, 40), np.int8)
    mask[:, 20:] = 100
    path = save_map(grid(mask, resolution=0.1), tmp_path / "keepout")
    params = CostmapParams(rolling_window=True, width=2.0, height=2.0, resolution=0.1, robot_radius=0.1,
                           layers=(KeepoutLayerParams(mask=str(path)),))
    costmap = Costmap(params)
    costmap.update(robot_pose=(1.0, 1.0, 0.0), frame_in_map=Pose2D(1.0, 0.0, 0.0))   # odom is 1 m east of map
    assert costmap.cost_at(1.05, 1.0) == LETHAL_OBSTACLE            # map x = 2.05 m: keepout
    assert costmap.cost_at(0.95, 1.0) == 0                          # map x = 1.95 m: free
    costmap.update(robot_pose=(1.0, 1.0, 0.0), frame_in_map=Pose2D(0.5, 0.0, 0.0))   # localization moved
    assert costmap.cost_at(1.45, 1.0) == 0 and costmap.cost_at(1.55, 1.0) == LETHAL_OBSTACLE


# ---------------------------------------------------------------- a walking person leaves no trail

@pytest.mark.parametrize("behind", ["wall", "open"])
def test_a_person_crossing_the_scan_leaves_no_ghost_trail_in_the_local_costmap(tmp_path, behind):
    """The sample local costmap (6 m rolling window, odom frame) with the robot standing in a hall
    while a person (0.3 m circle) walks across 1.5 m in front of it: once they have passed, the
    cells they stood on are free again — cleared by the beams that now pass through them to the
    wall behind, or (no wall within the lidar's range: no return) by the inf_is_valid beams."""
    from omninav.sim.lidar import LidarParams, make_scan
    from omninav.sim.lidar import scan as cast_scan
    from omninav.sim.world import load_world
    bounds = "[12.0, 8.0]" if behind == "wall" else "[40.0, 40.0]"
    start = (1.0, 4.0) if behind == "wall" else (20.0, 20.0)
    world_file = tmp_path / "hall.yaml"
    world_file.write_text(f"name: hall\nbounds: {bounds}\nrobot:\n  start: [{start[0]}, {start[1]}, 0.0]\n")
    world = load_world(world_file)
    lidar = LidarParams(noise_std=0.0)
    costmap = Costmap(load_costmap_params([PARAMS / "costmap_common_params.yaml",
                                           PARAMS / "costmap_local_params.yaml"], "local_costmap"))
    robot = np.array([*start, 0.0])
    trail = []
    for k in range(100):                    # 10 s at 10 Hz: the person walks 5 m across at 0.5 m/s
        person = np.array([[start[0] + 1.5, start[1] - 2.5 + 0.05 * k, 0.3]])
        ranges = cast_scan(world, robot, person, lidar, None)
        costmap.add_scan(make_scan(lidar, ranges, k * 100_000_000), robot)
        if k % 2 == 0:
            costmap.update(robot)
        if 30 <= k <= 70 and k % 10 == 0:   # where they were while in front of the robot
            trail.append(person[0, :2] - (0.3, 0.0))       # the side facing the robot
    info = costmap.info
    cells = [(int((y - info.origin.y) / info.resolution), int((x - info.origin.x) / info.resolution))
             for x, y in trail]
    assert all(0 <= r < info.height and 0 <= c < info.width for r, c in cells)
    assert all(costmap.costs[r, c] < INSCRIBED_INFLATED_OBSTACLE for r, c in cells), \
        [int(costmap.costs[r, c]) for r, c in cells]
