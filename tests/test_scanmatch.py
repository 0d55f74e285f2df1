"""The scan matcher recovers known offsets on a map built from exact scans of the room world."""
import numpy as np
import pytest

from omninav.services.slam import scanmatch as sm
from omninav.services.slam.particle_grids import GridGeometry, TiledGrids, cut_beams
from omninav.sim.lidar import cast
from omninav.sim.world import load_world, world_path

DELTA = 0.05
ANGLES = np.linspace(-np.pi, np.pi, 360, endpoint=False)
L_OCC = 0.85
SIGMA = 0.05
NO_PRIOR = np.zeros(3)


@pytest.fixture(scope="module")
def room():
    world = load_world(world_path("room"))
    grids = TiledGrids(GridGeometry.from_extent(-1.0, -1.0, 11.0, 9.0, DELTA))
    for pose in [(2.0, 2.0, 0.0), (5.0, 3.0, 1.0), (8.0, 4.0, 2.0), (4.0, 5.5, -1.0), (1.5, 4.0, 0.5)]:
        x, y, hit = beams(world, pose)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        grids.integrate(0, pose[:2], pose[0] + c * x - s * y, pose[1] + s * x + c * y, hit, L_OCC, -0.4, 5.0)
    return world, grids


def beams(world, pose):
    ranges = cast(world, pose[0], pose[1], pose[2] + ANGLES, max_range=12.0)
    return cut_beams(ranges, ANGLES, 0.0, 12.0, 11.0)


def setup(room, true_pose):
    world, grids = room
    x, y, hit = beams(world, true_pose)
    geo = np.array([grids.geometry.xmin, grids.geometry.ymin, 1.0 / DELTA])
    kernel = sm.gaussian_kernel(1, DELTA, SIGMA)
    return grids, geo, np.ascontiguousarray(x[hit]), np.ascontiguousarray(y[hit]), kernel


TRUE = np.array([4.3, 3.6, 0.4])


@pytest.mark.parametrize("offset", [(0.06, -0.04, 0.03), (-0.05, 0.07, -0.04), (0.0, 0.0, 0.06)])
def test_refinement_recovers_a_small_offset(room, offset):
    grids, geo, px, py, kernel = setup(room, TRUE)
    guess = TRUE + offset
    x, y, th, score = sm.refine(grids.pool, grids.hits, grids.tables[0], geo, px, py, *guess, kernel, SIGMA,
                                1 / L_OCC, 20, False, guess, NO_PRIOR)
    # the map quantises walls to 5 cm cells: a pose within a fifth of a cell is a recovered one
    assert np.hypot(x - TRUE[0], y - TRUE[1]) < 0.01
    assert abs(th - TRUE[2]) < 0.003
    assert score > 0.8


BOX = (0.013, 0.013, 4.013, 3.013)   # walls 13 mm into their cells: the cell centres are 12 mm off


def box_beams(pose):
    """Exact beams from inside the rectangle BOX."""
    dx, dy = np.cos(pose[2] + ANGLES), np.sin(pose[2] + ANGLES)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (BOX[2] - pose[0]) / dx, np.where(dx < 0, (BOX[0] - pose[0]) / dx, np.inf))
        ty = np.where(dy > 0, (BOX[3] - pose[1]) / dy, np.where(dy < 0, (BOX[1] - pose[1]) / dy, np.inf))
    return cut_beams(np.minimum(tx, ty), ANGLES, 0.0, 12.0, 11.0)


