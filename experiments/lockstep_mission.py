"""A whole navigation mission in one process, in lockstep: the services of a mission's compose
mapping (cli/navigate.py `compose_for`, the same parameters as the multi-process run) built as
Nodes and stepped by the InProcessRunner, with a goal sequencer in place of the user.

No wall clock is in the loop: the simulator advances a step only when every service has processed
what the last step released, so the run is as fast as the CPU computes it and the same mapping
gives the same messages — and, written with `recording`, the same MCAP file byte for byte — at any
machine load. The summary is the one `omninav navigate` prints (experiments/mission_score.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..schemas.messages import CancelGoal, Clock, Goal, NavStatus, Pose2D
from .mission_score import TERMINAL, MissionCollector, MissionSummary, summarize_mission
from ..services.recorder.mcap_io import RecordingWriter
from ..services.runtime.inprocess import CpuMeter, InProcessRunner
from ..services.runtime.node import NS_PER_S, Node
from ..services.runtime.run import build_node
from ..sim.world import World

START_S = 1.0           # sim s before the first goal: the map, the first scans and costmaps are out
CANCEL_WAIT_S = 2.0     # sim s for the navigator to confirm a cancel
SETTLE_S = 1.0          # sim s after the last goal ends: the robot comes to rest


class GoalSequencer(Node):
    """The user of a mission: sends the goals in order on the clock, each once the previous one
    succeeded; a goal without a final status within timeout_s is canceled; a failed goal ends the
    sequence. `finished` turns true settle_s after the last goal ended."""
    service = "navigate"

    def __init__(self, goals: np.ndarray, timeout_s: float, *, robot: str, start_s: float = START_S,
                 settle_s: float = SETTLE_S):
        self.goals, self.timeout_ns = np.asarray(goals, float).reshape(-1, 3), round(timeout_s * NS_PER_S)
        self.start_ns, self.settle_ns = round(start_s * NS_PER_S), round(settle_s * NS_PER_S)
        super().__init__(robot=robot)

    def setup(self) -> None:
        self.goal_pub = self.publisher("goal")
        self.cancel_pub = self.publisher("cancel")
        self.subscribe("sim/clock", self.on_clock)
        self.subscribe("nav_status", self.on_status, synced=False)
        self.next_goal = 0
        self.active: str | None = None
        self.sent_ns = self.cancel_ns = self.ended_ns = None
        self.outcomes: dict[str, str] = {}     # goal_id -> final status, or "timeout"
        self.finished = False

    def holds_lockstep(self) -> bool:
        return self.finished

    def on_status(self, msg: NavStatus) -> None:
        if msg.goal_id == self.active and msg.status in TERMINAL:
            self._end(msg.status if self.cancel_ns is None else "timeout")

    def _end(self, outcome: str) -> None:
        self.outcomes[self.active] = outcome
        self.active, self.cancel_ns = None, None
        if outcome != "succeeded":
            self.next_goal = len(self.goals)
        if self.next_goal >= len(self.goals):
            self.ended_ns = self.now_ns

    def on_clock(self, _clock: Clock) -> None:
        now = self.now_ns
        if self.ended_ns is not None:
            self.finished = now >= self.ended_ns + self.settle_ns
        elif self.active is None and now >= self.start_ns:
            x, y, yaw = (float(v) for v in self.goals[self.next_goal])
            self.next_goal += 1
            self.active, self.sent_ns = f"g{self.next_goal}", now
            self.goal_pub.publish(Goal(header=self.header("map"), goal_id=self.active, pose=Pose2D(x, y, yaw)))
        elif self.active is not None and self.cancel_ns is None and now - self.sent_ns >= self.timeout_ns:
            self.cancel_ns = now
            self.cancel_pub.publish(CancelGoal(header=self.header("map"), goal_id=self.active))
        elif self.cancel_ns is not None and now - self.cancel_ns >= round(CANCEL_WAIT_S * NS_PER_S):
            self._end("timeout")       # the navigator never confirmed the cancel


@dataclass
class LockstepRun:
    summary: MissionSummary
    outcomes: dict[str, str]        # goal_id -> final status or "timeout"
    sim_s: float
    nodes: dict[str, Node]          # by instance name: their counters, the sim's state


def mission_nodes(services: list[dict], robot: str, progress: Callable[[str], None] | None = None) -> dict[str, Node]:
    """The Nodes of a compose mapping's services (the recorder left out: the runner records),
    with the parameters `omninav up` would give them; `progress` hears of each as it is built
    (a node's setup loads maps and compiles its kernels: seconds each)."""
    wanted = [s for s in services if s["service"] != "recorder"]
    nodes = {}
    for k, s in enumerate(wanted):
        if progress is not None:
            progress(f"starting {s['name']} ({k + 1}/{len(wanted)})")
        nodes[s["name"]] = build_node(s["service"], s.get("params_file"), s.get("params") or {}, robot, s["name"])
    return nodes


def run_mission(services: list[dict], world: World, goals: np.ndarray, *, timeout_s: float, robot: str = "r1",
                recording: Path | None = None, max_sim_s: float | None = None,
                watch: Callable[[str, bytes, int], None] | None = None,
                progress: Callable[[str], None] | None = None, until: Callable[[], bool] | None = None,
                meter: CpuMeter | None = None,
                after_step: Callable[[dict[str, Node]], None] | None = None) -> LockstepRun:
    """Drive the goals through the stack in lockstep and score the mission against the truth.

    max_sim_s bounds the whole run (default: every goal's timeout, the cancels and the settling);
    `watch` sees every published (key, payload, stamp_ns), as InProcessRunner.tap does; `progress`
    hears of each service as it starts; `until` ends the run early once it turns true (a benchmark
    that judges arrival itself); `meter` is charged with the CPU time of each service's work
    (InProcessRunner: `omninav bench cpu`); `after_step` is handed the mission's nodes by name after
    every step (a test that shoves the simulated robot).
    """
    nodes = mission_nodes(services, robot, progress)
    sequencer = GoalSequencer(goals, timeout_s, robot=robot)
    runner = InProcessRunner([*nodes.values(), sequencer], meter)
    collector = MissionCollector(robot)
    runner.watch(collector.keys, collector.add_message)
    if watch is not None:
        runner.tap(watch)
    writer = RecordingWriter(recording) if recording is not None else None
    if writer is not None:
        runner.record(writer)
    sim = nodes["sim"]
    limit_s = max_sim_s or START_S + len(goals) * (timeout_s + CANCEL_WAIT_S) + SETTLE_S
    try:
        def done() -> bool:
            if after_step is not None:
                after_step(nodes)
            return sequencer.finished or (until is not None and until())
        runner.run_until(done, math.ceil(limit_s / sim.params.dt))
        runner.close()
    finally:
        if writer is not None:
            writer.close()
    navigator = nodes.get("navigator")
    summary = summarize_mission(collector.record(str(recording or "in-process run")), world,
                                goals_total=len(goals), recording=str(recording or ""),
                                goal_tolerance_m=navigator.params.xy_goal_tolerance if navigator else None)
    return LockstepRun(summary, dict(sequencer.outcomes), sim.now_ns / NS_PER_S, nodes)
