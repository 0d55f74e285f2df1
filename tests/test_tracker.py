"""The tracker core on synthetic scans of known movers: circles moving at known velocities in a
walled hall, seen by the simulated lidar from a robot standing (or driving) in it."""
import math

import numpy as np
import pytest

from omninav.schemas.messages import MapMetaData, OccupancyGrid, Pose2D
from omninav.services.tracker.tracker import MoverTracker, Track, TrackerParams, euclidean_clusters, predicted
from omninav.sim.lidar import LidarParams, cast, scan
from omninav.sim.world import load_world

LIDAR = LidarParams(noise_std=0.01)
RATE = 10.0     # scans per second
# s: the tracker starts afresh once the walls seen first are static (static_after_s), and confirms a
# track after confirm_hits scans and min_travel of motion
WARMED = 3.0


@pytest.fixture(scope="module")
def hall(tmp_path_factory):
    """An empty 12 m × 8 m hall with a pillar (a static circle no track may come from)."""
    path = tmp_path_factory.mktemp("hall") / "hall.yaml"
    path.write_text("name: hall\nbounds: [12.0, 8.0]\ncircles:\n  - {center: [9.0, 6.5], radius: 0.3}\n"
                    "robot:\n  start: [1.0, 4.0, 0.0]\n")
    return load_world(path)


def movers_at(t: float, movers) -> np.ndarray:
    """(K, 3) circles of movers given as (x0, y0, vx, vy, radius) at time t."""
    return np.array([[x + vx * t, y + vy * t, r] for x, y, vx, vy, r in movers]).reshape(-1, 3)


def run(world, movers, seconds: float, robot=lambda t: (1.0, 4.0, 0.0), seed: int = 0, tracker=None,
        odom_in_map=None):
    """Scans of the movers from the robot, fed to a tracker; the TrackSet after each scan."""
    rng = np.random.default_rng(seed)
    tracker = tracker or MoverTracker()
    out = []
    for k in range(int(seconds * RATE)):
        t = k / RATE
        pose = robot(t)
        ranges = scan(world, pose, movers_at(t, movers), LIDAR, rng)
        keep = np.isfinite(ranges)
        angles = pose[2] + LIDAR.angles()[keep]
        points = np.column_stack([pose[0] + ranges[keep] * np.cos(angles), pose[1] + ranges[keep] * np.sin(angles)])
        out.append(tracker.update(t, pose[:2], points, odom_in_map))
    return tracker, out


def assert_tracks(final, movers, t: float, velocity_tol: float = 0.1, position_tol: float = 0.15) -> None:
    truth = movers_at(t, movers)
    assert len(final.ids) == len(movers), final
    for (x, y, r), (_, _, vx, vy, _) in zip(truth, movers):
        k = int(np.argmin(np.hypot(final.states[:, 0] - x, final.states[:, 1] - y)))
        assert math.hypot(final.states[k, 0] - x, final.states[k, 1] - y) < position_tol, (final.states[k], x, y)
        assert math.hypot(final.states[k, 2] - vx, final.states[k, 3] - vy) < velocity_tol, (final.states[k], vx, vy)
        assert abs(final.radii[k] - r) < 0.1


@pytest.mark.parametrize("velocity", [(0.0, 0.5), (-0.4, 0.3), (0.0, -1.2)])
def test_one_mover_in_front_of_walls_gives_one_confirmed_track_with_its_velocity(hall, velocity):
    movers = [(5.0, 4.0 - 2.0 * np.sign(velocity[1]), *velocity, 0.3)]
    _, sets = run(hall, movers, 4.0)
    ids = {int(i) for s in sets[int(WARMED * RATE):] for i in s.ids}
    assert len(ids) == 1                       # one track, its id kept, none from walls or the pillar
    assert_tracks(sets[-1], movers, 3.9)


def test_static_walls_and_a_pillar_alone_give_no_track_even_while_the_robot_drives(hall):
    _, sets = run(hall, [], 6.0, robot=lambda t: (1.0 + 0.4 * t, 4.0 + 0.3 * math.sin(t), 0.2 * t))
    assert all(len(s.ids) == 0 for s in sets[int(3 * RATE):])     # once the walls have been seen for a while


