"""omninav report: a synthetic recording (truth, odom, follower, scans, movers, sim diagnostic)
drawn into a PNG, the summary figures checked against the motion, bad files refused clearly."""
import numpy as np
import pytest

from omninav.cli.main import main
from omninav.cli.report import in_world_frame, load_run, report_figure, scan_points, summarize, title_of
from omninav.schemas import encode
from omninav.schemas.messages import (Costmap, Diagnostic, Goal, Header, LaserScan, MapMetaData, NavStatus, Obstacles,
                                      OccupancyGrid, Odometry, Path, Pose2D, PoseWithCovariance)
from omninav.services.recorder.mcap_io import RecordingWriter, read_records
from omninav.geometry.se2 import integrate
from omninav.sim.lidar import LidarParams, make_scan, scan
from omninav.sim.world import load_world, world_path

from conftest import SHARED_DATA

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
DT, SECONDS = 0.01, 6.0
TRUE_TWIST, ODOM_TWIST = np.array([0.5, 0.0, 0.2]), np.array([0.5, 0.0, 0.21])   # odometry over-turns
START = np.array([1.2, 1.0, 0.0])


def odometry(t_ns, frame, pose, seq):
    return Odometry(header=Header(stamp_ns=t_ns, frame_id=frame, seq=seq), pose=Pose2D(*map(float, pose)))


