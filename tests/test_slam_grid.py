"""The SLAM grid: beams clear the cells they cross and mark their end; tiles are shared copy-on-write."""
import math

import numpy as np
import pytest

from omninav.geometry.grid import world_to_cell
from omninav.services.slam.particle_grids import TILE, GridGeometry, TiledGrids, cut_beams, segment_cells

L_OCC, L_FREE, L_MAX = 0.85, -0.4, 5.0


def grids(n_maps=1, capacity=64, size=4.0, delta=0.1):
    return TiledGrids(GridGeometry.from_extent(-size, -size, size, size, delta), n_maps, capacity)


def cell(g, x, y):
    u, v = g.grid_coords(x, y)
    return int(math.floor(v)), int(math.floor(u))


def test_a_beam_clears_the_cells_it_crosses_and_marks_its_end():
    g = grids()
    g.integrate(0, (0.05, 0.05), np.array([0.75]), np.array([0.05]), np.array([True]), L_OCC, L_FREE, L_MAX)
    l = g.logodds(0)
    row, col0 = cell(g, 0.05, 0.05)
    _, col_end = cell(g, 0.75, 0.05)
    assert col_end == col0 + 7
    assert np.allclose(l[row, col0:col_end], L_FREE)
    assert l[row, col_end] == pytest.approx(L_OCC)
    touched = np.zeros(l.shape, bool)
    touched[row, col0:col_end + 1] = True
    assert not l[~touched].any(), "nothing but the beam's cells may change"


def test_a_cell_keeps_the_mean_of_the_end_points_that_hit_it():
    g = grids()
    ends_x, ends_y = np.array([0.72, 0.78, 0.74]), np.array([0.01, 0.09, 0.02])   # all in one 0.1 m cell
    g.integrate(0, (0.05, 0.05), ends_x, ends_y, np.array([True, True, True]), L_OCC, L_FREE, L_MAX)
    g.integrate(0, (0.05, 0.05), np.array([0.76]), np.array([0.05]), np.array([False]), L_OCC, L_FREE, L_MAX)
    x, y, n = g.mean_hit(0, *cell(g, 0.75, 0.05))
    assert n == 3, "a beam that is cut there (no hit) does not count"
    assert x == pytest.approx(ends_x.mean(), abs=1e-5) and y == pytest.approx(ends_y.mean(), abs=1e-5)
    x, y, n = g.mean_hit(0, *cell(g, 0.45, 0.05))
    assert (x, y, n) == (pytest.approx(0.45, abs=1e-5), pytest.approx(0.05, abs=1e-5), 0), "a cell only crossed"


def test_a_beam_without_a_hit_only_clears():
    g = grids()
    g.integrate(0, (0.05, 0.05), np.array([0.05]), np.array([-0.95]), np.array([False]), L_OCC, L_FREE, L_MAX)
    l = g.logodds(0)
    assert (l <= 0).all() and np.count_nonzero(l) == 11  # the start cell, the 10 below it
    assert l[cell(g, 0.05, -0.95)] == pytest.approx(L_FREE)


def test_cut_beams_drops_no_returns_and_cuts_long_beams_to_free_space():
    angles = np.zeros(6)
    ranges = np.array([2.0, 9.0, 30.0, np.inf, np.nan, 0.0])  # hit, beyond maxUrange, no return, ...
    x, y, hit = cut_beams(ranges, angles, range_min=0.0, max_range=29.99, max_urange=5.0)
    assert np.allclose(x, [2.0, 5.0]) and np.allclose(y, 0.0)
    assert list(hit) == [True, False]


def test_log_odds_are_clamped():
    g = grids()
    for _ in range(20):
        g.integrate(0, (0.05, 0.05), np.array([0.55]), np.array([0.05]), np.array([True]), L_OCC, L_FREE, L_MAX)
    l = g.logodds(0)
    assert l.max() == pytest.approx(L_MAX) and l.min() == pytest.approx(-L_MAX)


def test_segment_traversal_is_connected_and_covers_every_point_of_the_segment():
    rng = np.random.default_rng(3)
    rows, cols = np.empty(200, np.int64), np.empty(200, np.int64)
    for _ in range(200):
        u0, v0, u1, v1 = rng.uniform(-20, 20, 4)
        n = segment_cells(u0, v0, u1, v1, rows, cols)
        path = set(zip(rows[:n].tolist(), cols[:n].tolist()))
        assert len(path) == n, "no cell twice"
        steps = np.abs(np.diff(rows[:n])) + np.abs(np.diff(cols[:n]))
        assert (steps == 1).all(), "4-connected"
        assert (rows[0], cols[0]) == (math.floor(v0), math.floor(u0))
        assert (rows[n - 1], cols[n - 1]) == (math.floor(v1), math.floor(u1))
        t = np.linspace(0.001, 0.999, 400)
        samples = set(zip(np.floor(v0 + t * (v1 - v0)).astype(int).tolist(),
                          np.floor(u0 + t * (u1 - u0)).astype(int).tolist()))
        assert samples <= path


def scan_fan(g, index, origin, radius=1.5, beams=90):
    a = np.linspace(0, 2 * np.pi, beams, endpoint=False)
    g.integrate(index, origin, origin[0] + radius * np.cos(a), origin[1] + radius * np.sin(a),
                np.ones(beams, bool), L_OCC, L_FREE, L_MAX)


def test_resampled_maps_share_tiles_until_one_writes():
    g = grids(n_maps=3)
    scan_fan(g, 0, (0.0, 0.0))
    alone = g.tiles_in_use()
    g.resample([0, 0, 0])
    assert g.tiles_in_use() == alone, "copies share every tile"
    before = g.logodds(0).copy()
    scan_fan(g, 1, (0.3, 0.2))
    assert np.array_equal(g.logodds(0), before), "a write to one map never shows in another"
    assert np.array_equal(g.logodds(2), before)
    assert not np.array_equal(g.logodds(1), before)
    assert alone < g.tiles_in_use() <= 2 * alone + 8
    g.resample([1, 1, 1])  # map 0's own tiles are referenced by no one now
    assert g.tiles_in_use() < 2 * alone
    assert all(np.array_equal(g.logodds(i), g.logodds(1)) for i in range(3))
    assert g.bytes_in_use() == g.tiles_in_use() * TILE * TILE * (4 + 3 * 2) + g.tables.nbytes


def test_the_tile_pool_grows_without_changing_the_result():
    small, large = grids(capacity=1), grids(capacity=512)
    for g in (small, large):
        scan_fan(g, 0, (0.0, 0.0), radius=3.5, beams=360)
    assert small.pool.shape[0] > 1
    assert np.array_equal(small.logodds(0), large.logodds(0))


def test_the_occupancy_grid_follows_the_map_server_cell_convention():
    g = grids()
    scan_fan(g, 0, (0.0, 0.0), radius=1.0, beams=360)
    grid = g.occupancy_grid(0, occ_thresh=0.65, stamp_ns=7)
    assert grid.header.stamp_ns == 7 and grid.info.resolution == pytest.approx(0.1)
    row, col = world_to_cell(grid.info, 1.0 * np.cos(0.3), 1.0 * np.sin(0.3))
    assert grid.data[row, col] == 100
    row, col = world_to_cell(grid.info, 0.3, 0.2)
    assert grid.data[row, col] == 0
    assert (grid.data == -1).any() and set(np.unique(grid.data)) <= {-1, 0, 100}