def test_two_movers_while_the_robot_drives_each_get_their_own_track(hall):
    movers = [(5.0, 1.5, 0.0, 0.6, 0.3), (8.0, 6.5, -0.3, -0.4, 0.25)]
    _, sets = run(hall, movers, 4.1, robot=lambda t: (1.0 + 0.3 * t, 4.0, 0.05 * t), seed=3)
    assert_tracks(sets[-1], movers, 4.0)     # (soon after, the first hides the second)
    assert len({int(i) for s in sets[int(WARMED * RATE):] for i in s.ids}) == 2


@pytest.mark.parametrize("angle_deg, speed, seed", [(90, 0.6, 0), (60, 0.8, 1), (130, 0.5, 2)])
def test_two_movers_crossing_each_other_keep_their_ids(hall, angle_deg, speed, seed):
    """Two people cross the same point (6, 4) at an angle, the second 1.5 s after the first (they do
    not walk through each other), and walk on; the first crosses the robot's line of sight."""
    a = math.radians(angle_deg)
    va, vb = (0.0, speed), (speed * math.sin(a), speed * math.cos(a))
    meet = 4.5
    movers = [(6.0 - va[0] * meet, 4.0 - va[1] * meet, *va, 0.25),
              (6.0 - vb[0] * (meet + 1.5), 4.0 - vb[1] * (meet + 1.5), *vb, 0.25)]
    _, sets = run(hall, movers, 8.0, seed=seed)
    before, after = sets[int(WARMED * RATE)], sets[-1]
    assert len(before.ids) == len(after.ids) == 2

    def id_of(track_set, t, which):
        x, y, _ = movers_at(t, movers)[which]
        return int(track_set.ids[np.argmin(np.hypot(track_set.states[:, 0] - x, track_set.states[:, 1] - y))])

    assert [id_of(before, WARMED, k) for k in (0, 1)] == [id_of(after, 7.9, k) for k in (0, 1)]
    assert_tracks(after, movers, 7.9, velocity_tol=0.15)


def test_with_a_static_map_the_walls_are_static_from_the_first_scan(hall):
    """The map (rasterized from the world's walls, odom frame = map frame shifted) explains the walls
    at once: the first scans, before any evidence, give no tentative cluster from them."""
    resolution = 0.05
    height, width = int(9.0 / resolution), int(13.0 / resolution)      # and half a metre around
    ys, xs = (np.mgrid[0:height, 0:width] + 0.5) * resolution - 0.5
    occupied = (xs < 0.05) | (xs > 11.95) | (ys < 0.05) | (ys > 7.95) | (np.hypot(xs - 9.0, ys - 6.5) < 0.3)
    grid = OccupancyGrid(info=MapMetaData(resolution=resolution, width=width, height=height,
                                          origin=Pose2D(-0.5, -0.5, 0.0)),
                         data=np.where(occupied, 100, 0).astype(np.int8))
    tracker = MoverTracker()
    tracker.set_map(grid)
    robot = (1.0, 4.0, 0.0)
    ranges = cast(hall, robot[0], robot[1], LIDAR.angles(), None, LIDAR.range_max)
    angles = LIDAR.angles()[np.isfinite(ranges)]
    points = np.column_stack([robot[0] + ranges[np.isfinite(ranges)] * np.cos(angles),
                              robot[1] + ranges[np.isfinite(ranges)] * np.sin(angles)])
    odom = points - (1.0, 4.0)     # the odom frame starts at the robot
    assert tracker.static_points(0.0, (0.0, 0.0), odom, odom_in_map=(1.0, 4.0, 0.0)).all()
    assert not MoverTracker().static_points(0.0, (0.0, 0.0), odom).any()    # without the map: all new


def test_a_person_who_stops_becomes_static_and_their_track_is_dropped(hall):
    params = TrackerParams()
    movers = [(5.0, 2.0, 0.0, 0.5, 0.3)]
    tracker, sets = run(hall, movers, WARMED + 1.0)
    assert len(sets[-1].ids) == 1
    standing = [(5.0, 2.0 + 0.5 * (WARMED + 1.0), 0.0, 0.0, 0.3)]
    _, later = run(hall, standing, params.static_after_s + 2.0, tracker=_shifted(tracker, WARMED + 1.0))
    assert len(later[-1].ids) == 0