def write_run(path, *, world="room", diagnostic=True, collisions=2, truth=True):
    steps = round(SECONDS / DT)
    times = np.arange(steps + 1) * DT
    true_poses = integrate(START, TRUE_TWIST, times)
    odom_poses = integrate(np.zeros(3), ODOM_TWIST, times)
    follower_poses = integrate(np.zeros(3), TRUE_TWIST * 1.01, times)
    world_obj = load_world(world_path(world))
    lidar = LidarParams(noise_std=0.0)
    with RecordingWriter(path) as writer:
        for k, t in enumerate(times):
            t_ns = round(t * 1e9)
            tracks = [("omninav/r1/odom", "odom", odom_poses), ("omninav/r1/odom_follower", "odom", follower_poses)]
            for key, frame, poses in tracks + ([("omninav/sim/r1/truth", "world", true_poses)] if truth else []):
                writer.write(key, "Odometry", encode(odometry(t_ns, frame, poses[k], k + 1)), k + 1, t_ns, t_ns)
            mover = np.array([[6.0 + np.cos(t), 4.0 + np.sin(t), 0.3]])
            writer.write("omninav/sim/movers", "Obstacles",
                         encode(Obstacles(header=Header(stamp_ns=t_ns, seq=k + 1), circles=mover,
                                          velocities=np.zeros((1, 2)))), k + 1, t_ns, t_ns)
            if k % 50 == 0:
                msg = make_scan(lidar, scan(world_obj, true_poses[k], mover, lidar, None), t_ns)
                msg.header.seq = k // 50 + 1
                writer.write("omninav/r1/scan", "LaserScan", encode(msg), msg.header.seq, t_ns, t_ns)
            if diagnostic and k % 100 == 0:
                diag = Diagnostic(header=Header(stamp_ns=t_ns, seq=k // 100 + 1), name="sim",
                                  values={"world": str(world_path(world)), "collisions": collisions if k else 0,
                                          "drive": "mecanum", "min_clearance_m": 0.4})
                writer.write("omninav/r1/diagnostics/sim", "Diagnostic", encode(diag), diag.header.seq, t_ns, t_ns)
    return true_poses, odom_poses


def is_png(path):
    data = path.read_bytes()
    return data[:8] == PNG_MAGIC and len(data) > 10_000


def test_the_report_draws_a_run_and_sums_it_up(tmp_path, capsys):
    recording = tmp_path / "run.mcap"
    true_poses, odom_poses = write_run(recording)
    out = tmp_path / "pictures" / "run.png"
    assert main(["report", str(recording), "-o", str(out)]) == 0
    assert is_png(out)
    printed = capsys.readouterr().out
    assert "room" in printed and "2 collisions" in printed and "6.0 s" in printed

    run = load_run(recording)
    summary = summarize(run)
    # the aligned odometry starts on the truth, so it ends where its own twist takes the true start
    expected_end = integrate(START, ODOM_TWIST, SECONDS)
    assert np.allclose(in_world_frame(run.odom, run.truth).poses[-1], expected_end, atol=1e-9)
    assert summary.odom_error_m == pytest.approx(np.hypot(*(expected_end[:2] - true_poses[-1][:2])), rel=1e-9)
    assert summary.odom_heading_error_rad == pytest.approx(0.01 * SECONDS, rel=1e-6)
    assert summary.distance_m == pytest.approx(0.5 * SECONDS, rel=1e-4)
    assert summary.collisions == 2 and summary.duration_s == pytest.approx(SECONDS)
    assert len(run.scans) == 13 and run.mover_circles.shape == (len(true_poses), 1, 3)


def test_without_a_world_only_the_data_is_drawn(tmp_path, capsys):
    recording = tmp_path / "run.mcap"
    write_run(recording, diagnostic=False)
    out = tmp_path / "run.png"
    assert main(["report", str(recording), "-o", str(out)]) == 0
    assert is_png(out)
    captured = capsys.readouterr()
    assert "drawing only the data" in captured.err and "collisions: unknown" in captured.out


def test_a_recording_without_truth_is_drawn_from_its_odometry(tmp_path, capsys):
    recording = tmp_path / "robot.mcap"
    write_run(recording, diagnostic=False, truth=False)
    out = tmp_path / "robot.png"
    assert main(["report", str(recording), "-o", str(out)]) == 0
    assert is_png(out)
    summary = summarize(load_run(recording))
    assert summary.odom_error_m is None and summary.distance_m == pytest.approx(0.5 * SECONDS, rel=1e-4)


@pytest.mark.skipif(not (SHARED_DATA / "maps" / "willow-full-0.05.yaml").is_file(), reason="shared map data absent")
def test_a_map_world_is_drawn_from_its_grid(tmp_path):
    recording = tmp_path / "run.mcap"
    write_run(recording, diagnostic=False)
    out = tmp_path / "willow.png"
    assert main(["report", str(recording), "-o", str(out), "--world", "willow"]) == 0
    assert is_png(out)


def test_missing_damaged_and_wrong_inputs_fail_clearly(tmp_path, capsys):
    out = tmp_path / "x.png"
    assert main(["report", str(tmp_path / "nosuch.mcap"), "-o", str(out)]) == 2
    assert "nosuch.mcap: no such recording" in capsys.readouterr().err

    recording = tmp_path / "run.mcap"
    write_run(recording)
    data = recording.read_bytes()
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(data[: len(data) // 2])
    assert main(["report", str(damaged), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not a readable MCAP recording" in err and f"omninav recover {damaged}" in err
    assert damaged.read_bytes() == data[: len(data) // 2]          # the recording is left as it was

    assert main(["report", str(recording), "-o", str(out), "--world", str(tmp_path / "none.yaml")]) == 2
    assert "--world" in capsys.readouterr().err
    assert main(["report", str(recording), "-o", str(recording)]) == 2
    assert "is the recording itself" in capsys.readouterr().err
    assert main(["report", str(recording), "-o", str(out), "--robot", "r2"]) == 2
    assert "nothing to draw for robot 'r2'" in capsys.readouterr().err
    assert not out.exists()


def test_a_navigation_run_brings_its_map_costmap_plans_and_goals(tmp_path):
    recording = tmp_path / "nav.mcap"
    info = MapMetaData(resolution=0.05, width=200, height=160, origin=Pose2D(0.0, 0.0, 0.0))
    costs = np.zeros((160, 200), np.uint8)
    costs[40:60, 40:60] = 254
    with RecordingWriter(recording) as writer:
        def put(key, msg, t_s):
            msg.header.stamp_ns, msg.header.seq = round(t_s * 1e9), 1
            writer.write(key, type(msg).__name__, encode(msg), 1, msg.header.stamp_ns, msg.header.stamp_ns)
        put("omninav/r1/map", OccupancyGrid(info=info, data=np.zeros((160, 200), np.int8)), 0.5)
        put("omninav/r1/costmap/global", Costmap(info=info, data=costs), 1.0)
        put("omninav/r1/goal", Goal(goal_id="g1", pose=Pose2D(4.0, 2.0, 1.0)), 1.0)
        put("omninav/r1/plan", Path(goal_id="g1#1", poses=np.zeros((0, 3)), error="no_path: x"), 1.2)
        put("omninav/r1/plan", Path(goal_id="g1#2", poses=np.array([[1.2, 1.0, 0.0], [4.0, 2.0, 1.0]])), 1.5)
    run = load_run(recording)
    assert run.map.info.width == 200 and run.costmap.data.max() == 254
    assert [p.goal_id for p in run.plans] == ["g1#2"] and run.goals[0].goal_id == "g1"    # failed plans left out
    out = tmp_path / "nav.png"
    report_figure(run, load_world(world_path("room")), "room").savefig(out)
    assert out.read_bytes()[:8] == PNG_MAGIC


def test_the_localizer_estimate_is_drawn_and_the_title_gives_the_missions_sim_time(tmp_path, capsys):
    """Goals sent at 2 s, the last ended at 5 s: the mission is 3 s of sim time in a 6 s recording; the
    localizer's poses (0.1 m beside the truth at the end) are drawn as a path with a final pose."""
    recording = tmp_path / "nav.mcap"
    true_poses, _ = write_run(recording)
    steps = len(true_poses)
    with RecordingWriter(tmp_path / "mission.mcap") as writer:
        for record in read_records(recording):
            writer.write_record(record)

        def put(key, msg, t_s, seq=1):
            msg.header.stamp_ns, msg.header.seq = round(t_s * 1e9), seq
            writer.write(key, type(msg).__name__, encode(msg), seq, msg.header.stamp_ns, msg.header.stamp_ns)
        for k in range(0, steps, 10):
            x, y, theta = true_poses[k]
            put("omninav/r1/pose", PoseWithCovariance(pose=Pose2D(x + 0.1 * k / (steps - 1), y, theta)), k * DT, k + 1)
        put("omninav/r1/goal", Goal(goal_id="g1", pose=Pose2D(2.0, 2.0, 0.0)), 2.0)
        put("omninav/r1/goal", Goal(goal_id="g2", pose=Pose2D(3.0, 2.0, 0.0)), 3.0, 2)
        put("omninav/r1/nav_status", NavStatus(goal_id="g1", status="succeeded"), 3.0)
        put("omninav/r1/nav_status", NavStatus(goal_id="g2", status="active"), 3.5, 2)
        put("omninav/r1/nav_status", NavStatus(goal_id="g2", status="succeeded"), 5.0, 3)
    run = load_run(tmp_path / "mission.mcap")
    summary = summarize(run)
    assert summary.mission and summary.duration_s == pytest.approx(3.0) and summary.start_s == pytest.approx(2.0)
    assert summary.estimate_error_m == pytest.approx(0.1, abs=1e-6)
    assert title_of(summary, "room").startswith("room | mission 3.0 s of sim time (from t = 2.0 s)")
    assert "final localizer error 0.100 m" in title_of(summary, "room")
    assert len(run.estimate) == len(range(0, steps, 10))
    fig = report_figure(run, load_world(world_path("room")), "room")
    labels = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    assert "localizer estimate" in labels and "localizer's final pose" in labels
    assert main(["report", str(tmp_path / "mission.mcap"), "-o", str(tmp_path / "mission.png")]) == 0
    assert "mission 3.0 s of sim time" in capsys.readouterr().out
    # without goals the title says it is the recording's span
    assert title_of(summarize(load_run(recording)), "room").startswith("room | recording 6.0 s of sim time")


def test_scan_readings_beyond_range_max_are_not_drawn():
    msg = LaserScan(header=Header(frame_id="laser"), angle_min=0.0, angle_max=0.3, angle_increment=0.1,
                    range_min=0.2, range_max=4.0, ranges=np.array([1.0, 4.0, 12.0, 0.1], np.float32))
    points = scan_points(msg, np.zeros(3), LidarParams(mount_x=0.0, mount_y=0.0, mount_yaw=0.0))
    assert np.allclose(np.hypot(points[:, 0], points[:, 1]), [1.0, 4.0])
