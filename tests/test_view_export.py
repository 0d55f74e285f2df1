"""`omninav export --foxglove`: a recording in Foxglove's well-known schemas, read back channel by
channel with the mcap reader; the input stays as it was."""
import hashlib

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from omninav.cli.main import main as cli_main
from omninav.schemas.codec import decode, encode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Chatter, Header
from omninav.services.recorder.mcap_io import RecordingWriter, read_records

from view_fixtures import S, VIEW_CHANNELS, JsonDecoderFactory, stack_messages

ROUNDS = 5      # 0.5 s apart: the grids, unchanged, go out once


def write_recording(path) -> None:
    with RecordingWriter(path) as writer:
        for round_ in range(ROUNDS):
            stamp = round_ * S // 2
            for key, msg in stack_messages(stamp).items():
                writer.write(key, type(msg).__name__, encode(msg), round_ + 1, stamp, stamp)
            # not shown by the view: left out of the export
            chatter = Chatter(Header(stamp_ns=stamp), "hello")
            writer.write(KeyLayout("r1").resolve("chatter"), "Chatter", encode(chatter), round_ + 1, stamp, stamp)
        writer.write(KeyLayout("r1").resolve("scan"), "LaserScan", b"\x93not a scan", 99, stamp, stamp)


def read_export(path) -> dict[str, list]:
    """topic -> [(schema name, log_time, decoded message)], as a viewer reads the file."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            out.setdefault(channel.topic, []).append((schema.name, message.log_time, decoded))
    return out


def test_export_writes_every_view_channel_and_leaves_the_recording_alone(tmp_path, capsys):
    recording, exported = tmp_path / "run.mcap", tmp_path / "foxglove.mcap"
    write_recording(recording)
    before = hashlib.sha256(recording.read_bytes()).hexdigest()
    assert cli_main(["export", "--foxglove", str(recording), "-o", str(exported)]) == 0
    assert hashlib.sha256(recording.read_bytes()).hexdigest() == before
    report = capsys.readouterr().out
    assert "malformed/omninav/r1/scan" in report

    channels = read_export(exported)
    assert {topic: rows[0][0] for topic, rows in channels.items()} == VIEW_CHANNELS
    # grids once (unchanged), everything else every round; log time = sim stamp
    assert len(channels["/map"]) == len(channels["/costmap/global"]) == 1
    assert [t for _, t, _ in channels["/scan"]] == [r * S // 2 for r in range(ROUNDS)]
    assert len(channels["/tf"]) == 4 * ROUNDS      # world→map, map→odom, odom→base_link, base_link→laser
    grid = channels["/costmap/global"][0][2]
    assert (grid.column_count, grid.frame_id) == (4, "map") and set(grid.data) == {254}
    assert list(channels["/scan"][-1][2].ranges[:2]) == [1.0, 2.0]
    (mover,) = channels["/truth/movers"][0][2].entities[0].cylinders
    assert (mover.pose.position.x, mover.size.x) == (2.0, 0.6)
    (track,) = channels["/tracks"][0][2].entities
    assert (track.frame_id, track.cylinders[0].pose.position.x, track.arrows[0].shaft_length) == ("odom", 2.5, 0.8)
    assert np.allclose([p.position.x for p in channels["/plan"][0][2].poses], [0.0, 1.0])
    assert channels["/localizer/pose"][0][2].pose.position.y == 2.0
    assert channels["/diagnostics/costmap"][0][2]["values"] == {"received/scan": 3}


def test_export_refuses_to_overwrite_and_names_an_unreadable_recording(tmp_path, capsys):
    recording, exported = tmp_path / "run.mcap", tmp_path / "foxglove.mcap"
    write_recording(recording)
    exported.write_bytes(b"keep me")
    assert cli_main(["export", "--foxglove", str(recording), "-o", str(exported)]) == 2
    assert "exists" in capsys.readouterr().err and exported.read_bytes() == b"keep me"
    (tmp_path / "junk.mcap").write_bytes(b"junk")
    assert cli_main(["export", "--foxglove", str(tmp_path / "junk.mcap"), "-o", str(tmp_path / "out.mcap")]) == 2
    assert "not an MCAP file" in capsys.readouterr().err


@pytest.mark.parametrize("form, suffix", [("--foxglove", "mcap"), ("--rerun", "rrd")])
def test_a_bad_recording_leaves_no_export_behind(form, suffix, tmp_path, capsys):
    """The output is opened before the recording is read: a missing or junk recording must not leave
    a half-written file (both exports left one, and the next try was refused: 'exists')."""
    if form == "--rerun":
        pytest.importorskip("rerun")
    (tmp_path / "junk.mcap").write_bytes(b"junk")
    for source, says in ((tmp_path / "missing.mcap", "no such recording"), (tmp_path / "junk.mcap", "not an MCAP file")):
        out = tmp_path / f"out.{suffix}"
        assert cli_main(["export", form, str(source), "-o", str(out)]) == 2
        assert says in capsys.readouterr().err and not out.exists()


def test_an_exported_mission_recording_is_right_channel_by_channel(tmp_path, capsys):
    """A short lockstep mission in the demo's room (its own recording, every service's keys), exported
    and read back: each channel against the recorded messages it comes from."""
    assert cli_main(["navigate", "--world", "room", "--in-process", "--goal", "3.2", "0.9", "30", "--timeout", "2",
                     "-o", str(tmp_path / "run"), "--json"]) == 1        # it cannot arrive in 2 s
    recording, exported = tmp_path / "run" / "run.mcap", tmp_path / "foxglove.mcap"
    assert cli_main(["export", "--foxglove", str(recording), "-o", str(exported)]) == 0
    recorded: dict[str, list] = {}
    for record in read_records(recording):
        recorded.setdefault(record.key, []).append(decode(record.payload))
    channels = read_export(exported)
    key = KeyLayout("r1").resolve
    services = {msg.name for k, msgs in recorded.items() if "/diagnostics/" in k for msg in msgs}
    assert {"localizer", "costmap", "tracker", "navigator", "local_planner"} <= services
    assert {topic: rows[0][0] for topic, rows in channels.items()} == \
        VIEW_CHANNELS | {f"/diagnostics/{s}": "omninav.Diagnostic" for s in services}
    # one exported message per recorded one (the grids: only when changed), log time = sim stamp
    for topic, source in (("/scan", "scan"), ("/truth/robot", "sim/truth"), ("/truth/movers", "sim/movers"),
                          ("/tracks", "tracks"), ("/localizer/pose", "pose"), ("/localizer/particles", "particlecloud"),
                          ("/plan", "plan"), ("/local_plan", "local_plan"), ("/goal", "goal")):
        assert [t for _, t, _ in channels[topic]] == [msg.header.stamp_ns for msg in recorded[key(source)]], topic
    for topic in ("/map", "/costmap/global", "/costmap/local"):
        assert 1 <= len(channels[topic]) <= len(recorded[key(topic[1:])]), topic
    assert channels["/map"][0][2].data == recorded[key("map")][0].data.tobytes()
    last_scan = recorded[key("scan")][-1]
    assert np.array_equal(channels["/scan"][-1][2].ranges, last_scan.ranges.astype(float))
    final_pose = recorded[key("pose")][-1].pose
    position = channels["/localizer/pose"][-1][2].pose.position
    assert (position.x, position.y) == (final_pose.x, final_pose.y)
    truth_entity = channels["/truth/robot"][-1][2].entities[0]
    assert truth_entity.frame_id == "world" and len(truth_entity.lines[0].points) >= 3
    goal_poses = channels["/goal"][0][2].poses
    assert (goal_poses[-1].position.x, goal_poses[-1].position.y) == (3.2, 0.9)
    tree = {(t.parent_frame_id, t.child_frame_id) for _, _, tf in channels["/tf"] for t in tf.transforms}
    assert {("world", "map"), ("map", "odom"), ("odom", "base_link"), ("base_link", "laser")} <= tree
    tracks = [len(msg.ids) for msg in recorded[key("tracks")]]
    assert [len(scene.entities[0].cylinders) for _, _, scene in channels["/tracks"]] == tracks
    assert channels["/diagnostics/localizer"][-1][2]["name"] == "localizer"
