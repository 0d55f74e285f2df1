"""AmclParams: every parameter of ROS 1 amcl, with its name, meaning and default.

Names and defaults follow ROS 1 amcl (navigation, noetic-devel: amcl_node.cpp and cfg/AMCL.cfg)
so a ROS 1 amcl YAML — flat, under `amcl:`, or in the ROS 2 `amcl: ros__parameters:` layout —
loads unchanged through `load_params_file(AmclParams, path)`. Two ROS 1 defaults disagree between
its documentation (wiki and AMCL.cfg: 0.0) and amcl_node.cpp (0.001 and 0.1):
recovery_alpha_slow / recovery_alpha_fast. We take the documented 0.0 (recovery off), which Nav2
also uses. Nav2's amcl renames many parameters and changes defaults: a Nav2 file (`amcl:
ros__parameters:`, alone or in a whole nav2_params.yaml) loads through AmclParams.from_mapping, its
names mapped by NAV2 below (its motion models are ROS 1's corrected ones: Nav2's
DifferentialMotionModel draws with the square root of the variance, as "diff-corrected" does);
names it has that omninav does not implement are accepted without effect, with a warning.

One group is not amcl's: temporal_update (off by default, so amcl's behaviour is the default) keeps
the filter updating while the robot stands still; docs/localizer.md says why and how.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..runtime.params import ForeignNames, ParamError, load_params

LASER_MODELS = ("beam", "likelihood_field", "likelihood_field_prob")
ODOM_MODELS = ("diff", "omni", "diff-corrected", "omni-corrected")

NAV2_MOTION_MODELS = {"nav2_amcl::DifferentialMotionModel": "diff-corrected", "nav2_amcl::OmniMotionModel":
                      "omni-corrected", "differential": "diff-corrected", "omnidirectional": "omni-corrected"}


def _nav2_motion_model(value) -> str:
    if value not in NAV2_MOTION_MODELS:
        raise ValueError(f"{value!r} is not one of {', '.join(NAV2_MOTION_MODELS)}")
    return NAV2_MOTION_MODELS[value]


NAV2 = ForeignNames(
    stack="Nav2", node="amcl",
    renames={**{f"alpha{k}": f"odom_alpha{k}" for k in range(1, 6)}, "robot_model_type": "odom_model_type",
             "max_beams": "laser_max_beams", "pf_err": "kld_err", "pf_z": "kld_z", "sigma_hit": "laser_sigma_hit",
             "lambda_short": "laser_lambda_short", "z_hit": "laser_z_hit", "z_max": "laser_z_max",
             "z_rand": "laser_z_rand", "z_short": "laser_z_short"},
    convert={"robot_model_type": _nav2_motion_model},
    # topics (wired by keys here), sim time (always), Nav2's initial-pose switches (omninav starts
    # from initial_pose_x/y/a, or from `initial_pose` below, always; its own saved pose is pose_file),
    # the free-space downsampling of its likelihood field and its own seed (ours is the node's seed)
    ignored=frozenset({"scan_topic", "map_topic", "use_sim_time", "set_initial_pose", "always_reset_initial_pose",
                       "initialize_at_saved_pose", "saved_pose_filepath", "freespace_downsampling", "random_seed"}))


@dataclass(frozen=True)
class AmclParams:
    # ---- overall filter
    min_particles: int = 100            # fewest particles the KLD bound may choose
    max_particles: int = 5000           # most particles
    kld_err: float = 0.01               # ε: largest KL divergence between true and sampled distribution
    kld_z: float = 0.99                 # z_{1-δ}: upper standard normal quantile, used as is (as amcl does)
    update_min_d: float = 0.2           # m of motion along odom x or y before a filter update
    update_min_a: float = math.pi / 6   # rad of rotation before a filter update
    resample_interval: int = 2          # filter updates between resamplings
    selective_resampling: bool = False  # resample only when the effective sample size < N/2
    transform_tolerance: float = 0.1    # s by which the published map→odom is post-dated
    recovery_alpha_slow: float = 0.0    # decay of the slow average weight (0: off; ROS suggests 0.001)
    recovery_alpha_fast: float = 0.0    # decay of the fast average weight (0: off; ROS suggests 0.1)
    # ---- not in ROS amcl: recovery as Probabilistic Robotics' Augmented_MCL (Table 8.3) has it
    recovery_reset_after_injection: bool = True  # zero w_slow and w_fast after injecting (amcl); false: keep them
    recovery_local_share: float = 0.0   # share of injected poses drawn near the estimate, not over the map (amcl: 0)
    recovery_local_std_xy: float = 0.5  # m, their spread around the estimate: a shove moves the robot a little
    recovery_local_std_a: float = 0.5   # rad
    # ---- not in ROS amcl: updates without motion (named after slam_gmapping's temporalUpdate)
    temporal_update: float = -1.0       # s: also update when this long passed without enough motion; ≤ 0: never (amcl)
    temporal_update_jitter_xy: float = 0.02  # m, std of the noise such an update adds to every particle
    temporal_update_jitter_a: float = 0.02   # rad, likewise for the heading
    # ---- not in ROS amcl: how well the scans fit the map at the estimate (the published beam fit)
    beam_fit_distance: float = 0.1      # m: a beam's end point this close to an obstacle fits the map
    initial_pose_x: float = 0.0         # m, mean of the initial Gaussian
    initial_pose_y: float = 0.0
    initial_pose_a: float = 0.0         # rad
    initial_cov_xx: float = 0.5 * 0.5   # m², initial covariance
    initial_cov_yy: float = 0.5 * 0.5
    initial_cov_aa: float = (math.pi / 12) ** 2  # rad²
    gui_publish_rate: float = -1.0      # Hz at most for the particle cloud; ≤ 0: never
    save_pose_rate: float = 0.5         # Hz at most to save the last pose for a restart; ≤ 0: never
    use_map_topic: bool = False         # subscribe to the map instead of asking the map server
    first_map_only: bool = False        # keep the first map received, ignore later ones
    force_update_after_initialpose: bool = False  # one filter update right after a new initial pose
    force_update_after_set_map: bool = False      # one filter update right after a new map
    std_warn_level_x: float = 0.2       # m: pose std above which the node warns
    std_warn_level_y: float = 0.2
    std_warn_level_yaw: float = 0.1     # rad
    # ---- laser model
    laser_min_range: float = -1.0       # m; ≤ 0: the scan's range_min
    laser_max_range: float = -1.0       # m; ≤ 0: the scan's range_max
    laser_max_beams: int = 30           # evenly spaced beams used per scan
    laser_z_hit: float = 0.95           # mixture weight of the hit part
    laser_z_short: float = 0.1          # mixture weight of the short part (beam model)
    laser_z_max: float = 0.05           # mixture weight of the max-range part (beam model)
    laser_z_rand: float = 0.05          # mixture weight of the random part
    laser_sigma_hit: float = 0.2        # m, std of the hit Gaussian
    laser_lambda_short: float = 0.1     # 1/m, decay of the short part (beam model)
    laser_likelihood_max_dist: float = 2.0  # m: the likelihood field's distances are clipped here
    laser_model_type: str = "likelihood_field"  # beam | likelihood_field | likelihood_field_prob
    do_beamskip: bool = False           # likelihood_field_prob: skip beams most particles disagree with
    beam_skip_distance: float = 0.5     # m: an end point this close to an obstacle agrees with the map
    beam_skip_threshold: float = 0.3    # a beam is used when more than this share of particles agree
    beam_skip_error_threshold: float = 0.9  # skip nothing when at least this share of beams would be skipped
    # ---- odometry model
    odom_model_type: str = "diff"       # diff | omni | diff-corrected | omni-corrected
    odom_alpha1: float = 0.2            # rotation noise from rotation
    odom_alpha2: float = 0.2            # rotation noise from translation
    odom_alpha3: float = 0.2            # translation noise from translation
    odom_alpha4: float = 0.2            # translation noise from rotation
    odom_alpha5: float = 0.2            # strafe noise from translation (omni models)
    odom_frame_id: str = "odom"
    base_frame_id: str = "base_link"
    global_frame_id: str = "map"
    tf_broadcast: bool = True           # publish map→odom

    def __post_init__(self):
        def need(ok: bool, name: str, what: str):
            if not ok:
                raise ValueError(f"parameter {name!r} must be {what}, got {getattr(self, name)!r}")

        need(self.min_particles >= 1, "min_particles", "at least 1")
        need(self.max_particles >= self.min_particles, "max_particles",
             f"at least min_particles ({self.min_particles})")
        need(self.kld_err > 0, "kld_err", "positive")
        need(self.kld_z > 0, "kld_z", "positive")
        need(self.update_min_d >= 0, "update_min_d", "≥ 0")
        need(self.update_min_a >= 0, "update_min_a", "≥ 0")
        need(self.resample_interval >= 1, "resample_interval", "at least 1")
        need(self.transform_tolerance >= 0, "transform_tolerance", "≥ 0")
        for name in ("recovery_alpha_slow", "recovery_alpha_fast", "recovery_local_share"):
            need(0 <= getattr(self, name) <= 1, name, "in [0, 1]")
        for name in ("temporal_update_jitter_xy", "temporal_update_jitter_a", "initial_cov_xx", "initial_cov_yy",
                     "initial_cov_aa", "std_warn_level_x", "beam_fit_distance",
                     "recovery_local_std_xy", "recovery_local_std_a",
                     "std_warn_level_y", "std_warn_level_yaw", "beam_skip_distance"):
            need(getattr(self, name) >= 0, name, "≥ 0")
        need(self.laser_max_beams >= 2, "laser_max_beams", "at least 2 (amcl skips the laser update below 2)")
        for name in ("laser_z_hit", "laser_z_short", "laser_z_max", "laser_z_rand", "laser_lambda_short"):
            need(getattr(self, name) >= 0, name, "≥ 0")
        need(self.laser_z_hit + self.laser_z_rand > 0, "laser_z_hit", "positive when laser_z_rand is 0")
        need(self.laser_sigma_hit > 0, "laser_sigma_hit", "positive")
        need(self.laser_likelihood_max_dist > 0, "laser_likelihood_max_dist", "positive")
        need(self.beam_fit_distance < self.laser_likelihood_max_dist, "beam_fit_distance",
             f"below laser_likelihood_max_dist ({self.laser_likelihood_max_dist}), where distances are clipped")
        need(self.laser_model_type in LASER_MODELS, "laser_model_type", " | ".join(LASER_MODELS))
        for name in ("beam_skip_threshold", "beam_skip_error_threshold"):
            need(0 <= getattr(self, name) <= 1, name, "in [0, 1]")
        need(self.odom_model_type in ODOM_MODELS, "odom_model_type", " | ".join(ODOM_MODELS))
        for k in range(1, 6):
            need(getattr(self, f"odom_alpha{k}") >= 0, f"odom_alpha{k}", "≥ 0")
        for name in ("odom_frame_id", "base_frame_id", "global_frame_id"):
            need(bool(getattr(self, name)), name, "a frame name")

    @property
    def odom_alphas(self) -> tuple[float, float, float, float, float]:
        return (self.odom_alpha1, self.odom_alpha2, self.odom_alpha3, self.odom_alpha4, self.odom_alpha5)

    @classmethod
    def from_mapping(cls, values: dict | None, source: str = "amcl"):
        """From our (ROS 1) names or Nav2's (NAV2; `initial_pose: {x, y, yaw}` as initial_pose_x/y/a)."""
        values = NAV2.translate(dict(values or {}), source)
        initial = values.pop("initial_pose", None)
        if initial is not None:
            if not isinstance(initial, dict) or not set(initial) <= {"x", "y", "z", "yaw"}:
                raise ParamError(f"{source}: initial_pose must be a mapping of x, y, z, yaw, got {initial!r}")
            for axis, ours in (("x", "initial_pose_x"), ("y", "initial_pose_y"), ("yaw", "initial_pose_a")):
                if axis in initial:
                    values[ours] = initial[axis]
        return load_params(cls, values, source, NAV2.names | {"initial_pose"})
