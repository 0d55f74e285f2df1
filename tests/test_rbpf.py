"""The particle filter on a simulated loop through the room, and slam-eval on the real MIT CSAIL log."""
import json

import numpy as np
import pytest

from omninav.geometry.se2 import compose, relative
from omninav.services.slam.particle_grids import TILE
from omninav.services.slam.params import SlamParams
from omninav.services.slam.rbpf import Rbpf, _Nodes
from omninav.sim.lidar import LidarParams, scan
from omninav.sim.world import load_world, world_path

from conftest import SHARED_DATA

LIDAR = LidarParams(beams=360, range_max=12.0, noise_std=0.01)
CORNERS = np.array([(1.2, 1.0), (8.3, 1.0), (8.3, 3.2), (1.2, 3.2), (1.2, 1.0)])
FAST = dict(particles=5, linearUpdate=0.2, angularUpdate=0.2, maxUrange=11.0, srr=0.05, srt=0.1, str=0.05,
            stt=0.1, iterations=10, search_window=0.2, search_angle=0.2, lstep=0.05, astep=0.02, search_below=0.5)


def loop_poses(step=0.1):
    """Drive the rectangle CORNERS at `step` m per scan, turning on the spot at each corner."""
    poses = []
    for a, b in zip(CORNERS[:-1], CORNERS[1:]):
        heading = np.arctan2(*(b - a)[::-1])
        if poses and abs(relative(poses[-1], [*a, heading])[2]) > 1e-9:
            last = poses[-1][2]
            turn = relative([0, 0, last], [0, 0, heading])[2]
            for f in np.linspace(0, 1, int(abs(turn) / 0.15) + 2)[1:]:
                poses.append(np.array([*a, last + f * turn]))
        n = int(np.ceil(np.linalg.norm(b - a) / step))
        poses += [np.array([*(a + (b - a) * k / n), heading]) for k in range(n + 1)]
    return np.array(poses)


@pytest.fixture(scope="module")
def loop():
    """Truth, drifting odometry (3 % long, 0.03 rad/m heading bias, noise) and scans."""
    world = load_world(world_path("room"))
    rng = np.random.default_rng(5)
    truth = loop_poses()
    odom = [truth[0].copy()]
    for a, b in zip(truth[:-1], truth[1:]):
        move = relative(a, b)
        dist = np.hypot(move[0], move[1])
        noisy = move * [1.03, 1.03, 1.0] + [0.0, 0.0, 0.03 * dist] + rng.normal(0, [0.003, 0.003, 0.002])
        odom.append(compose(odom[-1], noisy))
    scans = [scan(world, pose, None, LIDAR, rng) for pose in truth]
    return truth, np.array(odom), scans


def run(data, **overrides):
    truth, odom, scans = data
    slam = Rbpf(SlamParams(**{**FAST, **overrides}), LIDAR.angles(), LIDAR.range_max, LIDAR.range_min)
    updates = [slam.process(k * 100_000_000, odom[k], ranges) for k, ranges in enumerate(scans)]
    return slam, updates


def pose_errors(truth, estimate):
    """Position error of each pose after putting both trajectories' first poses on each other."""
    aligned = compose(truth[0], relative(estimate[0], estimate))
    return np.hypot(*(aligned[:, :2] - truth[:, :2]).T)


def test_the_filter_keeps_the_loop_closed_where_odometry_drifts(loop):
    truth, odom, _ = loop
    slam, _ = run(loop)
    indices, poses = slam.trajectory()
    slam_error = pose_errors(truth[indices], poses)
    odom_error = pose_errors(truth, odom)
    assert odom_error.max() > 1.0, "the test needs odometry that drifts"
    assert slam_error.max() < 0.08 and slam_error[-1] < 0.05