def test_the_hit_point_field_places_walls_inside_their_cells():
    grids = TiledGrids(GridGeometry.from_extent(-1.0, -1.0, 5.0, 4.0, DELTA))
    rng = np.random.default_rng(0)
    for x in np.linspace(0.8, 3.2, 5):
        for y in np.linspace(0.8, 2.2, 3):
            pose = (x, y, rng.uniform(-np.pi, np.pi))
            bx, by, hit = box_beams(pose)
            c, s = np.cos(pose[2]), np.sin(pose[2])
            grids.integrate(0, pose[:2], x + c * bx - s * by, y + s * bx + c * by, hit, L_OCC, -0.4, 5.0)
    geo = np.array([grids.geometry.xmin, grids.geometry.ymin, 1.0 / DELTA])
    kernel = sm.gaussian_kernel(1, DELTA, SIGMA)
    true = np.array([2.1, 1.3, 0.3])
    px, py, _ = box_beams(true)
    args = (grids.pool, grids.hits, grids.tables[0], geo, px, py)
    guess = true + (0.02, -0.015, 0.0)
    on_cells = sm.refine(*args, *guess, kernel, SIGMA, 1 / L_OCC, 20, False, guess, NO_PRIOR)
    assert np.hypot(on_cells[0] - true[0], on_cells[1] - true[1]) > 0.01, "the cell field puts walls at cell centres"
    on_points = sm.refine(*args, *on_cells[:3], kernel, SIGMA, 1 / L_OCC, sm.POLISH_ITERATIONS, True, guess,
                          NO_PRIOR)
    assert np.hypot(on_points[0] - true[0], on_points[1] - true[1]) < 0.005
    matched = sm.match_one(*args, *guess, kernel, kernel, SIGMA, 1 / L_OCC, 20, 0.5, 0.2, 0.1, 0.2, 0.02, guess,
                           NO_PRIOR)
    assert np.allclose(matched[:3], on_points[:3]), "a match is polished on the hit point field"
    assert matched[3] == pytest.approx(on_cells[3]), "its score is the cell field's"


def test_the_correlative_search_recovers_a_large_offset(room):
    grids, geo, px, py, kernel = setup(room, TRUE)
    guess = TRUE + (0.5, -0.4, 0.3)
    plain = sm.refine(grids.pool, grids.hits, grids.tables[0], geo, px, py, *guess, kernel, SIGMA, 1 / L_OCC, 20,
                      False, guess, NO_PRIOR)
    assert np.hypot(plain[0] - TRUE[0], plain[1] - TRUE[1]) > 0.05, "too far for refinement alone"
    coarse = sm.gaussian_kernel(2, DELTA, 0.1)
    x, y, th, score = sm.match_one(grids.pool, grids.hits, grids.tables[0], geo, px, py, *guess, kernel, coarse, SIGMA,
                                   1 / L_OCC, 20, 0.9, 0.6, 0.1, 0.4, 0.02, guess, NO_PRIOR)
    assert np.hypot(x - TRUE[0], y - TRUE[1]) < 0.01 and abs(th - TRUE[2]) < 0.003
    assert score > plain[3]


def test_the_likelihood_is_highest_at_the_true_pose(room):
    grids, geo, px, py, _ = setup(room, TRUE)
    at = lambda pose: sm.log_likelihood(grids.pool, grids.tables[0], geo, px, py, *pose, 2, 0.075, 1 / L_OCC)
    best = at(TRUE)
    for offset in [(0.05, 0, 0), (0, -0.05, 0), (0, 0, 0.02), (0.1, 0.1, 0)]:
        assert at(TRUE + offset) < best


def test_match_all_matches_each_particle_against_its_own_map(room):
    grids, geo, px, py, kernel = setup(room, TRUE)
    two = TiledGrids(grids.geometry, 2)
    two.pool, two.hits, two.refs, two.free, two.free_top = (grids.pool, grids.hits, grids.refs.copy(), grids.free,
                                                           grids.free_top)
    two.tables = np.stack([grids.tables[0], np.full_like(grids.tables[0], -1)])  # map 1 is empty
    guesses = np.array([TRUE + (0.05, 0.03, 0.02), TRUE + (0.05, 0.03, 0.02)])
    poses, scores, loglik = sm.match_all(two.pool, two.hits, two.tables, geo, px, py, guesses, kernel, kernel, SIGMA,
                                         1 / L_OCC, 20, 0.0, 0.5, 0.3, 0.1, 0.2, 0.02, 2, 0.075, guesses, NO_PRIOR)
    assert np.hypot(*(poses[0, :2] - TRUE[:2])) < 0.01
    assert np.allclose(poses[1], guesses[1]), "an empty map keeps the guess"
    assert scores[1] == 0.0 and scores[0] > 0.8
    assert loglik[0] > loglik[1]