def _shifted(tracker: MoverTracker, seconds: float) -> MoverTracker:
    """The tracker, its clock set back by `seconds` so that a second run can start at t = 0."""
    tracker.stamp_s -= seconds
    tracker.evidence.since[tracker.evidence.since >= 0] -= seconds
    return tracker


def test_clusters_measure_a_circles_centre_not_its_near_side():
    centre, radius = np.array([4.0, 0.0]), 0.3
    angles = np.linspace(-0.07, 0.07, 15)            # the beams that hit it from the origin
    world_angles = np.arctan2(centre[1], centre[0]) + angles
    # ray-circle intersection: the near side
    b = world_angles * 0
    d = np.column_stack([np.cos(world_angles), np.sin(world_angles)])
    proj = d @ centre
    r = proj - np.sqrt(np.maximum(radius ** 2 - (np.hypot(*centre) ** 2 - proj ** 2), 0)) + b
    points = d * r[:, None]
    (cluster,) = euclidean_clusters(points[np.isfinite(r)], (0.0, 0.0), TrackerParams())
    assert np.hypot(*(cluster.centre - centre)) < 0.06
    assert abs(cluster.radius - radius) < 0.05


def test_prediction_moves_the_state_and_grows_its_uncertainty():
    state, cov = predicted(np.array([1.0, 2.0, 0.5, -0.5]), np.eye(4) * 0.01, 2.0, 1.0)
    assert np.allclose(state, [2.0, 1.0, 0.5, -0.5])
    assert cov[0, 0] > 0.01 + 2.0 ** 2 * 0.01


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="cluster_tolerance"):
        TrackerParams(cluster_tolerance=0.0)
    with pytest.raises(ValueError, match="max_cluster_size"):
        TrackerParams(min_cluster_size=5, max_cluster_size=3)
    with pytest.raises(ValueError, match="older"):
        tracker = MoverTracker()
        tracker.update(1.0, (0, 0), np.zeros((0, 2)))
        tracker.update(0.5, (0, 0), np.zeros((0, 2)))


@pytest.mark.parametrize("jump", [(30.0, 0.0), (-30.0, 5.0), (0.0, -25.0)])
def test_the_evidence_grid_follows_a_robot_that_jumped_beyond_its_window(jump):
    """An odometry that jumps farther than the grid's side (a fusion restarted, a pose corrected):
    nothing of the old window lies in the new one, so it starts empty - it neither fails (it did:
    negative slices wrapped round) nor keeps cells from where the robot was."""
    from omninav.services.tracker.tracker import UNSET, EvidenceGrid
    grid = EvidenceGrid(TrackerParams())
    wall = np.column_stack([np.linspace(-2.0, 2.0, 41), np.full(41, 3.0)])
    grid.update(0.0, np.zeros(2), wall)
    assert (grid.since != UNSET).any()
    grid.update(0.1, np.asarray(jump), wall + jump)
    hit_here = grid.since != UNSET
    assert hit_here.any() and np.all(grid.since[hit_here] == 0.1)



def test_two_wide_movers_touching_in_the_scan_are_carved_along_their_tracks():
    """Two 0.5 m cylinders side by side as the lidar sees them: their arcs join in one cluster
    wider than any mover. Refused whole it was "a wall", and both tracks died while the robot
    drove at them (DynaBARN easy-25); carved along the circles where the tracks expect them, each
    is measured on its own."""
    def near_arc(centre, radius=0.5, spread=1.2, count=60):
        angles = np.arctan2(-centre[1], -centre[0]) + np.linspace(-spread, spread, count)
        return np.column_stack([centre[0] + radius * np.cos(angles), centre[1] + radius * np.sin(angles)])
    centres = np.array([[3.0, 0.0], [3.1, 1.05]])
    points = np.vstack([near_arc(c) for c in centres])
    params = TrackerParams(carve_by_tracks=True)
    assert euclidean_clusters(points, (0.0, 0.0), params) == []           # one cluster, too wide
    priors = np.column_stack([centres + [[0.05, -0.03], [-0.04, 0.06]], [0.45, 0.55]])   # tracks a little off
    clusters = euclidean_clusters(points, (0.0, 0.0), params, priors=priors)
    assert len(clusters) == 2
    for cluster, centre in zip(clusters, centres):
        assert np.hypot(*(cluster.centre - centre)) < 0.1 and cluster.radius <= params.max_cluster_radius
    fitting = TrackerParams(carve_by_tracks=True, fit_circles=True)      # no one circle fits two arcs
    assert len(euclidean_clusters(points, (0.0, 0.0), fitting, priors=priors)) == 2