def test_scans_are_processed_only_after_the_robot_moved_or_turned_enough(loop):
    _, _, scans = loop
    params = SlamParams(**{**FAST, "linearUpdate": 0.5, "angularUpdate": 0.3})
    slam = Rbpf(params, LIDAR.angles(), LIDAR.range_max)
    start = np.array([1.2, 1.0, 0.0])
    assert slam.process(0, start, scans[0]) is not None, "the first scan starts the map"
    assert slam.process(1, start + [0.3, 0, 0], scans[0]) is None
    assert slam.process(2, start + [0.49, 0, 0], scans[0]) is None
    assert slam.process(3, start + [0.5, 0, 0], scans[0]) is not None
    assert slam.process(4, start + [0.5, 0, 0.2], scans[0]) is None
    assert slam.process(5, start + [0.5, 0, 0.31], scans[0]) is not None
    assert slam.updates == 3 and slam.scan_count == 6
    timed = Rbpf(SlamParams(**{**FAST, "temporalUpdate": 1.0}), LIDAR.angles(), LIDAR.range_max)
    timed.process(0, start, scans[0])
    assert timed.process(900_000_000, start, scans[0]) is None
    assert timed.process(1_000_000_000, start, scans[0]) is not None


def test_resampling_happens_when_the_effective_sample_size_falls(loop):
    short = (loop[0][:40], loop[1][:40], loop[2][:40])
    never, updates = run(short, resampleThreshold=0.0)
    assert never.resamples == 0 and not any(u.resampled for u in updates if u)
    always, updates = run(short, resampleThreshold=1.0)
    neffs = [u.neff for u in updates[1:] if u]
    assert always.resamples == sum(n < always.n for n in neffs) > 0


def test_particles_share_the_map_tiles_they_have_not_changed(loop):
    # short beams: each scan writes a few of the room's tiles, as a scan does in a large building
    truth, odom, scans = loop
    short = (truth[:-1], odom[:-1], scans[:-1])
    slam, _ = run(short, particles=8, resampleThreshold=1.0, maxUrange=2.0)
    per_map = [np.count_nonzero(slam.grids.tables[i] >= 0) for i in range(slam.n)]
    assert slam.grids.tiles_in_use() < 0.75 * sum(per_map), "resampled particles share their tiles"
    assert slam.bytes_per_particle() < slam.grids.bytes_in_use() / 2
    before = slam.grids.tiles_in_use()
    slam.process(len(truth) * 100_000_000, odom[-1] + [0.0, 0.0, 0.5], scans[-1])  # surely an update
    side = int(np.ceil(2 * 2.0 / (TILE * slam.params.delta))) + 1  # tiles a 2 m scan can reach
    assert slam.grids.tiles_in_use() <= before + slam.n * side ** 2, "an update copies only what it writes"


def test_a_seed_gives_one_result_every_time(loop):
    first, _ = run(loop, seed=11)
    again, _ = run(loop, seed=11)
    other, _ = run(loop, seed=12)
    assert np.array_equal(first.trajectory()[1], again.trajectory()[1])
    assert not np.array_equal(first.trajectory()[1], other.trajectory()[1])


def test_the_odometry_prior_pulls_each_particle_towards_its_odometry_not_its_noisy_sample(loop):
    _, odom, scans = loop
    slam = Rbpf(SlamParams(**{**FAST, "translation_weight": 1e3, "rotation_weight": 1e3}), LIDAR.angles(),
                LIDAR.range_max, LIDAR.range_min)
    k = 0
    while slam.updates < 2:
        slam.process(k * 100_000_000, odom[k], scans[k])
        k += 1
    predicted = relative(odom[0], odom[k - 1])
    assert np.abs(slam.poses - predicted).max() < 1e-3, "every particle at the odometry's pose, noise or not"
    free, _ = run(loop)
    assert np.abs(free.trajectory()[1][1] - predicted).max() > 3e-3, "the scan alone would have moved it"


def test_scan_matching_mode_tracks_with_one_particle(loop):
    truth, _, _ = loop
    slam, _ = run(loop, mode="scan_matching")
    indices, poses = slam.trajectory()
    assert slam.n == 1 and slam.resamples == 0
    assert pose_errors(truth[indices], poses).max() < 0.1


CARMEN = SHARED_DATA / "carmen"


@pytest.mark.skipif(not (CARMEN / "mit-csail.clf").is_file(),
                    reason=f"the MIT CSAIL benchmark log is not in {CARMEN}")
