"""Nav2 parameter files load unchanged where omninav has the capability: the amcl, costmap, planner and
controller sections of nav2_bringup's shipped nav2_params.yaml (its defaults, written here as the
fixture: ros-navigation/navigation2, nav2_bringup/params/nav2_params.yaml, the DWB-era file), a
known Nav2 name omninav does not implement is accepted with a warning naming it, an unknown name is
an error naming it with the closest known one."""
import logging

import pytest

from omninav.services.costmap.params import InflationLayerParams, ObstacleLayerParams, load_costmap_params
from omninav.services.runtime.compose import ComposeError, load_compose
from omninav.services.runtime.params import load_node_params, read_params_mapping
from omninav.parameters.declare import ParamError
from omninav.services.runtime.service_registry import node_class


def build_params(service: str, path, name: str = ""):
    """What `omninav run SERVICE --params FILE` (build_node) makes of a file, without the node."""
    return load_node_params(node_class(service).Params, read_params_mapping(path, name or service), str(path))

NAV2_PARAMS = """\
amcl:
  ros__parameters:
    use_sim_time: True
    alpha1: 0.2
    alpha2: 0.2
    alpha3: 0.2
    alpha4: 0.2
    alpha5: 0.2
    base_frame_id: "base_footprint"
    beam_skip_distance: 0.5
    beam_skip_error_threshold: 0.9
    beam_skip_threshold: 0.3
    do_beamskip: false
    global_frame_id: "map"
    lambda_short: 0.1
    laser_likelihood_max_dist: 2.0
    laser_max_range: 100.0
    laser_min_range: -1.0
    laser_model_type: "likelihood_field"
    max_beams: 60
    max_particles: 2000
    min_particles: 500
    odom_frame_id: "odom"
    pf_err: 0.05
    pf_z: 0.99
    recovery_alpha_fast: 0.0
    recovery_alpha_slow: 0.0
    resample_interval: 1
    robot_model_type: "nav2_amcl::DifferentialMotionModel"
    save_pose_rate: 0.5
    sigma_hit: 0.2
    tf_broadcast: true
    transform_tolerance: 1.0
    update_min_a: 0.2
    update_min_d: 0.25
    z_hit: 0.5
    z_max: 0.05
    z_rand: 0.5
    z_short: 0.05
    scan_topic: scan

bt_navigator:
  ros__parameters:
    use_sim_time: True
    global_frame: map
    robot_base_frame: base_link
    odom_topic: /odom

controller_server:
  ros__parameters:
    use_sim_time: True
    controller_frequency: 20.0
    min_x_velocity_threshold: 0.001
    min_y_velocity_threshold: 0.5
    min_theta_velocity_threshold: 0.001
    failure_tolerance: 0.3
    progress_checker_plugin: "progress_checker"
    goal_checker_plugins: ["general_goal_checker"]
    controller_plugins: ["FollowPath"]
    progress_checker:
      plugin: "nav2_controller::SimpleProgressChecker"
      required_movement_radius: 0.5
      movement_time_allowance: 10.0
    general_goal_checker:
      stateful: True
      plugin: "nav2_controller::SimpleGoalChecker"
      xy_goal_tolerance: 0.25
      yaw_goal_tolerance: 0.25
    FollowPath:
      plugin: "dwb_core::DWBLocalPlanner"
      debug_trajectory_details: True
      min_vel_x: 0.0
      min_vel_y: 0.0
      max_vel_x: 0.26
      max_vel_y: 0.0
      max_vel_theta: 1.0
      min_speed_xy: 0.0
      max_speed_xy: 0.26
      min_speed_theta: 0.0
      acc_lim_x: 2.5
      acc_lim_y: 0.0
      acc_lim_theta: 3.2
      decel_lim_x: -2.5
      decel_lim_y: 0.0
      decel_lim_theta: -3.2
      vx_samples: 20
      vy_samples: 5
      vtheta_samples: 20
      sim_time: 1.7
      linear_granularity: 0.05
      angular_granularity: 0.025
      transform_tolerance: 0.2
      xy_goal_tolerance: 0.25
      trans_stopped_velocity: 0.25
      short_circuit_trajectory_evaluation: True
      stateful: True
      critics: ["RotateToGoal", "Oscillation", "BaseObstacle", "GoalAlign", "PathAlign", "PathDist", "GoalDist"]
      BaseObstacle.scale: 0.02
      PathAlign.scale: 32.0
      PathAlign.forward_point_distance: 0.1
      GoalAlign.scale: 24.0
      GoalAlign.forward_point_distance: 0.1
      PathDist.scale: 32.0
      GoalDist.scale: 24.0
      RotateToGoal.scale: 32.0
      RotateToGoal.slowing_factor: 5.0
      RotateToGoal.lookahead_time: -1.0

local_costmap:
  local_costmap:
    ros__parameters:
      update_frequency: 5.0
      publish_frequency: 2.0
      global_frame: odom
      robot_base_frame: base_link
      use_sim_time: True
      rolling_window: true
      width: 3
      height: 3
      resolution: 0.05
      robot_radius: 0.22
      plugins: ["voxel_layer", "inflation_layer"]
      inflation_layer:
        plugin: "nav2_costmap_2d::InflationLayer"
        cost_scaling_factor: 3.0
        inflation_radius: 0.55
      voxel_layer:
        plugin: "nav2_costmap_2d::VoxelLayer"
        enabled: True
        publish_voxel_map: True
        origin_z: 0.0
        z_resolution: 0.05
        z_voxels: 16
        max_obstacle_height: 2.0
        mark_threshold: 0
        observation_sources: scan
        scan:
          topic: /scan
          max_obstacle_height: 2.0
          clearing: True
          marking: True
          data_type: "LaserScan"
          raytrace_max_range: 3.0
          raytrace_min_range: 0.0
          obstacle_max_range: 2.5
          obstacle_min_range: 0.0
      static_layer:
        map_subscribe_transient_local: True
      always_send_full_costmap: True

global_costmap:
  global_costmap:
    ros__parameters:
      update_frequency: 1.0
      publish_frequency: 1.0
      global_frame: map
      robot_base_frame: base_link
      use_sim_time: True
      robot_radius: 0.22
      resolution: 0.05
      track_unknown_space: true
      plugins: ["static_layer", "obstacle_layer", "inflation_layer"]
      obstacle_layer:
        plugin: "nav2_costmap_2d::ObstacleLayer"
        enabled: True
        observation_sources: scan
        scan:
          topic: /scan
          max_obstacle_height: 2.0
          clearing: True
          marking: True
          data_type: "LaserScan"
          raytrace_max_range: 3.0
          raytrace_min_range: 0.0
          obstacle_max_range: 2.5
          obstacle_min_range: 0.0
      static_layer:
        plugin: "nav2_costmap_2d::StaticLayer"
        map_subscribe_transient_local: True
      inflation_layer:
        plugin: "nav2_costmap_2d::InflationLayer"
        cost_scaling_factor: 3.0
        inflation_radius: 0.55
      always_send_full_costmap: True

planner_server:
  ros__parameters:
    expected_planner_frequency: 20.0
    use_sim_time: True
    planner_plugins: ["GridBased"]
    GridBased:
      plugin: "nav2_navfn_planner/NavfnPlanner"
      tolerance: 0.5
      use_astar: false
      allow_unknown: true
"""


