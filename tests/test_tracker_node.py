"""The tracker service in the simulated crossing hall (two people walking back and forth across the
robot's way), in lockstep: each person gets one confirmed track near the simulator's truth with
their velocity, with and without the static map; the run replays byte for byte into the tracker."""
import numpy as np
import pytest

from local_pipeline import KEYS, recorder_tap
from omninav.cli.main import main
from omninav.cli.navigate import map_for
from omninav.schemas import decode
from omninav.schemas.messages import Tracks
from omninav.services.chassis.node import ChassisNode
from omninav.services.lidar.node import LidarNode, LidarNodeParams
from omninav.services.map_server.node import MapServerNode, MapServerParams
from omninav.services.truth_pose.node import TruthPoseNode
from omninav.services.recorder.mcap_io import RecordingWriter
from omninav.services.runtime.inprocess import InProcessRunner
from omninav.services.runtime.node import NS_PER_S
from omninav.services.tracker.node import TrackerNode, TrackerNodeParams
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.world import load_world, world_path

WORLD = "crossing"
START = tuple(float(v) for v in load_world(world_path(WORLD)).robot.start)


def run_tracker(seconds: float, with_map: bool, tmp_path, recording=None):
    """sim, chassis, lidar and the tracker (with map_server and truth_pose for the map), the robot
    standing at its start; (the Tracks published, the movers' truth per stamp in the odom frame)."""
    start = dict(zip(("initial_pose_x", "initial_pose_y", "initial_pose_a"), START))
    sim = SimNode(SimNodeParams(world=WORLD, dt=0.02))
    nodes = [sim, ChassisNode(), LidarNode(LidarNodeParams(world=WORLD)),
             TrackerNode(TrackerNodeParams(use_map=with_map, **start))]
    if with_map:
        world = load_world(world_path(WORLD))
        nodes += [MapServerNode(MapServerParams(yaml_filename=str(map_for(world, WORLD, tmp_path)),
                                                publish_period_s=1.0)), TruthPoseNode()]
    runner = InProcessRunner(nodes)
    tracks, movers = [], {}

    def tap(key, payload, _stamp):
        if key == KEYS.robot("tracks"):
            tracks.append(decode(payload, Tracks))
        elif key == KEYS.sim("movers"):
            msg = decode(payload)
            movers[msg.header.stamp_ns] = (msg.circles[:, :2] - START[:2], msg.velocities.copy())
    runner.tap(tap)
    writer = RecordingWriter(recording) if recording is not None else None
    if writer is not None:
        runner.tap(recorder_tap(writer))
    runner.run_until(lambda: False, round(seconds / sim.params.dt))
    runner.close()
    if writer is not None:
        writer.close()
    return tracks, movers


def matched(msg: Tracks, movers) -> list[tuple[int, float, float]]:
    """(track id, position error, velocity error) of the track nearest each mover at msg's stamp."""
    positions, velocities = movers[msg.header.stamp_ns]
    out = []
    for p, v in zip(positions, velocities):
        if len(msg.ids) == 0:
            out.append((-1, np.inf, np.inf))
            continue
        k = int(np.argmin(np.hypot(*(msg.states[:, :2] - p).T)))
        out.append((int(msg.ids[k]), float(np.hypot(*(msg.states[k, :2] - p))),
                    float(np.hypot(*(msg.states[k, 2:] - v)))))
    return out


@pytest.mark.parametrize("with_map", [False, True])
def test_each_person_crossing_the_hall_gets_one_track_with_their_velocity(tmp_path, with_map):
    tracks, movers = run_tracker(9.0, with_map, tmp_path)
    assert all(m.header.frame_id == "odom" for m in tracks)
    # from 4 s on (the walls are static then): two tracks, each near a person, as fast as they are
    later = [m for m in tracks if m.header.stamp_ns >= 4 * NS_PER_S]
    counts = [len(m.ids) for m in later]
    assert np.mean(np.equal(counts, 2)) > 0.9, counts
    found = [matched(m, movers) for m in later if len(m.ids) == 2]
    position_errors = [e for pairs in found for _, e, _ in pairs]
    velocity_errors = [e for pairs in found for _, _, e in pairs]
    assert np.median(position_errors) < 0.1 and np.percentile(position_errors, 95) < 0.35   # the turns at the walls are sudden
    assert np.median(velocity_errors) < 0.15
    ids = {i for pairs in found for i, _, _ in pairs}
    assert len(ids) <= 4          # the people turn back at the walls, a track may be begun again there


def test_the_tracker_replays_byte_for_byte(tmp_path, capsys):
    recording = tmp_path / "tracker.mcap"
    tracks, _ = run_tracker(6.0, True, tmp_path, recording)
    assert any(len(m.ids) for m in tracks)
    assert main(["replay", str(recording), "--into", "tracker", "--compare"]) == 0, capsys.readouterr().out
    assert "replay reproduces the recorded outputs byte for byte" in capsys.readouterr().out
