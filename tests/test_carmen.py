"""The CARMEN log parser on every line type it reads, on damaged lines, and `omninav import carmen`."""
import math

import numpy as np
import pytest

from omninav.cli.main import main as omninav
from omninav.schemas.codec import decode
from omninav.schemas.keys import KeyLayout
from omninav.services.importers.carmen import CarmenError, parse_lines, read_log, stamp_ns
from omninav.services.recorder.mcap_io import read_records

TAIL = "1134864629.895182 b21 0.086295"


def flaser(kind="FLASER", n=361, t="1134864629.895182", pose="1.0 2.0 0.5", odom=None):
    ranges = ["1.50"] * (n - 2) + ["81.91", "0.00"]
    return f"{kind} {n} {' '.join(ranges)} {pose} {odom or pose} {t} b21 0.086295"


def test_flaser_is_a_180_degree_scan_with_the_odometry_of_its_stamp():
    log = parse_lines([flaser()])
    (item,) = log.scans
    scan = item.scan
    assert item.line_type == "FLASER" and item.laser == 1 and item.line_number == 1
    assert scan.header.stamp_ns == 1134864629895182000 and scan.header.frame_id == "laser"
    assert scan.angle_min == pytest.approx(-math.pi / 2) and scan.angle_max == pytest.approx(math.pi / 2)
    assert scan.angle_increment == pytest.approx(math.radians(0.5))
    assert len(scan.ranges) == 361 and scan.ranges[0] == pytest.approx(1.5)
    assert scan.ranges[-2] == np.inf and np.isnan(scan.ranges[-1]), "81.91 is no return, 0 no measurement"
    assert np.allclose(item.robot_pose, [1.0, 2.0, 0.5]) and np.allclose(item.laser_offset, 0.0)
    (odom,) = log.odometry
    assert odom.header.stamp_ns == scan.header.stamp_ns
    assert (odom.pose.x, odom.pose.y, odom.pose.theta) == (1.0, 2.0, 0.5)


def test_rlaser_is_the_rear_laser_and_its_offset_comes_from_the_two_poses():
    line = flaser("RLASER", n=181, pose="0.8 2.0 3.64159", odom="1.0 2.0 0.5")
    (item,) = parse_lines([line]).scans
    assert item.laser == 2 and item.scan.header.frame_id == "rear_laser"
    assert item.scan.angle_increment == pytest.approx(math.radians(1.0))
    dx, dy, dyaw = item.laser_offset
    assert abs(dyaw) == pytest.approx(math.pi, abs=1e-5)
    assert np.hypot(dx, dy) == pytest.approx(0.2, abs=1e-6)


def test_odom_lines_carry_the_velocities():
    log = parse_lines([f"ODOM 1.0 2.0 0.5 0.3 0.1 0.0 {TAIL}"])
    (odom,) = log.odometry
    assert odom.header.stamp_ns == 1134864629895182000
    assert (odom.pose.x, odom.twist.linear_x, odom.twist.angular_z) == (1.0, 0.3, 0.1)
    assert not log.scans


def test_rawlaser_states_its_own_geometry_and_remissions():
    ranges = " ".join(["2.0"] * 4)
    line = f"RAWLASER3 0 -2.356 4.712 0.5 30.0 0.01 0 5 {ranges} 30.0 5 1 2 3 4 5 {TAIL}"
    (item,) = parse_lines([line]).scans
    scan = item.scan
    assert item.laser == 3 and item.robot_pose is None
    assert (scan.angle_min, scan.angle_increment, scan.range_max) == (-2.356, 0.5, 30.0)
    assert scan.angle_max == pytest.approx(-2.356 + 4 * 0.5)
    assert list(scan.ranges[:4]) == [2.0] * 4 and scan.ranges[4] == np.inf
    assert list(scan.intensities) == [1, 2, 3, 4, 5]


def test_robotlaser_carries_both_poses():
    line = (f"ROBOTLASER1 0 -1.5708 3.1416 0.0174533 81.9 0.01 0 3 1.0 2.0 3.0 0 "
            f"1.2 2.0 0.0 1.0 2.0 0.0 0.3 0.0 0.5 0.3 0.2 {TAIL}")
    log = parse_lines([line])
    (item,) = log.scans
    assert item.laser == 1 and np.allclose(item.laser_offset, [0.2, 0.0, 0.0])
    assert len(item.scan.intensities) == 0, "no remissions: no intensities"
    assert len(log.odometry) == 1