@pytest.fixture
def nav2_file(tmp_path):
    path = tmp_path / "nav2_params.yaml"
    path.write_text(NAV2_PARAMS)
    return path


def ignored_in(caplog) -> str:
    return " ".join(r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)


def test_amcl_takes_nav2s_names_from_the_whole_file(nav2_file, caplog):
    with caplog.at_level(logging.WARNING):
        params = build_params("localizer", nav2_file, "amcl")
    assert [getattr(params, f"odom_alpha{k}") for k in range(1, 6)] == [0.2] * 5
    assert params.odom_model_type == "diff-corrected"           # Nav2's models are ROS 1's corrected ones
    assert (params.laser_max_beams, params.min_particles, params.max_particles) == (60, 500, 2000)
    assert (params.kld_err, params.kld_z, params.laser_sigma_hit, params.laser_lambda_short) == (0.05, 0.99, 0.2, 0.1)
    assert (params.laser_z_hit, params.laser_z_max, params.laser_z_rand, params.laser_z_short) == (0.5, 0.05, 0.5, 0.05)
    assert (params.base_frame_id, params.resample_interval, params.update_min_d) == ("base_footprint", 1, 0.25)
    assert params.laser_max_range == 100.0 and params.transform_tolerance == 1.0
    assert "Nav2 parameters accepted without effect" in ignored_in(caplog)
    assert "scan_topic" in ignored_in(caplog) and "use_sim_time" in ignored_in(caplog)