def test_slam_eval_beats_raw_odometry_on_the_start_of_the_mit_csail_log(capsys):
    from omninav.cli.main import main as omninav

    code = omninav(["slam-eval", str(CARMEN / "mit-csail.clf"), "--relations", str(CARMEN / "mit-csail.relations"),
                    "--max-seconds", "80", "--set", "particles=4", "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["relations"] > 50
    assert result["trans_abs_mean_m"] < 0.75 * result["odometry"]["trans_abs_mean_m"]
    assert result["rot_abs_mean_deg"] < 0.75 * result["odometry"]["rot_abs_mean_deg"]
    for key in ("trans_abs_std_m", "trans_sq_mean", "rot_abs_std_deg", "rot_sq_mean"):
        assert key in result and key in result["odometry"]
    assert result["wall_s"] > 0 and result["realtime_factor"] > 0


@pytest.mark.skipif(not (CARMEN / "mit-csail.clf").is_file(),
                    reason=f"the MIT CSAIL benchmark log is not in {CARMEN}")
def test_slam_eval_runs_hector_without_odometry_on_the_start_of_the_mit_csail_log(capsys):
    from omninav.cli.main import main as omninav

    code = omninav(["slam-eval", str(CARMEN / "mit-csail.clf"), "--relations", str(CARMEN / "mit-csail.relations"),
                    "--max-seconds", "80", "--method", "hector", "--no-odometry", "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["method"] == "hector" and not result["odometry_guess"] and result["relations"] > 50
    assert result["trans_abs_mean_m"] < 0.75 * result["odometry"]["trans_abs_mean_m"]
    assert result["rot_abs_mean_deg"] < 0.25 * result["odometry"]["rot_abs_mean_deg"]


def test_the_trajectory_tree_drops_branches_no_particle_reaches():
    nodes = _Nodes(capacity=8)
    heads = np.full(3, -1, np.int64)
    expected = [[], [], []]  # each particle's history, kept by hand
    rng = np.random.default_rng(0)
    for k in range(200):
        poses = rng.normal(size=(3, 3))
        heads = nodes.add(heads, k, poses)
        expected = [history + [pose] for history, pose in zip(expected, poses)]
        if k % 3 == 0:  # a resampling: particle 0 survives, three times
            heads = heads[[0, 0, 0]]
            expected = [list(expected[0]) for _ in range(3)]
    for i in range(3):
        scans, poses = nodes.chain(int(heads[i]))
        assert np.array_equal(scans, np.arange(200)) and np.array_equal(poses, np.array(expected[i]))
    reachable = len({tuple(pose) for history in expected for pose in history})
    assert nodes.count <= 2 * reachable < 3 * 200, "dropped branches were reclaimed"


def test_the_map_to_odom_transform_carries_odometry_onto_the_estimate(loop):
    truth, odom, _ = loop
    slam, _ = run(loop)
    assert np.allclose(compose(slam.map_to_odom(), odom[-1]), slam.pose())


def test_slam_eval_names_what_is_wrong_with_its_input(tmp_path, capsys):
    from omninav.cli.main import main as omninav

    log, relations = tmp_path / "a.clf", tmp_path / "a.relations"
    ranges = " ".join(["2.0"] * 181)
    log.write_text("".join(f"FLASER 181 {ranges} {0.1 * k} 0 0 {0.1 * k} 0 0 {100 + k}.5 h 0.1\n" for k in range(5)))
    relations.write_text("100.5 101.5 0.1 0 0 0 0 0\n")
    assert omninav(["slam-eval", str(tmp_path / "missing.clf"), "--relations", str(relations)]) == 2
    assert "no such file" in capsys.readouterr().err
    assert omninav(["slam-eval", str(log), "--relations", str(relations), "--set", "particles=0"]) == 2
    assert "particles" in capsys.readouterr().err
    assert omninav(["slam-eval", str(log), "--relations", str(relations), "--set", "partcles=3"]) == 2
    assert "unknown parameter" in capsys.readouterr().err
    relations.write_text("900.5 901.5 0.1 0 0 0 0 0\n")
    assert omninav(["slam-eval", str(log), "--relations", str(relations)]) == 2
    assert "no relation" in capsys.readouterr().err
