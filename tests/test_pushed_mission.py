"""Issue 36 end to end: the Jackal without a map (`navigate --localization odom`, as BARN runs it)
is moved 0.4 m sideways as it nears its goal - the wheels never turn for it. On the chassis's
odometry alone the navigator declares the goal reached where the robot is not: a false success.
With the fusion (laser odometry, IMU, EKF) it notices, and whatever it says is true."""
import math
from pathlib import Path

import numpy as np
import pytest

from omninav.bench.shove import judge
from omninav.cli.navigate import compose_for, fuses_odometry
from omninav.cli.profile import load_profile
from omninav.experiments.lockstep_mission import run_mission
from omninav.experiments.mission_score import FALSE_SUCCESS_MARGIN_M
from omninav.sim.world import load_world, world_path

GOAL = (4.0, 1.0, 0.0)          # 2.8 m straight ahead of the room's start (1.2, 1.0, 0)
PUSH = (0.0, 0.4, 0.0)          # across the way, where the wheels cannot see it
NEAR_M = 0.35                   # m from the goal: where the robot is moved


def pushed_mission(odometry: str):
    world = load_world(world_path("room"))
    profile = load_profile("jackal")
    services = compose_for(world, Path(world.source), None, profile.drive, "odom", None, 0, 1.0, "r1", profile,
                           sim_dt=0.02, odometry=odometry)["services"]
    pushed = []

    def push_near_the_goal(nodes):
        sim = nodes["sim"].sim
        x, y, yaw = sim.pose
        if not pushed and math.hypot(x - GOAL[0], y - GOAL[1]) < NEAR_M:
            sim.teleport((x + PUSH[0], y + PUSH[1], yaw + PUSH[2]))
            pushed.append(sim.time)

    run = run_mission(services, world, np.array([GOAL]), timeout_s=40.0, after_step=push_near_the_goal)
    assert pushed, "the robot never came near its goal"
    return run.summary


def test_on_the_wheels_alone_a_pushed_robot_claims_a_goal_it_did_not_reach():
    summary = pushed_mission("chassis")
    goal = summary.goals[0]
    assert goal.status == "succeeded" and goal.false_success and summary.false_successes == 1
    assert goal.xy_error_m > 0.3 and not summary.success


def test_with_the_fusion_a_pushed_robot_claims_nothing_false_and_reaches_its_goal():
    summary = pushed_mission("fused")
    goal = summary.goals[0]
    assert summary.false_successes == 0 and not goal.false_success
    assert goal.status == "succeeded" and goal.xy_error_m <= 0.03 + FALSE_SUCCESS_MARGIN_M
    assert summary.success


@pytest.mark.parametrize("odometry, localization, followers, fused", [
    ("auto", "odom", True, True), ("auto", "amcl", True, False), ("auto", "amcl", False, True),
    ("auto", "slam", False, True), ("auto", "truth", False, False), ("chassis", "odom", False, False),
    ("fused", "amcl", True, True)])
def test_where_the_odometry_is_fused(odometry, localization, followers, fused):
    """auto fuses where nothing else sees a push: without a map, or without follower wheels."""
    assert fuses_odometry(odometry, localization, followers) == fused


def test_the_shove_bench_measures_the_odometrys_error_against_the_truths_motion():
    stamps = np.arange(0, 50) * 100_000_000                         # 5 s at 10 Hz
    moved = np.clip((stamps / 1e9 - 1.0) * 1.0, 0.0, 1.0)          # carried 1 m sideways from 1 s to 2 s
    truth = np.column_stack([stamps, np.full(50, 2.0), 3.0 + moved, np.zeros(50)])
    seen = np.clip(moved - np.where(stamps / 1e9 < 2.5, 0.3, 0.05), 0.0, None)   # 30 cm behind, then 5 cm
    odom = np.column_stack([stamps, np.zeros(50), seen, np.zeros(50)])
    result = judge(1.0, "fused", truth, odom, [(int(1.2e9), True), (int(4e9), False)])
    assert result.shoved_m == pytest.approx(1.0) and result.error_at_end_m == pytest.approx(0.3)
    assert result.error_after_1s_m == pytest.approx(0.05) and result.within_aim_after_s == pytest.approx(0.4)
    assert result.doubt_after_s == pytest.approx(0.1)               # began moving after 1.1 s, in doubt at 1.2 s
    stuck = judge(1.0, "chassis", truth, np.column_stack([stamps, np.zeros((50, 3))]), [])
    assert stuck.within_aim_after_s is None and stuck.final_error_m == pytest.approx(1.0) and stuck.doubt_after_s is None


def test_the_shove_bench_refuses_bad_input_in_one_line(capsys):
    from omninav.cli.main import main as cli_main
    assert cli_main(["bench", "shove", "--distance", "0", "5"]) == 2
    assert "--distance 0 5: each shove must be more than 0 and at most 3 m" in capsys.readouterr().err
    assert cli_main(["bench", "shove", "--profile", "nope"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "profile 'nope': no such file" in err