def test_the_most_complete_line_type_of_a_laser_is_used():
    robotlaser = (f"ROBOTLASER1 0 -1.5708 3.1416 0.0174533 81.9 0.01 0 3 1.0 2.0 3.0 0 "
                  f"1.0 2.0 0.0 1.0 2.0 0.0 0 0 0 0 0 {TAIL}")
    log = parse_lines([flaser(), robotlaser, flaser("RLASER")])
    assert [s.line_type for s in log.laser_scans(1)] == ["ROBOTLASER1"]
    assert [s.line_type for s in log.laser_scans(2)] == ["RLASER"]
    assert log.laser_scans(4) == []


def test_comments_unknown_and_damaged_lines_are_counted_not_fatal():
    lines = ["# message formats defined: PARAM SYNC ODOM", "PARAM robot_front_laser_max 81.9 " + TAIL,
             "TRUEPOS 1 2 3 4 5 6 " + TAIL, flaser().rsplit(" ", 200)[0],          # cut short
             f"ODOM 1.0 two 0.5 0.3 0.1 0.0 {TAIL}", f"ODOM 1.0 2.0 0.5 0.3 0.1 0.0 {TAIL} extra",
             "ODOM 1.0 2.0 0.5 0.3 0.1 0.0 1134864629.89x5 b21 0.1", "", flaser(t="1134864630.1")]
    log = parse_lines(lines)
    assert log.comments == 1 and dict(log.skipped) == {"PARAM": 1, "TRUEPOS": 1}
    assert [number for number, _ in log.damaged] == [4, 5, 6, 7]
    assert "odom y 'two' is not a number" in log.damaged[1][1]
    assert "unexpected fields" in log.damaged[2][1] and "timestamp" in log.damaged[3][1]
    assert len(log.scans) == 1 and log.scans[0].line_number == 9


def test_stamps_are_converted_digit_by_digit():
    assert stamp_ns("1134864629.895182") == 1134864629895182000
    assert stamp_ns("12") == 12_000_000_000 and stamp_ns("0.0000000019") == 1


def test_a_missing_or_useless_file_is_a_clear_error(tmp_path):
    with pytest.raises(CarmenError, match="no such file"):
        read_log(tmp_path / "missing.clf")
    (tmp_path / "junk.clf").write_text("FLASER 3 1 2\n")
    with pytest.raises(CarmenError, match="line 1"):
        read_log(tmp_path / "junk.clf")


def test_import_carmen_writes_scans_and_odometry_to_mcap(tmp_path, capsys):
    log = tmp_path / "small.clf"
    log.write_text("\n".join([flaser(t="1134864629.9"), "ODOM 1.1 2.0 0.5 0.3 0.1 0.0 1134864630.0 b21 0.2",
                              flaser(t="1134864630.1"), "UNKNOWNTYPE 1 2 3"]) + "\n")
    out = tmp_path / "small.mcap"
    assert omninav(["import", "carmen", str(log), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "2 scans" in printed and "skipped 1 UNKNOWNTYPE" in printed
    keys = KeyLayout("r1")
    records = list(read_records(out))
    assert [r.key for r in records] == [keys.robot("scan"), keys.robot("odom"), keys.robot("odom"),
                                        keys.robot("scan"), keys.robot("odom")]
    assert [r.stamp_ns for r in records] == sorted(r.stamp_ns for r in records)
    scan = decode(records[0].payload, key=records[0].key)
    assert len(scan.ranges) == 361 and scan.header.seq == 0
    assert decode(records[3].payload).header.seq == 1
    # an existing recording is never overwritten by accident
    assert omninav(["import", "carmen", str(log), "-o", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert omninav(["import", "carmen", str(tmp_path / "nope.clf"), "-o", str(tmp_path / "x.mcap")]) == 2
    assert "no such file" in capsys.readouterr().err and not (tmp_path / "x.mcap").exists()
