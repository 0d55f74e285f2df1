"""The rotation shim core (services/local_planner/shim.py): a robot facing away from a new path turns
on the spot, accel-limited, until the path lies within angular_dist_threshold, then hands over for
good; an aligned robot is left alone; a turn that would sweep the footprint into a wall is not
commanded. The shim in the running local planner: tests/test_local_planner_node.py."""
import math

import numpy as np

from omninav.schemas.messages import MapMetaData, Pose2D
from omninav.services.local_planner.footprint_check import FootprintCheck
from omninav.services.local_planner.shim import (RotationShim, RotationShimParams, heading_error, sampled_point,
                                                   turn_rate)
from omninav.geometry.se2 import integrate
from omninav.geometry.footprint import DEFAULT_FOOTPRINT

DT = 0.05
PARAMS = RotationShimParams(rotate_to_heading_angular_vel=1.0)    # clamped to max_vel_theta, as the node does
EAST = np.column_stack([np.linspace(0.0, 3.0, 61), np.zeros(61), np.zeros(61)])   # 5 cm apart, facing east
WEST = EAST * (-1.0, 1.0, 1.0)
INFO = MapMetaData(resolution=0.05, width=80, height=80, origin=Pose2D(x=-2.0, y=-2.0))


def free(poses):
    return np.ones(len(poses), bool)


def run_shim(pose, path, legal=free, ticks=200):
    """A kinematic loop (the turn rate follows the command): the shim's answers until it hands over."""
    shim, pose, wz, answers = RotationShim(PARAMS, DT), np.array(pose, float), 0.0, []
    shim.new_path()
    for _ in range(ticks):
        answer = shim.step(pose, (0.0, 0.0, wz), path, legal)
        answers.append(answer)
        if answer.phase != "rotate":
            return shim, pose, answers
        wz = answer.twist[2]
        pose = integrate(pose, answer.twist, DT)
    raise AssertionError("the shim never handed over")


def test_the_sampled_point_lies_forward_sampling_distance_along_the_path_from_the_nearest_point():
    assert np.allclose(sampled_point(EAST, (1.0, 0.3, 0.0), 0.5), (1.5, 0.0, 0.0))
    assert np.allclose(sampled_point(EAST, (2.9, 0.0, 0.0), 0.5), EAST[-1])      # beyond the end: the end
    assert math.isclose(heading_error(EAST, (0.0, 0.0, math.pi / 2), 0.5), -math.pi / 2)


def test_a_robot_facing_away_turns_on_the_spot_until_the_path_is_within_the_threshold():
    shim, pose, answers = run_shim((0.0, 0.0, math.pi), EAST)
    turns = np.array([a.twist for a in answers[:-1]])
    assert len(turns) > 10 and answers[-1].phase == "aligned"
    assert np.all(turns[:, :2] == 0.0) and np.allclose(pose[:2], 0.0)            # no translation
    assert np.all(np.sign(turns[:, 2]) == np.sign(turns[0, 2]))                  # one way round
    assert np.abs(turns[:, 2]).max() == PARAMS.rotate_to_heading_angular_vel
    assert np.abs(np.diff(np.concatenate([[0.0], turns[:, 2]]))).max() <= PARAMS.max_angular_accel * DT + 1e-12
    assert PARAMS.angular_dist_threshold - 0.06 < abs(pose[2]) <= PARAMS.angular_dist_threshold
    # handed over: the shim stays out for the rest of this path, even turned away again
    assert shim.step((0.0, 0.0, math.pi), (0.0, 0.0, 0.0), EAST, free).phase == "off"


def test_the_turn_slows_down_and_stops_on_the_target_heading():
    # the turn law followed to the end (the shim hands over at angular_dist_threshold before that)
    error, wz, errors, rates = 2.0, 0.0, [], []
    for _ in range(100):
        wz = turn_rate(PARAMS, error, wz, DT)
        error -= wz * DT
        errors.append(error)
        rates.append(wz)
    assert max(rates) == PARAMS.rotate_to_heading_angular_vel and abs(errors[-1]) < 1e-3 and abs(wz) < 1e-3
    assert min(errors) > -0.005                                               # no overshoot beyond 0.3°
    assert np.abs(np.diff(np.concatenate([[0.0], rates]))).max() <= PARAMS.max_angular_accel * DT + 1e-12


def test_an_aligned_robot_is_not_shimmed():
    for yaw in (0.0, 0.7, -0.7):
        _, pose, answers = run_shim((0.0, 0.0, yaw), EAST)
        assert [a.phase for a in answers] == ["aligned"] and pose[2] == yaw
        assert np.all(answers[0].twist == 0.0)


def test_a_turn_that_would_sweep_into_a_wall_is_not_commanded():
    # the robot (0.83 x 0.64 m) stands along a wall 0.45 m to its left (13 cm from its side): turned
    # in place, its front corner (0.53 m out) would sweep into the wall
    costs = np.zeros((INFO.height, INFO.width), np.uint8)
    costs[49:, :] = 254                                       # y ≥ 0.45 m
    footprint_check = FootprintCheck(DEFAULT_FOOTPRINT, 0, 0.05)

    def legal(poses):
        return footprint_check.legal_poses(poses, costs, INFO)

    shim, pose, answers = run_shim((0.0, 0.0, 0.0), WEST, legal)
    assert [a.phase for a in answers] == ["blocked"] and pose[2] == 0.0
    assert not legal(answers[0].poses).all() and legal(answers[0].poses[:1]).all()
    assert shim.step(pose, (0.0, 0.0, 0.0), EAST, legal).phase == "off"      # handed over for this path
    _, _, answers = run_shim((0.0, 0.0, 0.0), WEST, free)       # no wall: it turns
    assert answers[0].phase == "rotate"
