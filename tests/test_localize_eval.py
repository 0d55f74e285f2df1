"""`omninav localize-eval`: the routes, the harness's driving, the scoring, short runs in the simulator
(tracking, a kidnapping), and the real racecar bag against raw odometry."""
import contextlib
import io
import json
import math

import numpy as np
import pytest

from omninav.cli.main import main as omninav
from omninav.schemas.codec import encode
from omninav.experiments.localize_eval import (PARAMS_FILE, ROUTES, Route, Series, kidnap_result, route_command,
                                                 route_problems)
from omninav.services.localizer.params import AmclParams
from omninav.geometry.odometry_history import OdomHistory
from omninav.experiments.localize_realdata import Agreement, judge_start, load_run, search_start
from omninav.services.runtime.params import load_params_file
from omninav.sim.lidar import LidarParams, make_scan, scan
from omninav.sim.world import load_world, world_path

from conftest import SHARED_DATA

BAG = SHARED_DATA / "bags" / "localization_bag1_2022-03-29-19-23-29.bag"
BASEMENT = SHARED_DATA / "maps" / "basement_fixed.yaml"
try:
    import rosbags  # noqa: F401
    HAVE_ROSBAGS = True
except ImportError:
    HAVE_ROSBAGS = False


def test_the_paper_params_are_a_plain_ros1_amcl_file():
    params = load_params_file(AmclParams, PARAMS_FILE, "amcl")      # only amcl's own parameters
    assert params.odom_model_type == "omni-corrected" and params.laser_model_type == "likelihood_field_prob"
    assert params.recovery_alpha_slow > 0 and params.recovery_alpha_fast > params.recovery_alpha_slow


@pytest.mark.parametrize("name", sorted(ROUTES))
def test_every_route_is_clear_and_starts_at_the_start(name):
    world = load_world(world_path(name))
    assert route_problems(world, ROUTES[name]) == []
    assert math.dist(ROUTES[name].points[0], world.robot.start[:2]) < 0.3


def test_a_route_loops_from_its_loop_point():
    route = Route(((0, 0), (1, 0), (2, 0), (3, 0)), loop_from=1)
    assert route.legs() == [(0, 1), (1, 2), (2, 3), (3, 1)]
    assert [route.after(k) for k in range(4)] == [1, 2, 3, 1]


def test_a_route_through_furniture_is_reported():
    world = load_world(world_path("room"))
    there, back = route_problems(world, Route(((1.3, 0.8), (4.5, 3.0))))   # through the round table at (3, 2.2)
    assert there.startswith("segment 0 (1.3, 0.8) → (4.5, 3)") and back.startswith("segment 1 (4.5, 3) → (1.3, 0.8)")
    (problem,) = route_problems(world, Route(((1.3, 0.8), (8.3, 0.8), (8.3, 3.5), (6.2, 3.5))))   # closing leg
    assert problem.startswith("segment 3")


def test_route_commands():
    # holonomic: straight at the target (here behind and to the left), turning towards the way it goes
    vx, vy, wz = route_command((0.0, 0.0, 0.0), (-3.0, 4.0), True, 0.5, 1.0)
    assert (vx, vy) == pytest.approx((-0.3, 0.4)) and wz == 1.0
    # a differential drive turns on the spot first, then drives with a small correction
    assert route_command((0.0, 0.0, 0.0), (0.0, 2.0), False, 0.5, 1.0) == (0.0, 0.0, 1.0)
    vx, vy, wz = route_command((0.0, 0.0, 0.2), (2.0, 0.0), False, 0.5, 1.0)
    assert vx == pytest.approx(0.5 * math.cos(0.2)) and vy == 0.0 and wz == pytest.approx(-0.4)
    # slowing down when close
    assert route_command((0.0, 0.0, 0.0), (0.1, 0.0), True, 0.5, 1.0)[0] == pytest.approx(0.15)


