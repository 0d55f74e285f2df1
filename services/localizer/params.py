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

from ..runtime.params import ForeignNames
from ...parameters.declare import Parameters, ParamError, Rule, group, param
from ...parameters.from_mapping import load_params

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


# ---- per-model groups (as Beluga splits them): each model reads only its own group. AmclParams
# below is all of them under ROS amcl's flat names, which a YAML file sets; laser_params() and
# motion_params() hand the model in use its group.

@dataclass(frozen=True)
class DiffMotionParams(Parameters):
    """Odometry noise of the differential-drive models (diff, diff-corrected)."""
    odom_alpha1: float = param(0.2, ge=0)   # rotation noise from rotation
    odom_alpha2: float = param(0.2, ge=0)   # rotation noise from translation
    odom_alpha3: float = param(0.2, ge=0)   # translation noise from translation
    odom_alpha4: float = param(0.2, ge=0)   # translation noise from rotation

    @property
    def alphas(self) -> tuple[float, float, float, float, float]:
        """α1…α5 as motion.decompose takes them (a differential drive has no strafe noise)."""
        return (self.odom_alpha1, self.odom_alpha2, self.odom_alpha3, self.odom_alpha4, 0.0)


@dataclass(frozen=True)
class OmniMotionParams(DiffMotionParams):
    """Odometry noise of the omnidirectional models (omni, omni-corrected): also strafing."""
    odom_alpha5: float = param(0.2, ge=0)   # strafe noise from translation

    @property
    def alphas(self) -> tuple[float, float, float, float, float]:
        return (*super().alphas[:4], self.odom_alpha5)


@dataclass(frozen=True)
class LaserMixtureParams(Parameters):
    """What every laser model mixes: a Gaussian hit part and a uniform random part."""
    laser_z_hit: float = param(0.95, ge=0)      # mixture weight of the hit part
    laser_z_rand: float = param(0.05, ge=0)     # mixture weight of the random part
    laser_sigma_hit: float = param(0.2, gt=0)   # m, std of the hit Gaussian

    rules = (Rule("laser_z_hit", lambda p: p.laser_z_hit + p.laser_z_rand > 0, "positive when laser_z_rand is 0"),)


@dataclass(frozen=True)
class LikelihoodFieldParams(LaserMixtureParams):
    """The likelihood field model (likelihood_field): distances to the nearest obstacle."""
    laser_likelihood_max_dist: float = param(2.0, gt=0)   # m: the likelihood field's distances are clipped here


@dataclass(frozen=True)
class LikelihoodFieldProbParams(LikelihoodFieldParams):
    """likelihood_field_prob: the likelihood field, skipping the beams most particles disagree with."""
    do_beamskip: bool = False                                     # skip beams (once the filter converged)
    beam_skip_distance: float = param(0.5, ge=0)                  # m: an end point this close to an obstacle agrees
    beam_skip_threshold: float = param(0.3, ge=0, le=1)           # a beam is used when more than this share agree
    beam_skip_error_threshold: float = param(0.9, ge=0, le=1)     # skip nothing when at least this share would be skipped


@dataclass(frozen=True)
class BeamModelParams(LaserMixtureParams):
    """The beam model (beam): ray casting, with short readings and max-range readings."""
    laser_z_short: float = param(0.1, ge=0)          # mixture weight of the short part
    laser_z_max: float = param(0.05, ge=0)           # mixture weight of the max-range part
    laser_lambda_short: float = param(0.1, ge=0)     # 1/m, decay of the short part


LASER_GROUPS: dict[str, type] = {"beam": BeamModelParams, "likelihood_field": LikelihoodFieldParams,
                                 "likelihood_field_prob": LikelihoodFieldProbParams}
MOTION_GROUPS: dict[str, type] = {"diff": DiffMotionParams, "diff-corrected": DiffMotionParams,
                                  "omni": OmniMotionParams, "omni-corrected": OmniMotionParams}


