"""`omninav bench amcl`: one full filter update (motion + likelihood-field weighing + resampling).

The robot stands in the main corridor of the Willow Garage map (the `willow` world, built on
shared/data/maps/willow-full-0.05.yaml); a 60-beam scan is cast there once. For each particle
count N the filter is set up with min_particles = max_particles = N (the KLD pass still runs, but
keeps N), resample_interval 1 and laser_max_beams 60; every repeat starts from a fresh Gaussian
cloud (0.2 m, 0.2 m, 0.1 rad) around the true pose — one untimed update to start the filter — then
times one update whose odometry has moved 0.25 m, so motion, weighing and resampling all run.

The reference, timed in the same run on the same clouds: the same likelihood-field weighing written
as plain vectorised numpy over an (N, beams) array. Its result is checked against the kernel's.
The numba warm-up (compiling, or loading the cache) is done and timed before anything is measured.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

import numpy as np

from ..sim.lidar import LidarParams, scan
from ..sim.world import WorldError, load_world, world_path
from ..services.localizer.filter import Amcl, warm_up
from ..services.localizer.params import AmclParams
from ..services.localizer.reference import likelihood_field_numpy
from ..services.localizer.sensor import prepare_scan

COUNTS = (500, 2000, 10000)
BEAMS = 60
SPREAD = (0.2, 0.2, 0.1)
STEP = 0.25          # m of odometry per timed update (> update_min_d)
_AIM_MS_2000 = 2.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=50, help="timed updates per particle count (default 50)")
    parser.add_argument("--world", default="willow", help="world (with a map) to localize in (default willow)")


def _measure(world, count: int, repeats: int) -> dict:
    params = AmclParams(min_particles=count, max_particles=count, resample_interval=1, laser_max_beams=BEAMS,
                        laser_model_type="likelihood_field", odom_model_type="diff-corrected",
                        odom_alpha1=0.05, odom_alpha2=0.05, odom_alpha3=0.05, odom_alpha4=0.05)
    truth = np.asarray(world.robot.start, np.float64)
    lidar = LidarParams(beams=BEAMS, range_max=12.0, noise_std=0.01)
    rng = np.random.default_rng(count)
    ranges = scan(world, truth, None, lidar, rng)
    beams = prepare_scan(ranges, lidar.angle_min, lidar.angle_increment, lidar.range_min, lidar.range_max, params)
    amcl = Amcl(params, world.grid, np.random.default_rng(count + 1))
    cloud = np.diag(np.square(SPREAD))
    updates, sensor_kernel, sensor_numpy, worst = [], [], [], 0.0
    for _ in range(repeats):
        amcl.set_initial_pose(truth, cloud)
        amcl.update(np.zeros(3), beams)                       # starts the filter: not timed
        start = time.perf_counter()
        updated = amcl.update(np.array([STEP, 0.0, 0.0]), beams)
        updates.append(time.perf_counter() - start)
        if not updated:
            raise RuntimeError("the timed update did not run")
        # the sensor step alone, numba kernel and numpy reference, on the same particles
        poses, weights = amcl.poses.copy(), np.ones(amcl.n)
        start = time.perf_counter()
        amcl.laser.weigh(poses, amcl.n, beams, weights)
        sensor_kernel.append(time.perf_counter() - start)
        start = time.perf_counter()
        reference = likelihood_field_numpy(amcl.laser, poses, beams)
        sensor_numpy.append(time.perf_counter() - start)
        worst = max(worst, float(np.max(np.abs(reference - weights) / reference)))
    used = int(np.count_nonzero(beams.ranges < beams.range_max))
    median = statistics.median(updates)
    return {"median_ms": round(median * 1e3, 4),
            "us_per_particle_beam": round(median * 1e6 / (count * BEAMS), 5),
            "sensor_median_ms": round(statistics.median(sensor_kernel) * 1e3, 4),
            "numpy_sensor_median_ms": round(statistics.median(sensor_numpy) * 1e3, 4),
            "sensor_speedup_vs_numpy": round(statistics.median(sensor_numpy) / statistics.median(sensor_kernel), 1),
            "max_relative_difference_vs_numpy": worst,
            "beams": BEAMS, "beams_with_return": used, "repeats": repeats}


def main(args: argparse.Namespace) -> int:
    if args.repeats < 1:
        print("--repeats must be positive", file=sys.stderr)
        return 2
    try:
        world = load_world(world_path(args.world))
    except WorldError as exc:
        print(f"omninav bench amcl: {exc}", file=sys.stderr)
        return 2
    if world.grid is None:
        print(f"omninav bench amcl: world {args.world!r} has no map", file=sys.stderr)
        return 2
    start = time.perf_counter()
    warm_up()
    warm = time.perf_counter() - start
    print(f"numba warm-up (compile or load the cache, not in any timing): {warm:.2f} s",
          file=sys.stderr if args.json else sys.stdout)
    figures = {str(count): _measure(world, count, args.repeats) for count in COUNTS}
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"amcl full update (motion + likelihood field + KLD/low-variance resampling), {BEAMS} beams, "
          f"world {world.name}, median of {args.repeats}:")
    for count, f in figures.items():
        print(f"  {int(count):>6} particles: {f['median_ms']:8.3f} ms  {f['us_per_particle_beam']:.4f} µs/particle-beam"
              f"   sensor {f['sensor_median_ms']:.3f} ms vs numpy {f['numpy_sensor_median_ms']:.3f} ms "
              f"({f['sensor_speedup_vs_numpy']}×)")
    print(f"aim: ≤ {_AIM_MS_2000} ms at 2000 particles × {BEAMS} beams (Beluga's C++ reference: about 1 ms)")
    return 0
