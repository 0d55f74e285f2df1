"""`omninav bench sim [--json]`: how fast the simulator steps, and how far odometry drifts in it.

Speed: steps per second of `Simulation.step()` in the room, the warehouse (movers) and willow
(a real map: thousands of static boxes), median over repeats, beside the reference measured in
the same run — pymunk stepping an identical Space with nothing of ours around it. The robot
turns on the spot at its start and is timed after one full turn, when the minimum clearance is
set, so the figure is the common case; the cost of one exact clearance query and how many the
timed steps made are reported beside it (only a step that may set a new minimum pays one).
Times are this process's CPU time (time.process_time): the machine is shared, and other users'
load would otherwise count against whichever side ran while it peaked; both sides are
single-threaded, so CPU time is what they cost.

Drift: a mecanum robot with the default noise drives 60 s in an open 20 m × 20 m arena — two
figure-eights (1 m radius circles at 0.5 m/s), a strafe left and back, then stands still —
its commands shaped by the chassis's own limits (Kinematics.limit) every step, and wheel
odometry integrated by services.chassis.odometry from the sim's encoders, as the chassis runs
it. Reported: final and largest position (m) and heading (deg) error against the truth, median
over seeds; the follower-wheel odometry (followers + gyro) likewise.

Lidar: CPU ms of one scan of the Jackal profile's lidar (a Hokuyo UST-10LX: 1081 beams, range
noise, dropouts beyond its rated range) in BARN world 0 from the robot's start, median over
repeats, beside the reference in the same run: the same beams through the old sensor model (the
new effects off, constant noise only, which the tests hold byte-identical to the model before
them); and the profile's lidar as it was (541 beams at 10 Hz). Each also as CPU ms per sim second
at its rate.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..cli.profile import load_profile
from ..experiments.barn import PROFILE as BARN_PROFILE, SIM_DT as BARN_SIM_DT
from ..geometry.se2 import wrap_angle
from ..parameters.from_mapping import load_params
from ..services.chassis.follower_wheels import follower_odometry
from ..services.chassis.kinematics import ChassisParams, Kinematics
from ..services.chassis.odometry import wheel_odometry
from ..services.lidar.node import LidarNodeParams
from ..sim.body import BodyParams
from ..sim.lidar import LidarParams, scan
from ..sim.physics import SimParams, Simulation
from ..sim.world import World, WorldError, load_world, shared_data_dir, world_path

WORLDS = ("room", "warehouse", "willow")
SPIN = (0.0, 0.0, 0.5)                          # m/s, m/s, rad/s while measuring speed
CIRCLE_S = 4 * math.pi                          # one 1 m radius circle at 0.5 m/s
DRIFT_PATTERN = (                               # (seconds, twist) — 60 s in all
    (CIRCLE_S, (0.5, 0.0, 0.5)), (CIRCLE_S, (0.5, 0.0, -0.5)),
    (CIRCLE_S, (0.5, 0.0, 0.5)), (CIRCLE_S, (0.5, 0.0, -0.5)),
    (3.0, (0.0, 0.3, 0.0)), (3.0, (0.0, -0.3, 0.0)),
    (60.0 - 4 * CIRCLE_S - 6.0, (0.0, 0.0, 0.0)),
)
ARENA = "name: arena\nbounds: [20.0, 20.0]\nrobot: {start: [10.0, 10.0, 0.0], drive: mecanum}\n"
BARN_WORLD = Path("barn") / "worlds" / "world_0.world"     # in the shared data folder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--steps", type=int, default=1000, help="steps per timed repeat (default 1000)")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats per world (default 5)")
    parser.add_argument("--seeds", type=int, default=3, help="60 s drift runs, seeds 0..N-1 (default 3)")
    parser.add_argument("--scans", type=int, default=200, help="lidar scans per timed repeat (default 200)")


def step_rates(world: World, steps: int, repeats: int, params: SimParams = SimParams(),
               body: BodyParams = BodyParams()) -> tuple[float, float, float, float]:
    """Median steps/s of Simulation.step(), of the same simulation looking for contacts once a
    step (max_substep = dt: the physics before substeps) and of the bare pymunk Space of an
    identical simulation, and the exact clearance queries per 1000 timed steps."""
    sim = Simulation(world, params, body=body)
    once = Simulation(world, dataclasses.replace(params, max_substep=params.dt), body=body)
    bare = Simulation(world, params, body=body)
    for s in (sim, once):
        s.set_wheel_command(s.kinematics.ik(SPIN))
    dt = sim.params.dt
    for _ in range(round(2 * math.pi / SPIN[2] / dt) + 1):   # one full turn: the clearance minimum is set
        sim.step()
        once.step()
        bare.space.step(dt)
    queries_before = sim.clearance_queries
    ours, single, reference = [], [], []
    for _ in range(repeats):                    # interleaved, so load changes hit all alike
        for simulation, rates in ((sim, ours), (once, single)):
            start = time.process_time()
            for _ in range(steps):
                simulation.step()
            rates.append(steps / (time.process_time() - start))
        start = time.process_time()
        for _ in range(steps):
            bare.space.step(dt)
        reference.append(steps / (time.process_time() - start))
    queries = (sim.clearance_queries - queries_before) * 1000 / (steps * repeats)
    return statistics.median(ours), statistics.median(single), statistics.median(reference), queries


def clearance_query_ms(world: World, calls: int = 50) -> float:
    movers = world.movers.circles_at(0.0)
    world.footprint_clearance(world.robot.start, movers)
    times = []
    for _ in range(calls):
        start = time.process_time()
        world.footprint_clearance(world.robot.start, movers)
        times.append(time.process_time() - start)
    return statistics.median(times) * 1e3


def scan_costs(scans: int, repeats: int) -> dict:
    """Median CPU ms per scan of the Jackal's lidar, of the old sensor model on the same beams and
    of the Jackal's lidar as it was, and each one's rate (module docstring)."""
    world = load_world((shared_data_dir(Path(__file__)) or Path("shared/data")) / BARN_WORLD)
    ust = load_params(LidarNodeParams, load_profile("jackal").params["lidar"])
    old_model = LidarParams(beams=ust.beams, fov=ust.fov, range_min=ust.range_min, range_max=ust.range_max,
                            noise_std=ust.noise_std, rate_hz=ust.rate_hz)
    old_profile = LidarParams(beams=541, fov=ust.fov, range_min=0.06, range_max=30.0, noise_std=0.01)
    lidars = {"ust10lx": ust, "reference_old_model": old_model, "old_profile_541_beams": old_profile}
    rng = np.random.default_rng(0)
    for params in lidars.values():              # compile, or load the cached kernels
        scan(world, world.robot.start, None, params, rng)
    times: dict[str, list[float]] = {name: [] for name in lidars}
    for _ in range(repeats):                    # interleaved, so load changes hit all alike
        for name, params in lidars.items():
            start = time.process_time()
            for _ in range(scans):
                scan(world, world.robot.start, None, params, rng)
            times[name].append((time.process_time() - start) / scans * 1e3)
    return {name: {"beams": params.beams, "rate_hz": params.rate_hz,
                   "scan_ms": round(statistics.median(times[name]), 4),
                   "ms_per_sim_s": round(statistics.median(times[name]) * params.rate_hz, 3)}
            for name, params in lidars.items()}


def drift_run(world: World, seed: int) -> dict:
    """Drive DRIFT_PATTERN with the default noise; errors of wheel and follower odometry vs truth."""
    sim = Simulation(world, SimParams(seed=seed), ChassisParams(drive="mecanum"))
    kinematics = Kinematics(sim.chassis)
    step_ns = round(sim.params.dt * 1e9)
    odometers = {"wheel": wheel_odometry(sim.chassis, sim.pose), "follower": follower_odometry(sim.chassis, sim.pose)}
    odometers["wheel"].update(0, np.zeros(kinematics.n_wheels))
    odometers["follower"].update(0, np.zeros(2))
    worst = {name: [0.0, 0.0] for name in odometers}
    previous = np.zeros(3)
    for seconds, twist in DRIFT_PATTERN:
        for _ in range(round(seconds / sim.params.dt)):
            command = kinematics.limit(twist, previous, sim.params.dt)
            previous = command.twist
            sim.set_wheel_command(command.wheels)
            r = sim.step()
            readings = {"wheel": r.encoder_positions, "follower": r.follower_positions}
            for name, odometer in odometers.items():
                estimate = odometer.update(sim.steps * step_ns, readings[name], r.gyro_z)
                errors = _errors(estimate.pose, r.pose)
                worst[name] = [max(w, e) for w, e in zip(worst[name], errors)]
    return {name: {"final_m": _errors(odometer.pose, sim.pose)[0], "final_deg": _errors(odometer.pose, sim.pose)[1],
                   "max_m": worst[name][0], "max_deg": worst[name][1], "collisions": sim.collisions}
            for name, odometer in odometers.items()}


def _errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    return (float(np.hypot(*(estimate[:2] - truth[:2]))),
            float(np.degrees(abs(wrap_angle(estimate[2] - truth[2])))))


def barn_case() -> tuple[World, SimParams, BodyParams] | None:
    """BARN world 0 with the Jackal's body at BARN's step, as `bench barn` simulates it; None
    without the shared data."""
    data = shared_data_dir(Path(__file__))
    path = data / BARN_WORLD if data is not None else None
    if path is None or not path.is_file():
        return None
    body = load_params(BodyParams, load_profile(BARN_PROFILE).body, "jackal body")
    return load_world(path), SimParams(dt=BARN_SIM_DT, drive="diff"), body


def measure(steps: int, repeats: int, seeds: int, scans: int) -> dict:
    figures: dict = {"steps_per_s": {}, "one_check_steps_per_s": {}, "reference_steps_per_s": {},
                     "substeps": {}, "clearance_query_ms": {}, "clearance_queries_per_1000_steps": {}}
    cases = [(name, load_world(world_path(name)), SimParams(), BodyParams()) for name in WORLDS]
    barn = barn_case()
    if barn is not None:
        cases.append(("barn-0 jackal", *barn))
    for name, world, params, body in cases:
        ours, single, reference, queries = step_rates(world, steps, repeats, params, body)
        figures["steps_per_s"][name] = round(ours)
        figures["one_check_steps_per_s"][name] = round(single)
        figures["reference_steps_per_s"][name] = round(reference)
        figures["substeps"][name] = params.substeps
        figures["clearance_queries_per_1000_steps"][name] = round(queries, 1)
        figures["clearance_query_ms"][name] = round(clearance_query_ms(Simulation(world, params, body=body).world), 3)
    with tempfile.TemporaryDirectory() as folder:
        arena = Path(folder) / "arena.yaml"
        arena.write_text(ARENA)
        runs = [drift_run(load_world(arena), seed) for seed in range(seeds)]
    for name, prefix in (("wheel", "drift_60s"), ("follower", "follower_drift_60s")):
        for key, suffix in (("final_m", "m"), ("final_deg", "deg"), ("max_m", "max_m"), ("max_deg", "max_deg")):
            figures[f"{prefix}_{suffix}"] = round(statistics.median(run[name][key] for run in runs), 4)
    figures["lidar_barn_world_0"] = scan_costs(scans, repeats)
    figures["drift_collisions"] = sum(run["wheel"]["collisions"] for run in runs)
    figures["drift_seeds"] = seeds
    figures["sim_params"] = {k: getattr(SimParams(), k) for k in
                             ("dt", "wheel_slip_std", "encoder_noise_std", "encoder_ticks_per_rev",
                              "gyro_noise_std", "gyro_bias", "max_substep")}
    return figures


def report(fig: dict) -> str:
    lines = [f"{'world':15s}{'substeps':>9s}{'sim steps/s':>13s}{'one check/step':>16s}{'bare pymunk':>13s}"
             f"{'clearance query':>17s}{'queries/1000 steps':>20s}"]
    for name in fig["steps_per_s"]:
        lines.append(f"{name:15s}{fig['substeps'][name]:9d}{fig['steps_per_s'][name]:13d}"
                     f"{fig['one_check_steps_per_s'][name]:16d}{fig['reference_steps_per_s'][name]:13d}"
                     f"{fig['clearance_query_ms'][name]:14.3f} ms{fig['clearance_queries_per_1000_steps'][name]:20.1f}")
    lines += [
        "(robot turning on the spot at its start, after one full turn; medians; 'one check/step' is the",
        " same simulation looking for contacts once a step, as before substeps; the bare reference is",
        " one pymunk step of an identical space: no substeps, motors, noise, sensors or clearance tracking)",
        f"odometry drift after 60 s (figure-eights and a strafe, default noise, median of "
        f"{fig['drift_seeds']} seeds):",
        f"  wheel odometry:    final {fig['drift_60s_m']:.4f} m, {fig['drift_60s_deg']:.3f} deg; "
        f"max {fig['drift_60s_max_m']:.4f} m, {fig['drift_60s_max_deg']:.3f} deg",
        f"  follower + gyro:   final {fig['follower_drift_60s_m']:.4f} m, {fig['follower_drift_60s_deg']:.3f} deg; "
        f"max {fig['follower_drift_60s_max_m']:.4f} m, {fig['follower_drift_60s_max_deg']:.3f} deg",
        "  noise: " + ", ".join(f"{k} {v}" for k, v in fig["sim_params"].items()),
        "lidar scan in BARN world 0 from the robot's start (CPU ms, medians):",
    ]
    labels = {"ust10lx": "Jackal profile (UST-10LX model)", "reference_old_model": "the same beams, old model",
              "old_profile_541_beams": "Jackal profile as it was"}
    for name, row in fig["lidar_barn_world_0"].items():
        lines.append(f"  {labels[name]:33s}{row['beams']:5d} beams {row['scan_ms']:8.3f} ms/scan "
                     f"{row['ms_per_sim_s']:8.2f} ms per sim s at {row['rate_hz']:g} Hz")
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    if min(args.steps, args.repeats, args.seeds, args.scans) < 1:
        print("omninav bench sim: --steps, --repeats, --seeds and --scans must be at least 1", file=sys.stderr)
        return 2
    try:
        figures = measure(args.steps, args.repeats, args.seeds, args.scans)
    except WorldError as exc:                   # e.g. willow's map missing from the shared data folder
        print(f"omninav bench sim: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(figures) if args.json else report(figures), flush=True)
    return 0