@dataclass(frozen=True)
class AmclParams(OmniMotionParams, LikelihoodFieldProbParams, BeamModelParams):
    """Every ROS amcl parameter under its flat name: the filter's and the interface's here, each
    model's in its group above."""
    # ---- overall filter
    min_particles: int = param(100, ge=1)            # fewest particles the KLD bound may choose
    max_particles: int = 5000                        # most particles
    kld_err: float = param(0.01, gt=0)               # ε: largest KL divergence between true and sampled distribution
    kld_z: float = param(0.99, gt=0)                 # z_{1-δ}: upper standard normal quantile, used as is (as amcl does)
    update_min_d: float = param(0.2, ge=0)           # m of motion along odom x or y before a filter update
    update_min_a: float = param(math.pi / 6, ge=0)   # rad of rotation before a filter update
    resample_interval: int = param(2, ge=1)          # filter updates between resamplings
    selective_resampling: bool = False               # resample only when the effective sample size < N/2
    transform_tolerance: float = param(0.1, ge=0)    # s by which the published map→odom is post-dated
    recovery_alpha_slow: float = param(0.0, ge=0, le=1)   # decay of the slow average weight (0: off; ROS suggests 0.001)
    recovery_alpha_fast: float = param(0.0, ge=0, le=1)   # decay of the fast average weight (0: off; ROS suggests 0.1)
    # ---- not in ROS amcl: recovery as Probabilistic Robotics' Augmented_MCL (Table 8.3) has it
    recovery_reset_after_injection: bool = True  # zero w_slow and w_fast after injecting (amcl); false: keep them
    recovery_local_share: float = param(0.0, ge=0, le=1)   # share of injected poses drawn near the estimate, not over the map (amcl: 0)
    recovery_local_std_xy: float = param(0.5, ge=0)  # m, their spread around the estimate: a shove moves the robot a little
    recovery_local_std_a: float = param(0.5, ge=0)   # rad
    # ---- not in ROS amcl: updates without motion (named after slam_gmapping's temporalUpdate)
    temporal_update: float = -1.0       # s: also update when this long passed without enough motion; ≤ 0: never (amcl)
    temporal_update_jitter_xy: float = param(0.02, ge=0)  # m, std of the noise such an update adds to every particle
    temporal_update_jitter_a: float = param(0.02, ge=0)   # rad, likewise for the heading
    # ---- not in ROS amcl: how well the scans fit the map at the estimate (the published beam fit)
    beam_fit_distance: float = param(0.1, ge=0)      # m: a beam's end point this close to an obstacle fits the map
    initial_pose_x: float = 0.0         # m, mean of the initial Gaussian
    initial_pose_y: float = 0.0
    initial_pose_a: float = 0.0         # rad
    initial_cov_xx: float = param(0.5 * 0.5, ge=0)   # m², initial covariance
    initial_cov_yy: float = param(0.5 * 0.5, ge=0)
    initial_cov_aa: float = param((math.pi / 12) ** 2, ge=0)  # rad²
    gui_publish_rate: float = -1.0      # Hz at most for the particle cloud; ≤ 0: never
    save_pose_rate: float = 0.5         # Hz at most to save the last pose for a restart; ≤ 0: never
    use_map_topic: bool = False         # subscribe to the map instead of asking the map server
    first_map_only: bool = False        # keep the first map received, ignore later ones
    force_update_after_initialpose: bool = False  # one filter update right after a new initial pose
    force_update_after_set_map: bool = False      # one filter update right after a new map
    std_warn_level_x: float = param(0.2, ge=0)       # m: pose std above which the node warns
    std_warn_level_y: float = param(0.2, ge=0)
    std_warn_level_yaw: float = param(0.1, ge=0)     # rad
    # ---- laser, every model (each model's own parameters: its group above)
    laser_min_range: float = -1.0       # m; ≤ 0: the scan's range_min
    laser_max_range: float = -1.0       # m; ≤ 0: the scan's range_max
    laser_max_beams: int = param(30, ge=2)   # evenly spaced beams used per scan (amcl skips the laser update below 2)
    laser_model_type: str = param("likelihood_field", choices=LASER_MODELS)
    # ---- odometry model (its noise: the model's group above)
    odom_model_type: str = param("diff", choices=ODOM_MODELS)
    odom_frame_id: str = param("odom", nonempty=True)
    base_frame_id: str = param("base_link", nonempty=True)
    global_frame_id: str = param("map", nonempty=True)
    tf_broadcast: bool = True           # publish map→odom

    rules = (Rule("max_particles", lambda p: p.max_particles >= p.min_particles,
                  "at least min_particles ({p.min_particles})"),
             Rule("beam_fit_distance", lambda p: p.beam_fit_distance < p.laser_likelihood_max_dist,
                  "below laser_likelihood_max_dist ({p.laser_likelihood_max_dist}), where distances are clipped"))

    def laser_params(self) -> LaserMixtureParams:
        """The parameters of the laser model in use (laser_model_type)."""
        return group(self, LASER_GROUPS[self.laser_model_type])

    def motion_params(self) -> DiffMotionParams:
        """The odometry noise of the motion model in use (odom_model_type)."""
        return group(self, MOTION_GROUPS[self.odom_model_type])

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