def test_convergence_needs_the_error_to_hold_and_the_statistics_cover_everything_after():
    series = Series()
    errors = [2.0, 0.05, 0.5, 0.05, 0.05, 0.05, 0.04, 0.03, 0.12, 0.02, 0.02, 0.02]
    for k, e in enumerate(errors):
        series.t.append(0.5 * k)
        series.position.append(e)
        series.heading.append(math.radians(1.0))
        series.injected.append(0)
    assert series.converged_at() == 1.5                    # 0.05 at 0.5 s did not hold for 1 s
    assert series.converged_at(4.1) == 4.5                  # after the 0.12 at 4.0 s
    assert series.converged_at(5.1) is None                 # too little left to hold for 1 s
    stats = series.stats(1.5)
    assert stats["samples"] == 9 and stats["position_cm"]["max"] == 12.0   # the later 12 cm counts
    assert stats["heading_deg"]["p95"] == pytest.approx(1.0)


def test_a_kidnapping_is_scored_against_the_injections_while_tracking():
    series = Series()
    for k in range(40):   # every 0.1 s; 3 random poses at 1.0 s while tracking, 50 per scan after the jump
        series.t.append(0.1 * k)
        series.position.append(0.02 if k < 20 else 2.0)
        series.heading.append(0.01)
        series.injected.append(3 * (k >= 10) if k < 20 else 3 + 50 * (k - 19))
        series.beam_fit.append(0.5 if k < 5 else 0.95 if k < 20 else 0.2 + 0.01 * k)   # 0.5: before converging
    k = kidnap_result(series, {"at_s": 1.95, "from": [0.0, 0.0, 0.0], "to": [3.0, 4.0, 0.0]}, 0.5)
    assert k["jump_m"] == 5.0 and k["error_after_m"] == 2.0
    assert k["detected"] and k["detected_after_s"] == pytest.approx(0.05)
    assert k["random_poses_per_s_before"] == pytest.approx(3 / 1.4, abs=0.05)   # 0.5 s to 1.9 s
    assert k["random_poses_first_s_after"] == 500                              # scans at 2.0 … 2.9 s
    assert k["beam_fit_min_before"] == 0.95 and k["beam_fit_min_first_s_after"] == 0.4
    assert not k["recovered"]


SYMMETRIC_ROOM = """\
name: symmetric
bounds: [6.0, 4.0]
boxes:                 # the same about the centre (3, 2) turned half a turn
  - {center: [1.5, 1.0], size: [0.8, 0.5]}
  - {center: [4.5, 3.0], size: [0.8, 0.5]}
robot:
  start: [2.0, 2.6, 0.3]
"""


def _scans_from(world, pose, count=3):
    lidar = LidarParams(beams=360, range_max=10.0, noise_std=0.01)
    rng = np.random.default_rng(0)
    scans = [make_scan(lidar, scan(world, pose, None, lidar, rng), k * 100_000_000) for k in range(count)]
    history = OdomHistory(keep_ns=10 ** 12)
    for k in range(count):
        history.add(k * 100_000_000, np.zeros(3))
    return scans, history


@pytest.mark.parametrize("second_box, ambiguous", [("[4.5, 3.0]", True), ("[4.5, 1.0]", False)])
def test_a_start_that_a_point_symmetric_room_cannot_tell_apart_is_reported_ambiguous(tmp_path, second_box, ambiguous):
    path = tmp_path / "symmetric.yaml"
    path.write_text(SYMMETRIC_ROOM.replace("[4.5, 3.0]", second_box))   # [4.5, 1.0]: no longer symmetric
    world = load_world(path)
    grid = world.rasterize(0.05)
    scans, history = _scans_from(world, world.robot.start)
    search = judge_start(search_start(grid, scans, history, (0.0, 0.0, 0.0)), Agreement(grid, (0.0, 0.0, 0.0)),
                         scans, history)
    found = [search["pose"], search["runner_up"]["pose"]]
    mirror = (6.0 - world.robot.start[0], 4.0 - world.robot.start[1])
    assert min(math.hypot(p[0] - world.robot.start[0], p[1] - world.robot.start[1]) for p in found) < 0.1
    assert search["ambiguous"] is ambiguous and search["fit"] > 0.9
    if ambiguous:   # the other candidate is the mirror image, fitting as well
        assert min(math.hypot(p[0] - mirror[0], p[1] - mirror[1]) for p in found) < 0.1
        assert search["runner_up"]["fit"] > 0.9
    else:
        assert search["runner_up"]["fit"] < search["fit"] - 0.1


