"""`omninav import FORMAT …`: convert other robots' logs into omninav MCAP recordings.

Each format is a subcommand (`carmen`, `rosbag`), so the
arguments of one format never constrain another's.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from ..experiments.progress import progress
from ..schemas.codec import encode
from ..schemas.keys import KeyLayout
from ..schemas.registry import type_info


def add_arguments(parser: argparse.ArgumentParser) -> None:
    formats = parser.add_subparsers(dest="format", required=True, metavar="FORMAT")
    carmen = formats.add_parser("carmen", help="a CARMEN log (FLASER, RLASER, ODOM, RAWLASER1-4, ROBOTLASER1)")
    carmen.add_argument("log", help="the CARMEN log file (.clf, .log)")
    carmen.add_argument("-o", "--output", required=True, help="the MCAP file to write")
    carmen.add_argument("--laser", type=int, choices=(1, 2, 3, 4), default=1,
                        help="which laser goes to the scan key: 1 front (FLASER, ROBOTLASER1, RAWLASER1), "
                             "2 rear (RLASER, ROBOTLASER2, RAWLASER2), 3, 4 (default 1)")
    carmen.add_argument("--robot", default="r1", help="robot namespace of the keys (default r1)")
    carmen.add_argument("--force", action="store_true", help="overwrite the output file if it exists")
    carmen.set_defaults(run=_main_carmen)
    bag = formats.add_parser("rosbag", help="a ROS 1 (.bag) or ROS 2 bag (folder; sqlite3 .db3 or MCAP, CDR): "
                                            "LaserScan and Odometry "
                                            "(needs pip install 'omninav[rosbag]')")
    bag.add_argument("bag", help="the ROS 1 .bag file, or the ROS 2 bag folder (with metadata.yaml)")
    bag.add_argument("-o", "--output", required=True, help="the MCAP file to write")
    bag.add_argument("--scan-topic", default=None,
                     help="sensor_msgs/LaserScan topic (default: the bag's one LaserScan topic)")
    bag.add_argument("--odom-topic", default=None,
                     help="nav_msgs/Odometry topic (default: the bag's one Odometry topic; without one, "
                          "odometry from /tf's odom -> base transforms)")
    bag.add_argument("--robot", default="r1", help="robot namespace of the keys (default r1)")
    bag.add_argument("--force", action="store_true", help="overwrite the output file if it exists")
    bag.set_defaults(run=_main_rosbag)


def main(args: argparse.Namespace) -> int:
    return args.run(args)


def _fail(message: str) -> int:
    print(f"omninav import: {message}", file=sys.stderr)
    return 2


def _write_recording(path: Path, messages: list[tuple[str, object]]) -> None:
    """(key, message) pairs in stamp order into a new MCAP file, replaced atomically so a failure
    never leaves half a recording where a whole one was expected."""
    from ..services.recorder.mcap_io import RecordingWriter

    tmp = path.with_name(f".{path.name}.part")
    seqs: dict[str, int] = {}
    try:
        writer = RecordingWriter(tmp, metadata={"source": "omninav import"})
        with progress(len(messages), "messages") as bar:
            for key, msg in messages:
                seqs[key] = seqs.get(key, -1) + 1
                msg.header.seq = seqs[key]
                stamp = msg.header.stamp_ns
                # log_time = the original stamp, so live replay keeps the log's pacing
                writer.write(key, type_info(type(msg))[0], encode(msg), seqs[key], stamp, stamp)
                bar.advance()
        writer.close()
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _main_carmen(args: argparse.Namespace) -> int:
    from ..services.importers.carmen import CarmenError, read_log

    output = Path(args.output)
    if output.exists() and not args.force:
        return _fail(f"{output} exists; pass --force to overwrite it")
    try:
        log = read_log(args.log)
        keys = KeyLayout(args.robot)
    except (CarmenError, ValueError) as exc:
        return _fail(str(exc))
    scans = log.laser_scans(args.laser)
    messages = [(keys.robot("scan"), s.scan) for s in scans] + [(keys.robot("odom"), o) for o in log.odometry]
    messages.sort(key=lambda item: item[1].header.stamp_ns)  # stable: a scan before odometry of its stamp
    try:
        _write_recording(output, messages)
    except OSError as exc:
        return _fail(f"{output}: {exc}")
    used = {s.line_type for s in scans}
    other = len(log.scans) - len(scans)
    print(f"{output}: {len(scans)} scans ({', '.join(sorted(used)) or 'none'}) on {keys.robot('scan')}, "
          f"{len(log.odometry)} odometry messages on {keys.robot('odom')}")
    if other:
        print(f"  {other} laser lines of other lasers or duplicate line types not written")
    offsets = [s.laser_offset for s in scans if s.laser_offset is not None]
    if offsets:
        x, y, yaw = offsets[0]
        print(f"  laser mounting in the robot frame (from the log): x={x:.3f} m, y={y:.3f} m, yaw={yaw:.4f} rad")
    for line_type, count in sorted(log.skipped.items()):
        print(f"  skipped {count} {line_type} lines")
    if log.damaged:
        print(f"  {len(log.damaged)} damaged lines skipped:")
        for number, what in log.damaged[:10]:
            print(f"    line {number}: {what}")
        if len(log.damaged) > 10:
            print(f"    ... and {len(log.damaged) - 10} more")
    return 0


def _main_rosbag(args: argparse.Namespace) -> int:
    from ..services.importers.rosbag import RosbagError, keyed_messages, read_bag

    output = Path(args.output)
    if output.exists() and not args.force:
        return _fail(f"{output} exists; pass --force to overwrite it")
    try:
        keys = KeyLayout(args.robot)
        contents = read_bag(args.bag, args.scan_topic, args.odom_topic)
    except (RosbagError, ValueError) as exc:
        return _fail(str(exc))
    try:
        _write_recording(output, keyed_messages(contents, keys))
    except OSError as exc:
        return _fail(f"{output}: {exc}")
    print(f"{output}: {len(contents.scans)} scans from {contents.scan_topic} on {keys.robot('scan')}, "
          f"{len(contents.odometry)} odometry messages from {contents.odom_source} on {keys.robot('odom')}")
    if contents.laser_pose is not None:
        x, y, yaw = contents.laser_pose
        print(f"  laser mounting in the robot frame (from the bag's tf): x={x:.3f} m, y={y:.3f} m, yaw={yaw:.4f} rad")
    for topic, count in sorted(contents.unstamped.items()):
        print(f"  {count} messages on {topic} had no header stamp: stamped with the bag's record time")
    other = sorted(t for t in contents.topics if t not in contents.used_topics)
    if other:
        print(f"  not converted: {', '.join(other)}")
    return 0