def test_with_fit_circles_a_partly_hidden_cylinder_is_measured_at_its_centre():
    """A 0.5 m cylinder of which the lidar sees only one flank (the rest behind another): the
    half-circle rule puts the centre behind the middle of the flank, the circle fit at the centre."""
    centre, radius = np.array([3.0, 0.0]), 0.5
    facing = math.pi
    angles = facing + np.linspace(0.2, 1.2, 40)           # one flank only
    rng = np.random.default_rng(0)
    points = centre + (radius + rng.normal(0.0, 0.005, len(angles)))[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    (plain,) = euclidean_clusters(points, (0.0, 0.0), TrackerParams())
    (fitted,) = euclidean_clusters(points, (0.0, 0.0), TrackerParams(fit_circles=True))
    assert np.hypot(*(fitted.centre - centre)) < 0.03 and abs(fitted.radius - radius) < 0.03
    assert np.hypot(*(plain.centre - centre)) > 0.1


def _arc(centre, radius=0.5, spread=1.2, count=60) -> np.ndarray:
    """The side of a cylinder a lidar at the origin sees."""
    angles = np.arctan2(-centre[1], -centre[0]) + np.linspace(-spread, spread, count)
    return np.column_stack([centre[0] + radius * np.cos(angles), centre[1] + radius * np.sin(angles)])


def test_one_cylinder_two_tracks_claim_is_measured_whole_not_carved_into_fragments():
    """Two tracks of 0.25 m on the two halves of one 0.5 m cylinder (a sliver coming out from behind
    another started a second track): carved along them, each scan measured two fragments and kept
    the cylinder split, the tracks' velocities 50° apart (DynaBARN hard-20). An arc one circle fits
    is one mover."""
    centre = np.array([3.0, 0.0])
    points = _arc(centre)
    priors = np.array([[2.75, -0.25, 0.25], [2.75, 0.25, 0.25]])
    carved = euclidean_clusters(points, (0.0, 0.0), TrackerParams(carve_by_tracks=True), priors=priors)
    assert len(carved) == 2                                               # without the fit
    params = TrackerParams(carve_by_tracks=True, fit_circles=True)
    (whole,) = euclidean_clusters(points, (0.0, 0.0), params, priors=priors)
    assert np.hypot(*(whole.centre - centre)) < 0.03 and abs(whole.radius - 0.5) < 0.03


def test_a_track_inside_another_tracks_circle_is_dropped_the_older_kept():
    """Two solid movers cannot overlap: a track whose centre lies inside the circle of one with more
    hits is the same mover tracked twice, and only the older stays."""
    params = TrackerParams(carve_by_tracks=True, fit_circles=True)
    tracker = MoverTracker(params)
    tracker.warm_until_s = math.inf                        # no restart once the walls are known
    older = Track(1, np.array([3.0, 0.0, 1.0, 0.0]), np.eye(4) * 0.01, 0.5, hits=12, moved=True)
    younger = Track(2, np.array([2.8, 0.2, 0.2, 1.0]), np.eye(4) * 0.01, 0.25, hits=5, moved=True)
    apart = Track(3, np.array([3.0, 1.2, 0.0, 1.0]), np.eye(4) * 0.01, 0.5, hits=3, moved=True)
    tracker.tracks = [younger, older, apart]
    tracker.stamp_s = 0.0
    tracker.update(0.0, (0.0, 0.0), np.vstack([_arc(np.array([3.0, 0.0])), _arc(np.array([3.0, 1.2]))]))
    assert [t.id for t in tracker.tracks] == [1, 3]
    without = MoverTracker(TrackerParams())
    without.warm_until_s = math.inf
    without.tracks, without.stamp_s = [Track(**vars(t)) for t in (younger, older, apart)], 0.0
    without.update(0.0, (0.0, 0.0), np.vstack([_arc(np.array([3.0, 0.0])), _arc(np.array([3.0, 1.2]))]))
    assert len(without.tracks) == 3