def test_amcl_reads_nav2s_omni_model_and_initial_pose(tmp_path):
    path = tmp_path / "amcl.yaml"
    path.write_text("amcl:\n  ros__parameters:\n    robot_model_type: nav2_amcl::OmniMotionModel\n"
                    "    set_initial_pose: true\n    initial_pose: {x: 1.5, y: -2.0, z: 0.0, yaw: 0.7}\n")
    params = build_params("localizer", path, "amcl")
    assert params.odom_model_type == "omni-corrected"
    assert (params.initial_pose_x, params.initial_pose_y, params.initial_pose_a) == (1.5, -2.0, 0.7)


@pytest.mark.parametrize("text, needle", [
    ("alpha6: 0.2", "unknown parameter 'alpha6' (did you mean 'alpha5'?)"),
    ("max_beam: 60", "unknown parameter 'max_beam' (did you mean 'max_beams'"),
    ("robot_model_type: nav2_amcl::AckermannModel", "'robot_model_type': 'nav2_amcl::AckermannModel' is not one of"),
    ("initial_pose: {x: 1.0, heading: 2.0}", "initial_pose must be a mapping of x, y, z, yaw"),
])
def test_a_bad_nav2_amcl_name_or_value_is_named(tmp_path, text, needle):
    path = tmp_path / "amcl.yaml"
    path.write_text("amcl:\n  ros__parameters:\n    " + text + "\n")
    with pytest.raises(ParamError) as err:
        build_params("localizer", path, "amcl")
    assert needle in str(err.value) and str(path) in str(err.value)


def test_both_costmaps_load_from_the_whole_file(nav2_file, caplog):
    with caplog.at_level(logging.WARNING):
        local = load_costmap_params(nav2_file, "local_costmap")
        glob = load_costmap_params(nav2_file, "global_costmap")
    assert local.rolling_window and (local.width, local.height, local.resolution) == (3.0, 3.0, 0.05)
    assert local.robot_radius == 0.22 and local.global_frame == "odom"
    assert [layer.name for layer in local.layers] == ["voxel_layer", "inflation_layer"]
    (source,) = local.layer(ObstacleLayerParams).observation_sources
    assert (source.obstacle_range, source.raytrace_range, source.clearing) == (2.5, 3.0, True)
    assert [layer.name for layer in glob.layers] == ["static_layer", "obstacle_layer", "inflation_layer"]
    inflation = glob.layer(InflationLayerParams)
    assert (inflation.inflation_radius, inflation.cost_scaling_factor) == (0.55, 3.0)
    assert glob.track_unknown_space and glob.update_frequency == 1.0
    warned = ignored_in(caplog)
    assert "raytrace_min_range" in warned and "map_subscribe_transient_local" in warned
    assert "static_layer" in warned           # the local costmap's section its plugin list does not name