def test_a_match_below_the_minimum_score_keeps_the_guess(room):
    grids, geo, px, py, kernel = setup(room, TRUE)
    guess = np.array([TRUE + (0.05, 0.03, 0.02)])
    args = (grids.pool, grids.hits, grids.tables[:1], geo, px, py, guess, kernel, kernel, SIGMA, 1 / L_OCC, 20)
    kept, scores, loglik = sm.match_all(*args, 0.99, 0.0, 0.0, 0.1, 0.0, 0.02, 2, 0.075, guess, NO_PRIOR)
    assert scores[0] < 0.99 and np.array_equal(kept, guess)
    matched, _, better = sm.match_all(*args, 0.0, 0.0, 0.0, 0.1, 0.0, 0.02, 2, 0.075, guess, NO_PRIOR)
    assert not np.array_equal(matched, guess) and better[0] > loglik[0], "the likelihood is taken where the pose is"


def corridor_ranges(pose, end_x):
    """Exact ranges in a corridor between walls y = 0 and y = 2, closed at x = end_x (ahead)."""
    dx, dy = np.cos(pose[2] + ANGLES), np.sin(pose[2] + ANGLES)
    with np.errstate(divide="ignore"):
        ty = np.where(dy > 0, (2.0 - pose[1]) / dy, np.where(dy < 0, -pose[1] / dy, np.inf))
        tx = np.where(dx > 0, (end_x - pose[0]) / dx, np.inf)
    return np.minimum(tx, ty)


def test_the_odometry_prior_holds_a_corridor_match_along_the_corridor_only():
    """The corridor's end wall, 8 m ahead, was mapped 5 cm too far (as a drifted pose would map it):
    the only thing that tells x. Odometry is right. The prior keeps x near the odometry, while the
    3 cm across the corridor, which every wall point sees, are still corrected."""
    grids = TiledGrids(GridGeometry.from_extent(-8.0, -1.0, 10.0, 3.0, DELTA))
    for x in np.linspace(-6.0, 0.0, 13):
        pose = (x, 1.0 + 0.1 * np.sin(x), 0.0)
        bx, by, hit = cut_beams(corridor_ranges(pose, 8.05), ANGLES, 0.0, 12.0, 11.0)
        grids.integrate(0, pose[:2], pose[0] + bx, pose[1] + by, hit, L_OCC, -0.4, 5.0)
    true = np.array([0.3, 1.0, 0.0])
    bx, by, hit = cut_beams(corridor_ranges(true, 8.0), ANGLES, 0.0, 12.0, 11.0)
    geo = np.array([grids.geometry.xmin, grids.geometry.ymin, 1.0 / DELTA])
    kernel = sm.gaussian_kernel(1, DELTA, SIGMA)
    odometry = true + (0.0, 0.03, 0.0)

    def match(prior, weights):
        return np.array(sm.match_one(grids.pool, grids.hits, grids.tables[0], geo, np.ascontiguousarray(bx[hit]),
                                     np.ascontiguousarray(by[hit]), *odometry, kernel, kernel, SIGMA, 1 / L_OCC, 10,
                                     0.5, 0.2, 0.1, 0.2, 0.02, prior, weights)[:3]) - true

    free = match(odometry, NO_PRIOR)
    assert free[0] > 0.03 and abs(free[1]) < 0.005, "without the prior the end wall drags x along"
    weights = np.array([3.0, 3.0, 12.0]) ** 2
    held = match(odometry, weights)
    assert abs(held[0]) < 0.015 and abs(held[1]) < 0.01
    assert np.allclose(match(odometry + (0.0, 0.0, 2 * np.pi), weights), held), "the prior's heading is an angle"
