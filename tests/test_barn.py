"""BARN Challenge worlds (sim/barn_world.py) and `omninav bench barn` (experiments/barn.py): a `.world`
file loads as the challenge sets it up, the challenge's score on hand-computed numbers, the Jackal
profile, and one world driven through in lockstep."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from omninav.cli.main import main as cli_main
from omninav.cli.navigate import compose_for
from omninav.cli.profile import ProfileError, load_profile
from omninav.experiments.barn import barn_score, optimal_time, reference_length, run_world
from omninav.services.costmap.params import load_costmap_params
from omninav.sim.node import SimNodeParams, open_world
from omninav.sim.world import WorldError, load_world, shared_data_dir

BARN = shared_data_dir(Path(__file__)) / "barn"
needs_barn = pytest.mark.skipif(not (BARN / "worlds").is_dir(), reason="the BARN data is not beside the checkout")


def _state_cylinders(path: Path) -> list[tuple[float, float]]:
    """The unit cylinders' x, y in the file's <state> block, read with a regular expression."""
    state = path.read_text().split("<state", 1)[1]
    found = re.findall(r"<model name='unit_cylinder_\d+'>\s*<pose[^>]*>([^<]+)</pose>", state)
    return [tuple(float(v) for v in pose.split()[:2]) for pose in found]


@needs_barn
@pytest.mark.parametrize("number", [0, 7])
def test_a_barn_world_holds_the_state_blocks_cylinders_the_jackal_at_the_start_and_the_goal(number):
    path = BARN / "worlds" / f"world_{number}.world"
    world = open_world(str(path))
    expected = _state_cylinders(path)
    assert len(world.circles) == len(expected) > 100
    assert sorted(map(tuple, world.circles[:, :2].tolist())) == sorted(expected)
    assert np.all(world.circles[:, 2] == 0.075)
    assert world.robot.start.tolist() == pytest.approx([-2.25, 3.0, math.pi / 2])
    assert world.goals.tolist() == [pytest.approx([-2.25, 13.0, math.pi / 2])]
    assert world.robot.drive == "diff"
    assert np.ptp(world.robot.footprint, axis=0).tolist() == pytest.approx([0.42, 0.33])
    assert not world.outside(world.circles[:, :2]).any()
    assert world.footprint_clearance(world.robot.start) > 0.1       # the robot starts clear of the clutter


def test_a_broken_or_missing_world_file_is_one_clear_line(tmp_path):
    truncated = tmp_path / "world_1.world"
    truncated.write_text("<sdf version='1.6'><world name='default'><state world_name='default'><model name='unit_")
    no_state = tmp_path / "world_2.world"
    no_state.write_text("<sdf version='1.6'><world name='default'></world></sdf>")
    bad_pose = tmp_path / "world_3.world"
    bad_pose.write_text("<sdf><world><state><model name='unit_cylinder_0'><pose>1 two 0 0 0 0</pose></model>"
                        "</state></world></sdf>")
    for path, words in ((truncated, "not a readable SDF"), (no_state, "no <world><state>"),
                        (bad_pose, "unit_cylinder_0"), (tmp_path / "world_9.world", "no such file")):
        with pytest.raises(WorldError) as caught:
            load_world(path)
        message = str(caught.value)
        assert str(path) in message and words in message and "\n" not in message


def test_the_reference_length_and_score_follow_the_challenges_formula():
    # cells (15, 0) and (15, 29) lie at (-2.325, 5.075) and (-2.325, 9.425)
    cells = np.array([[15, 0], [15, 29]])
    by_hand = math.hypot(0.075, 2.075) + 4.35 + math.hypot(0.075, 3.575)
    assert reference_length(cells) == pytest.approx(by_hand)
    ot = optimal_time(cells)
    assert ot == pytest.approx(by_hand / 2.0)
    assert barn_score(True, 0.5 * ot, ot) == pytest.approx(0.5)        # faster than 2·OT counts as 2·OT
    assert barn_score(True, 4.0 * ot, ot) == pytest.approx(0.25)
    assert barn_score(True, 20.0 * ot, ot) == pytest.approx(0.125)     # slower than 8·OT counts as 8·OT
    assert barn_score(False, 4.0 * ot, ot) == 0.0


@needs_barn
def test_the_reference_length_of_a_shipped_path_file():
    cells = np.load(BARN / "path_files" / "path_0.npy")
    points = [(-2.25, 3.0)] + [(x * 0.15 - 0.075 - 4.5, y * 0.15 + 0.075 + 5.0) for x, y in cells] + [(-2.25, 13.0)]
    by_hand = sum(math.dist(a, b) for a, b in zip(points, points[1:]))
    assert reference_length(cells) == pytest.approx(by_hand)


def test_the_jackal_profile_sets_the_robot_of_every_service(tmp_path):
    profile = load_profile("jackal")
    # the outline with the wheels (the body the simulator collides), padded to the challenge's 0.53 m
    assert profile.drive == "diff" and profile.footprint_padding == 0.057
    size = np.ptp(np.array(profile.footprint), axis=0)
    assert size.tolist() == pytest.approx(np.ptp(np.array(profile.body["outline"]), axis=0).tolist(), abs=1e-3)
    assert size[1] + 2 * profile.footprint_padding == pytest.approx(0.53)
    world = load_world(Path(__file__).resolve().parents[1] / "sim" / "worlds" / "room.yaml")
    services = {s["name"]: s for s in compose_for(world, Path(world.source), None, profile.drive, "odom",
                                                  tmp_path / "run.mcap", 0, 1.0, "r1", profile)["services"]}
    assert "map_server" not in services and "localizer" not in services
    for name in ("sim", "local_planner", "collision_monitor"):
        assert services[name]["params"]["footprint"] == [list(p) for p in profile.footprint]
    assert services["local_planner"]["params"]["max_vel_x"] == 2.0
    sim = SimNodeParams(**services["sim"]["params"])
    wheels = sim.chassis_params()
    # the same wheels; without a map the chassis's odometry goes to the fusion (issue 36)
    assert {**sim.chassis, "drive": profile.drive, "fused_odometry": True} == services["chassis"]["params"]
    assert {"laser_odometry", "ekf"} <= set(services)
    monitor = services["collision_monitor"]["params"]                     # and the monitor knows how they follow
    assert (monitor["acc_lim_x"], monitor["acc_lim_theta"]) == (sim.chassis["acc_lim_x"], sim.chassis["acc_lim_theta"])
    assert wheels.wheel_radius * wheels.max_wheel_speed >= 2.0             # the simulated wheels reach 2 m/s
    assert services["lidar"]["params"]["fov"] == pytest.approx(math.radians(270))
    assert services["lidar"]["params"]["range_max"] == 30.0
    costmap = services["costmap"]["params"]
    for name in ("global", "local"):
        params = load_costmap_params(costmap[f"{name}_costmap_files"], f"{name}_costmap")
        assert sorted(params.footprint) == sorted(profile.footprint)
        assert params.footprint_padding == profile.footprint_padding
    assert load_costmap_params(costmap["global_costmap_files"], "global_costmap").track_unknown_space
    # the simulator alone moves the Jackal as it is: its URDF collision shape, larger than the footprint
    body = sim.body_params()
    assert np.ptp(np.array(body.outline), axis=0).tolist() == pytest.approx([0.458, 0.41559])
    assert body.track_multiplier == 1.5 and body.traction_mu == 0.5
    assert all("body" not in s.get("params", {}) and "outline" not in s.get("params", {})
               for name, s in services.items() if name != "sim")


def test_a_broken_profile_is_one_clear_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("drive: tank\nfootprint: [[0, 0], [1, 0], [1, 1]]\n")
    with pytest.raises(ProfileError, match="drive: expected one of"):
        load_profile(str(bad))
    with pytest.raises(ProfileError, match="no such file"):
        load_profile("no_such_robot")
    sound = "drive: diff\nfootprint: [[0, 0], [1, 0], [1, 1]]\ncostmap_common_params: jackal_costmap_common_params.yaml\n"
    bad.write_text(sound + "body: {mass: -3}\n")
    with pytest.raises(ProfileError, match="body: .*mass must be > 0"):
        load_profile(str(bad))
    bad.write_text(sound + "body: {traction: 0.5}\n")
    with pytest.raises(ProfileError, match="body: .*traction_mu"):
        load_profile(str(bad))


@needs_barn
def test_a_barn_world_is_driven_through_without_a_map_or_a_collision():
    result = run_world(BARN / "worlds" / "world_2.world", BARN / "path_files" / "path_2.npy", seed=0)
    assert result.success and not result.collision and not result.timeout, result
    assert result.time_s < 100.0 and 0.125 <= result.score <= 0.5


@pytest.mark.parametrize("argv, message", [
    (["--worlds", "/no/such/folder"], "no such folder"),
    (["--range", "9-2", "--worlds", "{tmp}"], "expected FIRST-LAST"),     # a folder that is there: the range is at fault
    (["--range", "0-1", "--worlds", "{tmp}"], "world_0.world: no such file"),
])
def test_bench_barn_input_errors_are_one_line_and_exit_2(argv, message, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert cli_main(["bench", "barn", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