def test_the_costmap_names_an_unknown_nav2_name_with_the_closest_one(tmp_path):
    path = tmp_path / "costmap.yaml"
    path.write_text(NAV2_PARAMS.replace("      robot_radius: 0.22\n      resolution: 0.05\n      track_unknown",
                                        "      robot_radius: 0.22\n      resolutoin: 0.05\n      track_unknown"))
    with pytest.raises(ParamError, match=r"unknown parameter 'resolutoin' \(did you mean 'resolution'\?\)"):
        load_costmap_params(path, "global_costmap")


def test_the_planner_takes_navfns_names(nav2_file, caplog):
    with caplog.at_level(logging.WARNING):
        params = build_params("global_planner", nav2_file, "planner_server")
    assert (params.default_tolerance, params.use_dijkstra, params.allow_unknown) == (0.5, True, True)
    assert "expected_planner_frequency" in ignored_in(caplog)
    astar = tmp_file(nav2_file.parent, NAV2_PARAMS.replace("use_astar: false", "use_astar: true"))
    assert build_params("global_planner", astar).use_dijkstra is False


def test_the_controller_takes_dwbs_names(nav2_file, caplog):
    with caplog.at_level(logging.WARNING):
        params = build_params("local_planner", nav2_file, "controller_server")
    assert (params.max_vel_x, params.min_vel_x, params.max_vel_y, params.min_vel_y) == (0.26, 0.0, 0.0, 0.0)
    assert (params.max_vel_theta, params.min_vel_theta) == (1.0, -1.0)     # DWB's is a magnitude
    assert (params.acc_lim_x, params.acc_lim_y, params.acc_lim_theta) == (2.5, 0.0, 3.2)
    assert (params.vx_samples, params.vy_samples, params.vtheta_samples, params.sim_time) == (20, 5, 20, 1.7)
    assert (params.sim_granularity, params.controller_frequency, params.xy_goal_tolerance) == (0.05, 20.0, 0.25)
    assert (params.path_distance_bias, params.goal_distance_bias, params.occdist_scale) == (32.0, 24.0, 0.02)
    assert params.forward_point_distance == 0.1
    warned = ignored_in(caplog)
    assert all(name in warned for name in ("decel_lim_x", "critics", "general_goal_checker", "progress_checker"))


@pytest.mark.parametrize("service, old, new, needle", [
    ("local_planner", "max_vel_x: 0.26", "max_vel_xx: 0.26",
     "unknown parameter 'max_vel_xx' (did you mean 'max_vel_x'?)"),
    ("local_planner", 'plugin: "dwb_core::DWBLocalPlanner"', 'plugin: "nav2_mppi_controller::MPPIController"',
     "type 'nav2_mppi_controller::MPPIController' is not implemented here"),
    ("global_planner", 'plugin: "nav2_navfn_planner/NavfnPlanner"', 'plugin: "nav2_smac_planner/SmacPlannerHybrid"',
     "type 'nav2_smac_planner/SmacPlannerHybrid' is not implemented here"),
    ("global_planner", "tolerance: 0.5", "tolerence: 0.5", "unknown parameter 'tolerence' (did you mean 'tolerance'?)"),
])
def test_an_unknown_nav2_controller_or_planner_name_is_named(tmp_path, service, old, new, needle):
    path = tmp_file(tmp_path, NAV2_PARAMS.replace(old, new))
    with pytest.raises(ParamError) as err:
        build_params(service, path)
    assert needle in str(err.value)


def test_a_compose_file_loads_a_nav2_file_for_the_localizer(nav2_file):
    compose = nav2_file.parent / "stack.yaml"
    compose.write_text(f"services:\n  - {{name: amcl, service: localizer, params_file: {nav2_file.name}}}\n")
    (spec,) = load_compose(compose).services
    assert spec.params["robot_model_type"] == "nav2_amcl::DifferentialMotionModel"
    nav2_file.write_text(NAV2_PARAMS.replace("max_beams: 60", "max_beam: 60"))
    with pytest.raises(ComposeError, match="max_beam"):
        load_compose(compose)


def tmp_file(folder, text):
    path = folder / "nav2_edited.yaml"
    path.write_text(text)
    return path
