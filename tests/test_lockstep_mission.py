"""Missions in one process, in lockstep (experiments/lockstep_mission.py, `navigate --in-process`):
the stack `omninav navigate` composes reaches the goal, and the same mission twice gives the same
recording, message for message (diagnostics aside: they carry wall-time figures)."""
from __future__ import annotations

import json
import math

import numpy as np

from omninav.cli.main import main as cli_main
from omninav.cli.navigate import compose_for, map_for
from omninav.experiments.lockstep_mission import run_mission
from omninav.services.recorder.mcap_io import read_records
from omninav.sim.world import load_world, world_path

GOAL = np.array([[2.3, 0.9, math.radians(30.0)]])     # 1.1 m ahead of the start, turned: a whole mission, short


def _outputs(path):
    return [(r.key, r.stamp_ns, r.seq, r.payload) for r in read_records(path) if "/diagnostics/" not in r.key]


def test_a_lockstep_mission_arrives_and_its_recording_is_the_same_every_time(tmp_path):
    world = load_world(world_path("room"))
    map_file = map_for(world, "room", tmp_path)
    runs = []
    for attempt in range(2):
        recording = tmp_path / f"run{attempt}.mcap"
        compose = compose_for(world, world_path("room"), map_file, "mecanum", "amcl", recording, 0, 1.0, "r1")
        runs.append(run_mission(compose["services"], world, GOAL, timeout_s=60.0, recording=recording))
    summary = runs[0].summary
    assert summary.success and summary.collisions == 0, summary
    assert runs[0].outcomes == {"g1": "succeeded"}
    assert summary.final_xy_error_m < 0.05
    first, second = _outputs(tmp_path / "run0.mcap"), _outputs(tmp_path / "run1.mcap")
    assert len(first) > 1000 and first == second


def test_navigate_lockstep_cancels_a_goal_it_cannot_reach_in_time_and_says_so(tmp_path, capsys):
    code = cli_main(["navigate", "--world", "room", "--in-process", "--goal", "8.5", "6.5", "0", "--timeout", "3",
                     "-o", str(tmp_path), "--json"])
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert code == 1 and not summary["success"]
    assert "1 goal(s) checked on the map" in captured.err                 # progress, before and while starting
    assert "starting sim (1/" in captured.err and "starting navigator (" in captured.err
    assert summary["goals"][0]["status"] in ("canceled", "none")
    assert (tmp_path / "run.mcap").is_file()
