"""The pipeline tested by replaying a recording (recordings/README.md): what the robot saw on a
room mission — clock, ground truth, odometry, scans and the goals sent — is fed to map_server,
the localizer, the costmap and the global planner with `omninav navigate`'s parameters, in one
process (services/replay/source.py); they are judged by outcome: the pose against the recorded
truth, a plan to every goal, and the recorded drive free of collisions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import REPO
from omninav.cli.navigate import compose_for, map_for
from omninav.experiments.lockstep_mission import mission_nodes
from omninav.schemas import decode
from omninav.schemas.keys import KeyLayout
from omninav.services.replay.source import RecordingSource
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.geometry.se2 import wrap_angle
from omninav.sim.world import load_world, world_path

FIXTURE = REPO / "recordings" / "fixtures" / "room_mission.mcap"
KEYS = KeyLayout("r1")
RECORDED = [KEYS.sim("clock"), KEYS.sim_robot("truth"), KEYS.robot("odom"), KEYS.robot("scan"), KEYS.robot("goal")]
REPLAYED = ("map_server", "localizer", "costmap", "global_planner")


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    world = load_world(world_path("room"))
    folder = tmp_path_factory.mktemp("pipeline")
    services = compose_for(world, world_path("room"), map_for(world, "room", folder), "mecanum", "amcl",
                           folder / "unused.mcap", 0, 1.0, "r1")["services"]
    chosen = [s for s in services if s["name"] in REPLAYED]
    for service in chosen:
        if service["name"] == "global_planner":      # plan the user's goals themselves (no navigator here)
            service["params"] = {**service["params"], "goal_topic": "goal"}
    source = RecordingSource(FIXTURE, RECORDED)
    runner = InProcessRunner([source, *mission_nodes(chosen, "r1").values()])
    seen: dict[str, list] = {}
    runner.tap(lambda key, payload, _stamp: seen.setdefault(key, []).append(decode(payload)))
    runner.run_until(lambda: source.finished, max_steps=len(source.records))
    runner.close()
    return world, seen


def test_the_localizer_follows_the_recorded_truth(replayed):
    _, seen = replayed
    truth = {m.header.stamp_ns: m.pose for m in seen[KEYS.sim_robot("truth")]}
    poses = seen[KEYS.robot("pose")]
    assert len(poses) > 50
    errors = np.array([[math.hypot(p.pose.x - truth[p.header.stamp_ns].x, p.pose.y - truth[p.header.stamp_ns].y),
                        abs(math.degrees(wrap_angle(p.pose.theta - truth[p.header.stamp_ns].theta)))]
                       for p in poses if p.header.stamp_ns in truth])
    assert len(errors) == len(poses)
    assert np.percentile(errors[:, 0], 95) < 0.05 and np.percentile(errors[:, 1], 95) < 2.0
    assert errors[-1, 0] < 0.05


def test_the_planner_finds_a_plan_to_every_recorded_goal(replayed):
    _, seen = replayed
    goals = seen[KEYS.robot("goal")]
    plans = [p for p in seen[KEYS.robot("plan")] if len(p.poses)]
    assert len(goals) == 2 and not any(p.error for p in plans)
    for goal in goals:
        ends = [p.poses[-1] for p in plans if p.goal_id == goal.goal_id]
        assert ends, f"no plan for {goal.goal_id}"
        assert math.hypot(ends[0][0] - goal.pose.x, ends[0][1] - goal.pose.y) < 0.05


def test_the_recorded_drive_touched_nothing(replayed):
    world, seen = replayed
    poses = np.array([(m.pose.x, m.pose.y, m.pose.theta) for m in seen[KEYS.sim_robot("truth")]])
    assert world.footprint_clearance(poses).min() > 0.0