def _run(capsys, *args):
    code = omninav(["localize-eval", *args, "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


def test_tracking_in_the_room_from_a_rough_initial_pose(capsys):
    r = _run(capsys, "--world", "room", "--mode", "track", "--duration", "25")
    assert (r["world"], r["drive"], r["mode"]) == ("room", "mecanum", "track")
    assert r["collisions"] == 0 and r["scans"] > 240 and r["converged"]
    after = r["after_convergence"]
    assert after["samples"] > 200
    assert after["position_cm"]["p95"] < 6.0 and after["heading_deg"]["p95"] < 2.0   # aims: 5 cm, 2°


def test_a_kidnapping_in_the_room_is_detected(capsys):
    r = _run(capsys, "--world", "room", "--drive", "diff", "--mode", "kidnap", "--duration", "20",
             "--kidnap-at", "8")
    k = r["kidnap"]
    assert k["done"] and k["at_s"] >= 8.0 and k["jump_m"] > 3.0 and k["error_after_m"] > 1.0
    assert k["detected"] and 0 < k["detected_after_s"] < 20.0 - k["at_s"]
    assert k["random_poses_first_s_after"] > 10 * k["random_poses_per_s_before"]   # not a chance injection
    assert r["after_convergence"]["position_cm"]["max"] < 10.0       # tracking until then


@pytest.mark.parametrize("args, message", [
    (["--world", "nowhere"], "nowhere"),
    (["--world", "corridor"], "no route for world 'corridor'"),
    (["--route", "1,1;2"], "expected at least two waypoints"),
    (["--route", "1.3,0.8;4.5,3"], "the route is not clear"),
    (["--set", "laser_max_beem=30"], "laser_max_beem"),
    (["--params", "/nonexistent/amcl.yaml"], "no such file"),
    (["--bag", "x.bag"], "--bag needs --map"),
    (["--mode", "kidnap", "--shove", "0.3,0.3"], "--shove '0.3,0.3': expected X,Y,YAW"),
])
def test_user_errors_are_one_line(capsys, args, message):
    assert omninav(["localize-eval", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def needs_the_bag(test):
    test = pytest.mark.skipif(not HAVE_ROSBAGS,
                              reason="the optional rosbags package is not installed (pip install '.[rosbag]')")(test)
    return pytest.mark.skipif(not (BAG.is_file() and BASEMENT.is_file()), reason="no shared data (bag and basement map)")(test)


@pytest.fixture(scope="module")
def racecar_run(tmp_path_factory):
    """localize-eval on the racecar bag with amcl's behaviour (no update without motion), and its figure."""
    picture = tmp_path_factory.mktemp("real") / "real.png"
    return _run_quietly("--bag", str(BAG), "--map", str(BASEMENT), "--plot", str(picture)), picture


def _run_quietly(*args):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert omninav(["localize-eval", *args, "--json"]) == 0
    return json.loads(out.getvalue())


@needs_the_bag
def test_on_the_racecar_bag_the_localizer_agrees_with_the_map_better_than_odometry(racecar_run):
    r, picture = racecar_run
    assert r["scans"] == 281 and r["odometry"] == 350 and r["scans_scored"] > 270
    assert r["start"]["how"] == "searched" and r["laser_pose"] == [0.285, 0.0, 0.0]
    assert r["laser_pose_from"] == "the MIT racecar's default"     # the bag has no tf
    ours, odometry = r["localizer"], r["raw_odometry"]
    assert ours["mean"] > 0.5 and ours["mean"] > odometry["mean"] + 0.3
    assert ours["median"] > 0.45 and ours["p10"] > odometry["median"] + 0.3
    assert min(ours["per_second"]) > 0.3                    # never lost for a whole second
    assert np.mean(r["series"]["raw_odometry"][-40:]) < 0.2  # while odometry ends up in a wall
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@needs_the_bag
def test_on_the_racecar_bag_global_localization_finds_the_searched_start(racecar_run):
    tracked = racecar_run[0]
    assert not tracked["start"]["ambiguous"]                     # the runner-up fits the first scans far worse
    assert tracked["start"]["runner_up"]["fit"] < tracked["start"]["fit"] - 0.2
    ours = _run_quietly("--bag", str(BAG), "--map", str(BASEMENT), "--global-localization")
    assert "global localization" in ours["start"]["localizer"]
    # particles over the whole basement at the first scan; from the second second on, the same corridor
    assert min(ours["localizer"]["per_second"][1:]) > 0.45
    gaps = np.hypot(*(np.array(ours["paths"]["localizer"]) - np.array(tracked["paths"]["localizer"]))[:, :2].T)
    t = np.array(ours["series"]["t"])
    assert gaps[t > 1.0].max() < 0.3 and gaps[-1] < 0.1


@needs_the_bag
def test_on_the_racecar_bag_temporal_updates_end_where_the_scans_fit(racecar_run):
    # amcl: the car brakes, stands for 2.5 s, and the estimate stays where the last update left it
    ros = racecar_run[0]["end"]
    assert ros["distance_m"] > 0.3 and ros["localizer_share"] < ros["best_fit_share"] - 0.3
    # an update at every scan while it stands (the racecar's lidar: 40 Hz)
    ours = _run_quietly("--bag", str(BAG), "--map", str(BASEMENT), "--set", "temporal_update=0.025")
    end = ours["end"]
    assert end["distance_m"] < 0.05 and end["heading_deg"] < 1.5
    assert end["localizer_share"] > end["best_fit_share"] - 0.02 and end["best_fit_share"] > 0.85
    # while it drives, updates come from motion nearly always: no worse than amcl's
    assert np.all(np.array(ours["localizer"]["per_second"][:4])
                  > np.array(racecar_run[0]["localizer"]["per_second"][:4]) - 0.03)


@pytest.mark.skipif(not HAVE_ROSBAGS, reason="the optional rosbags package is not installed (pip install '.[rosbag]')")
@pytest.mark.skipif(not BAG.is_file(), reason="no shared data (the racecar bag)")
def test_an_imported_recording_gives_the_same_run_as_its_bag(tmp_path, capsys):
    recording = tmp_path / "bag1.mcap"
    assert omninav(["import", "rosbag", str(BAG), "-o", str(recording)]) == 0
    capsys.readouterr()
    from_bag, from_mcap = load_run(BAG, "/scan", "/vesc/odom"), load_run(recording, "/scan", "/vesc/odom")
    for kind in ("scans", "odometry"):
        for message in getattr(from_mcap, kind):
            message.header.seq = 0   # numbered by the importer, 0 straight from the bag; the localizer ignores it
        assert [encode(m) for m in getattr(from_mcap, kind)] == [encode(m) for m in getattr(from_bag, kind)]


def test_the_laser_mounting_is_what_is_given_then_the_bags_tf_then_the_racecars():
    from omninav.experiments.localize_realdata import laser_mounting
    assert laser_mounting((None, None, None), None) == ((0.285, 0.0, 0.0), "the MIT racecar's default")
    assert laser_mounting((None, None, None), (-0.064, 0.01, 0.3)) == ((-0.064, 0.01, 0.3), "the bag's tf")
    assert laser_mounting((0.1, None, None), (-0.064, 0.01, 0.3)) == ((0.1, 0.01, 0.3),
                                                                       "given, the rest from the bag's tf")
    assert laser_mounting((0.1, 0.0, 0.0), (-0.064, 0.01, 0.3)) == ((0.1, 0.0, 0.0), "given")
