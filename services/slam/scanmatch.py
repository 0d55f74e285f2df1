"""Scan-to-map matching on a particle's own grid: a correlative search, then Gauss-Newton.

The matching field. Each cell's occupancy evidence o = clamp(log-odds / l_occ, 0, 1) (one hit is
full evidence; free and unknown cells are 0). At each cell centre the field is
S = max over the (2·kernelSize + 1)² cells around it of o · exp(−d² / 2σ²), d their distance —
a likelihood field of the nearest obstacle, computed on the fly from the log-odds, so no particle
has to keep a distance transform up to date. Between cell centres S is interpolated bilinearly,
which makes it continuous with a gradient everywhere (Hector SLAM's trick), so a pose can be
refined below the cell size.

match_one(): start from the guess; refine by Gauss-Newton on Σ (1 − S(p_i))² over the scan's end
points p_i (Levenberg damping, a step is taken only if it lowers the cost). The score is the mean
S over the points (1: every end point on an obstacle cell). When that score is below
`search_below` (a poor start: an odometry glitch, a loop coming back to old parts of the map), an
exhaustive correlative search picks a new start — coarse first (steps lstep, astep over ±window,
±angle, on a field twice as wide, 60 of the end points), then half steps around its best (the
normal field, every end point), the field read at the nearest cell centre — and the refinement
runs again from there; the better result wins.

That field knows obstacles only as cell centres: a wall 1 cm into its cell is put 1.5 cm off,
and a wall on a cell border, hit in both cells, leaves a flat stretch between their centres
along which a match slides at no cost; on a route such slips add up to drift. So the result is
polished (a few Gauss-Newton steps) on the hit point field: around an end point p, the best over
the cells within kernelSize + 1½ cells of o · exp(−|p − m|² / 2σ²), m the cell's mean hit point
(grid.py), cut and shifted to zero at that distance so it stays continuous. That field peaks on
the surfaces themselves, but it ripples along a wall whose cells were hit only a few times (the
mean points are spaced a cell apart), and its basin is narrow: it only polishes a good match.
A pose that needed the search (a loop closing, where the map may hold an old and a new copy of
a wall) is not polished. The score returned is the cell field's, so minimumScore and
search_below keep their meaning.

The odometry prior (translation_weight, rotation_weight; Cartographer's ceres scan matcher):
each refinement also pulls towards a prior pose — the particle's pose moved by the odometry —
so a direction the scan hardly constrains (along a corridor) follows the odometry instead of
small biases of the map that add up from match to match (docs/slam.md: the office route drifted
9 cm in x without it). After a search that won, the pull is towards the search's best.

The particle weight uses a separate, sharper likelihood: each end point's squared distance to
the nearest obstacle cell centre within kernelSize + 1 cells (capped there), over 2·lsigma².
It stays on cell centres: on mean hit points the likelihood no longer told the particles apart
(polished onto the same surfaces), the filter never resampled on MIT CSAIL and every particle
kept a map of its own (7.9 MB per particle instead of 1.7 MB, both polishing `iterations` steps).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .particle_grids import HIT_SCALE, TILE_BITS, TILE_MASK

INV_HIT_SCALE = 1.0 / HIT_SCALE


@njit(cache=True, inline="always")
def _evidence(pool, table, row, col, inv_l_occ):
    if row < 0 or col < 0:
        return 0.0
    tr, tc = row >> TILE_BITS, col >> TILE_BITS
    if tr >= table.shape[0] or tc >= table.shape[1]:
        return 0.0
    tile = table[tr, tc]
    if tile < 0:
        return 0.0
    value = pool[tile, row & TILE_MASK, col & TILE_MASK] * inv_l_occ
    return min(max(value, 0.0), 1.0)


# called, not inlined (nor _load_points): they run on a cache miss only, once per cell (block) and
# particle map, and a copy at each call site of the inlined helpers above them cost seconds of compile
@njit(cache=True, _nrt=False)
def _node(pool, table, row, col, kernel, inv_l_occ):
    """The field at the centre of cell (row, col)."""
    k = (kernel.shape[0] - 1) // 2
    best = 0.0
    for dr in range(-k, k + 1):
        for dc in range(-k, k + 1):
            o = _evidence(pool, table, row + dr, col + dc, inv_l_occ)
            if o > 0.0:
                best = max(best, o * kernel[dr + k, dc + k])
    return best


@njit(cache=True, inline="always")
def _cached_node(pool, table, row, col, kernel, inv_l_occ, cache):
    """_node, computed once per cell of the area `cache` (field_cache) covers and kept there: a
    refinement reads the same few cells around the end points at every step."""
    values, stamps, frame = cache[0], cache[1], cache[2]
    i, j = row - frame[0], col - frame[1]
    if 0 <= i < values.shape[0] and 0 <= j < values.shape[1]:
        if stamps[i, j] != frame[2]:
            values[i, j] = _node(pool, table, row, col, kernel, inv_l_occ)
            stamps[i, j] = frame[2]
        return values[i, j]
    return _node(pool, table, row, col, kernel, inv_l_occ)


@njit(cache=True)
def field_cache(geo, px, py, poses, margin):
    """An empty cache of field values for the cells the end points (px, py) fall in from any of
    `poses`, and `margin` cells around: (node values, their stamps, frame, hit point blocks' first
    entry, their number of entries, their stamps, entries). A value is current when its stamp
    equals frame[2]; frame[:2] is the area's first (row, col), frame[3] the entries in use. Set
    frame[2] to a new value and frame[3] to 0 to empty it (another particle's map)."""
    xmin, ymin, inv_delta = geo[0], geo[1], geo[2]
    row0, row1, col0, col1 = 1 << 62, -(1 << 62), 1 << 62, -(1 << 62)
    for k in range(poses.shape[0]):
        x, y, th = poses[k, 0], poses[k, 1], poses[k, 2]
        c, s = math.cos(th), math.sin(th)
        for i in range(px.shape[0]):
            row = int(math.floor((y + s * px[i] + c * py[i] - ymin) * inv_delta))
            col = int(math.floor((x + c * px[i] - s * py[i] - xmin) * inv_delta))
            row0, row1, col0, col1 = min(row0, row), max(row1, row), min(col0, col), max(col1, col)
    if row1 < row0:
        row0, row1, col0, col1 = 0, -1, 0, -1
    shape = (row1 - row0 + 1 + 2 * margin, col1 - col0 + 1 + 2 * margin)
    return (np.empty(shape), np.zeros(shape, np.int64), np.array([row0 - margin, col0 - margin, 1, 0]),
            np.empty(shape, np.int64), np.empty(shape, np.int64), np.zeros(shape, np.int64),
            np.empty((BLOCK_ENTRIES * px.shape[0], 3)))


BLOCK_ENTRIES = 64  # hit point block entries kept per end point (beyond: computed without the cache)


@njit(cache=True)
def _one_pose(x, y, th):
    poses = np.empty((1, 3))
    poses[0, 0], poses[0, 1], poses[0, 2] = x, y, th
    return poses


@njit(cache=True, inline="always")
def _cell_field(pool, table, u, v, kernel, inv_l_occ, cache):
    """The field of cell centres interpolated bilinearly at grid coordinates (u, v), and its gradient (per cell)."""
    a, b = u - 0.5, v - 0.5
    c0, r0 = int(math.floor(a)), int(math.floor(b))
    s00 = _cached_node(pool, table, r0, c0, kernel, inv_l_occ, cache)
    s01 = _cached_node(pool, table, r0, c0 + 1, kernel, inv_l_occ, cache)
    s10 = _cached_node(pool, table, r0 + 1, c0, kernel, inv_l_occ, cache)
    s11 = _cached_node(pool, table, r0 + 1, c0 + 1, kernel, inv_l_occ, cache)
    fu, fv = a - c0, b - r0
    s = (1 - fv) * ((1 - fu) * s00 + fu * s01) + fv * ((1 - fu) * s10 + fu * s11)
    ds_du = (1 - fv) * (s01 - s00) + fv * (s11 - s10)
    ds_dv = (1 - fu) * (s10 - s00) + fu * (s11 - s01)
    return s, ds_du, ds_dv


@njit(cache=True, _nrt=False)
def _load_points(pool, hits, table, row0, col0, m, inv_l_occ, entries, first):
    """Evidence and mean hit point (grid coordinates) of each cell with evidence among the m × m
    from (row0, col0) on, row by row, into entries[first:]; returns how many. Most blocks lie
    inside one tile: then the tile is looked up once."""
    last_r, last_c = row0 + m - 1, col0 + m - 1
    one_tile = (row0 >= 0 and col0 >= 0 and row0 >> TILE_BITS == last_r >> TILE_BITS
                and col0 >> TILE_BITS == last_c >> TILE_BITS
                and last_r >> TILE_BITS < table.shape[0] and last_c >> TILE_BITS < table.shape[1])
    block_tile = table[row0 >> TILE_BITS, col0 >> TILE_BITS] if one_tile else -1
    if one_tile and block_tile < 0:
        return 0
    k = first
    for i in range(m):
        for j in range(m):
            row, col = row0 + i, col0 + j
            if one_tile:
                tile = block_tile
                o = min(max(pool[tile, row & TILE_MASK, col & TILE_MASK] * inv_l_occ, 0.0), 1.0)
            else:
                o = _evidence(pool, table, row, col, inv_l_occ)
                tile = table[row >> TILE_BITS, col >> TILE_BITS] if o > 0.0 else -1
            if o > 0.0:
                entries[k, 0] = o
                entries[k, 1] = col + hits[tile, row & TILE_MASK, col & TILE_MASK, 0] * INV_HIT_SCALE
                entries[k, 2] = row + hits[tile, row & TILE_MASK, col & TILE_MASK, 1] * INV_HIT_SCALE
                k += 1
    return k - first


@njit(cache=True, inline="always")
def _point_field(pool, hits, table, u, v, reach, inv_two_sigma2, floor, inv_l_occ, cache):
    """The field at grid coordinates (u, v) and its gradient (per cell): the best over the cells
    around of evidence × a Gaussian of the distance to the cell's mean hit point, cut (and shifted
    to zero) at reach + ½ cells — the block of (2·reach + 2)² cells read holds every hit point that
    close. The block's cells with evidence are kept in `cache` (field_cache): the polish reads the
    same blocks at every step."""
    frame, starts, counts, stamps, entries = cache[2], cache[3], cache[4], cache[5], cache[6]
    m = 2 * reach + 2
    row0, col0 = int(math.floor(v - 0.5)) - reach, int(math.floor(u - 0.5)) - reach
    i, j = row0 - frame[0], col0 - frame[1]
    if 0 <= i < starts.shape[0] and 0 <= j < starts.shape[1] and (
            stamps[i, j] == frame[2] or frame[3] + 2 * m * m <= entries.shape[0]):
        if stamps[i, j] != frame[2]:
            starts[i, j] = frame[3]
            counts[i, j] = _load_points(pool, hits, table, row0, col0, m, inv_l_occ, entries, frame[3])
            stamps[i, j] = frame[2]
            frame[3] += counts[i, j]
        first, count = starts[i, j], counts[i, j]
    else:   # outside the cache, or it is full: the block goes into the entries' last m² rows, kept spare
        first = entries.shape[0] - m * m
        count = _load_points(pool, hits, table, row0, col0, m, inv_l_occ, entries, first) if first >= 0 else 0
    cut2 = (reach + 0.5) * (reach + 0.5)
    best, best_du, best_dv = 0.0, 0.0, 0.0
    for e in range(first, first + count):
        o = entries[e, 0]
        du, dv = u - entries[e, 1], v - entries[e, 2]
        d2 = du * du + dv * dv
        if d2 >= cut2:
            continue
        g = math.exp(-d2 * inv_two_sigma2)
        value = o * (g - floor) / (1.0 - floor)
        if value > best:
            slope = -2.0 * inv_two_sigma2 * o * g / (1.0 - floor)
            best, best_du, best_dv = value, slope * du, slope * dv
    return best, best_du, best_dv


@njit(cache=True, _nrt=False)
def _linearize(pool, hits, table, geo, px, py, x, y, th, kernel, points, inv_two_sigma2, floor, inv_l_occ, prior,
               prior_weight, h, g, cache):
    """Cost Σ (1 − S)² over the N end points + N · Σ prior_weight · (pose − prior)², and the score (mean
    S), at a pose on the cell field, or with `points` on the hit point field; fills in the
    Gauss-Newton system h, g."""
    xmin, ymin, inv_delta = geo[0], geo[1], geo[2]
    reach = (kernel.shape[0] - 1) // 2
    c, s = math.cos(th), math.sin(th)
    h[:] = 0.0
    g[:] = 0.0
    cost, total = 0.0, 0.0
    for i in range(px.shape[0]):
        wx, wy = c * px[i] - s * py[i], s * px[i] + c * py[i]
        u, v = (x + wx - xmin) * inv_delta, (y + wy - ymin) * inv_delta
        if points:
            f, du, dv = _point_field(pool, hits, table, u, v, reach + 1, inv_two_sigma2, floor, inv_l_occ, cache)
        else:
            f, du, dv = _cell_field(pool, table, u, v, kernel, inv_l_occ, cache)
        r = 1.0 - f
        cost += r * r
        total += f
        if du == 0.0 and dv == 0.0:
            continue
        # the residual's Jacobian: −∇S · ∂p/∂(x, y, θ)
        j0, j1 = -du * inv_delta, -dv * inv_delta
        j2 = j0 * -wy + j1 * wx
        g[0] += j0 * r
        g[1] += j1 * r
        g[2] += j2 * r
        h[0, 0] += j0 * j0
        h[0, 1] += j0 * j1
        h[0, 2] += j0 * j2
        h[1, 1] += j1 * j1
        h[1, 2] += j1 * j2
        h[2, 2] += j2 * j2
    # the prior's residuals are Cartographer's weight · (pose − prior); squared and times N here, as
    # the scan's N residuals are summed where Cartographer scales each by 1/√N
    n = px.shape[0]
    turn = (th - prior[2] + math.pi) % (2.0 * math.pi) - math.pi
    for d, value in enumerate((x - prior[0], y - prior[1], turn)):
        w = n * prior_weight[d]
        cost += w * value * value
        g[d] += w * value
        h[d, d] += w
    h[1, 0], h[2, 0], h[2, 1] = h[0, 1], h[0, 2], h[1, 2]
    return cost, total / max(n, 1)


@njit(cache=True)
def refine(pool, hits, table, geo, px, py, x, y, th, kernel, sigma, inv_l_occ, iterations, points, prior,
           prior_weight):
    """Gauss-Newton with Levenberg damping from (x, y, th) on the cell field (kernel), or with
    `points` on the hit point field (a Gaussian of width sigma, m, cut at kernelSize + 1½ cells),
    pulled towards the pose `prior` with prior_weight (x, y, θ; per end point, see _linearize);
    returns (x, y, th, score)."""
    return _refine(pool, hits, table, geo, px, py, x, y, th, kernel, sigma, inv_l_occ, iterations, points, prior,
                   prior_weight, field_cache(geo, px, py, _one_pose(x, y, th), np.int64(NODE_MARGIN)))


NODE_MARGIN = 4  # cells around the end points at the start pose that a refinement keeps field values of


@njit(cache=True)
def _refine(pool, hits, table, geo, px, py, x, y, th, kernel, sigma, inv_l_occ, iterations, points, prior,
            prior_weight, cache):
    """refine() with `cache` (field_cache) over `table`, of the cell field's kernel."""
    reach = (kernel.shape[0] - 1) // 2
    inv_two_sigma2 = 1.0 / (2.0 * (sigma * geo[2]) ** 2)
    floor = math.exp(-(reach + 1.5) ** 2 * inv_two_sigma2)
    h, g = np.zeros((3, 3)), np.zeros(3)
    h_new, g_new = np.zeros((3, 3)), np.zeros(3)
    cost, score = _linearize(pool, hits, table, geo, px, py, x, y, th, kernel, points, inv_two_sigma2, floor,
                             inv_l_occ, prior, prior_weight, h, g, cache)
    damping = 1e-3
    for _ in range(iterations):
        if h[0, 0] + h[1, 1] + h[2, 2] == 0.0:
            break
        improved = False
        step = np.zeros(3)
        for _try in range(5):
            a = h.copy()
            for d in range(3):
                a[d, d] += damping * h[d, d] + 1e-9
            step = np.linalg.solve(a, -g)
            nx, ny, nth = x + step[0], y + step[1], th + step[2]
            new_cost, new_score = _linearize(pool, hits, table, geo, px, py, nx, ny, nth, kernel, points,
                                             inv_two_sigma2, floor, inv_l_occ, prior, prior_weight, h_new,
                                             g_new, cache)
            if new_cost < cost:
                x, y, th, cost, score = nx, ny, nth, new_cost, new_score
                h[:, :] = h_new
                g[:] = g_new
                damping = max(damping * 0.3, 1e-6)
                improved = True
                break
            damping *= 10.0
        if not improved or (abs(step[0]) + abs(step[1]) < 1e-5 and abs(step[2]) < 1e-6):
            break
    return x, y, th, score


@njit(cache=True)
def search(pool, table, geo, px, py, x, y, th, kernel, inv_l_occ, window, lstep, angle, astep, cache):
    """Exhaustive search over a box of poses around (x, y, th): translations in whole cells (lstep
    rounded to cells), angles in astep; the field is read at the nearest cell centre. Returns the
    best (x, y, th, score). Field values are computed once per cell, on first use, in a patch
    covering every candidate's end points, so a candidate costs one array read per point; `cache` is
    a field_cache of `kernel` or an empty one."""
    xmin, ymin, inv_delta = geo[0], geo[1], geo[2]
    step = max(1, int(round(lstep * inv_delta)))
    n_lin = int(window * inv_delta + 1e-9) // step
    n_ang = int(angle / astep + 1e-9)
    n = px.shape[0]
    n_angles = 2 * n_ang + 1
    rows, cols = np.empty((n_angles, n), np.int64), np.empty((n_angles, n), np.int64)
    for ia in range(n_angles):
        c, s = math.cos(th + (ia - n_ang) * astep), math.sin(th + (ia - n_ang) * astep)
        for i in range(n):
            rows[ia, i] = int(math.floor((y + s * px[i] + c * py[i] - ymin) * inv_delta))
            cols[ia, i] = int(math.floor((x + c * px[i] - s * py[i] - xmin) * inv_delta))
    reach = n_lin * step
    row_base, col_base = rows.min() - reach, cols.min() - reach
    patch = np.full((rows.max() + reach - row_base + 1, cols.max() + reach - col_base + 1), np.float32(-1.0))
    rows -= row_base
    cols -= col_base
    return _best_candidate(pool, table, kernel, inv_l_occ, cache, rows, cols, patch, row_base, col_base, x, y, th,
                           step, n_lin, n_ang, astep, inv_delta)


@njit(cache=True, _nrt=False)
def _best_candidate(pool, table, kernel, inv_l_occ, cache, rows, cols, patch, row_base, col_base, x, y, th, step,
                    n_lin, n_ang, astep, inv_delta):
    """search()'s scoring of its candidates (rows, cols: each angle's end point cells, relative to the
    patch), apart because it allocates nothing: so no reference counting slows its loops."""
    n = rows.shape[1]
    best_total, best_x, best_y, best_th = -1.0, x, y, th
    for ia in range(2 * n_ang + 1):
        t = th + (ia - n_ang) * astep
        for iy in range(-n_lin, n_lin + 1):
            for ix in range(-n_lin, n_lin + 1):
                dr, dc = iy * step, ix * step
                total = 0.0
                for i in range(n):
                    r, c = rows[ia, i] + dr, cols[ia, i] + dc
                    value = patch[r, c]
                    if value < 0.0:
                        value = _cached_node(pool, table, r + row_base, c + col_base, kernel, inv_l_occ, cache)
                        patch[r, c] = value
                    total += value
                # on a tie (an empty map, a featureless corridor) the guess itself wins
                if total > best_total + 1e-9 or (total > best_total - 1e-9 and ix == 0 and iy == 0
                                                   and ia == n_ang):
                    best_total = total
                    best_x, best_y, best_th = x + dc / inv_delta, y + dr / inv_delta, t
    return best_x, best_y, best_th, best_total / max(n, 1)


SEARCH_POINTS = 60  # end points the coarse search scores (evenly spread over the scan)
# Gauss-Newton steps on the hit point field: they start at the cell field's optimum, a fraction of
# a cell from its own (all `iterations`: 0.0304 m instead of 0.0309 m on MIT CSAIL, at 1.3× the time)
POLISH_ITERATIONS = 3


@njit(cache=True)
def _match_cells(pool, hits, table, geo, px, py, x, y, th, kernel, coarse_kernel, sigma, inv_l_occ, iterations,
                 search_below, window, lstep, angle, astep, prior, prior_weight, cache):
    """The match on the cell field: refinement, and the search when that scores below search_below.
    Returns (x, y, th, score) and the pose the winning refinement was pulled towards: `prior`, or
    the search's best (the odometry was off by more than refinement corrects)."""
    # arguments of one type at every call (np.bool_, not a literal False; contiguous end points, not a
    # strided view): each kernel below compiles once, not once per variant (_linearize about 20 s each
    # on a cold cache, which every fresh checkout starts with)
    rx, ry, rth, score = _refine(pool, hits, table, geo, px, py, x, y, th, kernel, sigma, inv_l_occ, iterations,
                                 np.bool_(False), prior, prior_weight, cache)
    if score >= search_below or (window <= 0.0 and angle <= 0.0):
        return rx, ry, rth, score, prior
    stride = max(1, px.shape[0] // SEARCH_POINTS)
    no_cache = field_cache(geo, px[:0], py[:0], np.empty((0, 3)), np.int64(0))
    cx, cy, cth, _ = search(pool, table, geo, np.ascontiguousarray(px[::stride]), np.ascontiguousarray(py[::stride]),
                            x, y, th, coarse_kernel, inv_l_occ, window, lstep, angle, astep, no_cache)
    cx, cy, cth, _ = search(pool, table, geo, px, py, cx, cy, cth, kernel, inv_l_occ,
                            lstep / 2, lstep / 2, astep / 2, astep / 4, cache)
    found = np.array([cx, cy, cth])
    sx, sy, sth, s_score = _refine(pool, hits, table, geo, px, py, cx, cy, cth, kernel, sigma, inv_l_occ,
                                   iterations, np.bool_(False), found, prior_weight, cache)
    if s_score > score:
        return sx, sy, sth, s_score, found
    return rx, ry, rth, score, prior


@njit(cache=True)
def match_one(pool, hits, table, geo, px, py, x, y, th, kernel, coarse_kernel, sigma, inv_l_occ, iterations,
              search_below, window, lstep, angle, astep, prior, prior_weight):
    """Refine from the guess on the cell field; if that scores below search_below, search coarse to
    fine (steps lstep, astep over ±window, ±angle on a wider field, then half steps around the
    best) and refine from there too; the better result is then refined on the hit point field.
    Every refinement is pulled towards `prior` (the odometry's prediction), or, after a search that
    won, towards the search's best, with prior_weight (x, y, θ; 0: no pull). Returns (x, y, th, the
    cell field's score)."""
    cache = field_cache(geo, px, py, _one_pose(x, y, th), NODE_MARGIN + int(window * geo[2]))
    return _match_one(pool, hits, table, geo, px, py, x, y, th, kernel, coarse_kernel, sigma, inv_l_occ, iterations,
                      search_below, window, lstep, angle, astep, prior, prior_weight, cache)


@njit(cache=True)
def _match_one(pool, hits, table, geo, px, py, x, y, th, kernel, coarse_kernel, sigma, inv_l_occ, iterations,
               search_below, window, lstep, angle, astep, prior, prior_weight, cache):
    """match_one() with `cache` (field_cache) over `table`, of `kernel`."""
    x, y, th, score, prior = _match_cells(pool, hits, table, geo, px, py, x, y, th, kernel, coarse_kernel, sigma,
                                          inv_l_occ, iterations, search_below, window, lstep, angle, astep,
                                          prior, prior_weight, cache)
    if score >= search_below:
        x, y, th, _ = _refine(pool, hits, table, geo, px, py, x, y, th, kernel, sigma, inv_l_occ,
                              min(iterations, POLISH_ITERATIONS), np.bool_(True), prior, prior_weight, cache)
    return x, y, th, score


@njit(cache=True, _nrt=False)
def log_likelihood(pool, table, geo, px, py, x, y, th, radius, lsigma, inv_l_occ):
    """Σ over end points of −d²/(2·lsigma²), d the distance to the nearest obstacle cell centre
    within `radius` cells (capped at radius + ½ cell)."""
    xmin, ymin, inv_delta = geo[0], geo[1], geo[2]
    delta = 1.0 / inv_delta
    cap = ((radius + 0.5) * delta) ** 2
    c, s = math.cos(th), math.sin(th)
    total = 0.0
    for i in range(px.shape[0]):
        u = (x + c * px[i] - s * py[i] - xmin) * inv_delta
        v = (y + s * px[i] + c * py[i] - ymin) * inv_delta
        col, row = int(math.floor(u)), int(math.floor(v))
        best = cap
        for dr in range(-radius, radius + 1):
            for dc in range(-radius, radius + 1):
                if _evidence(pool, table, row + dr, col + dc, inv_l_occ) >= 1.0:
                    du = (col + dc + 0.5 - u) * delta
                    dv = (row + dr + 0.5 - v) * delta
                    best = min(best, du * du + dv * dv)
        total -= best / (2.0 * lsigma * lsigma)
    return total


@njit(cache=True)
def match_all(pool, hits, tables, geo, px, py, poses, kernel, coarse_kernel, sigma, inv_l_occ, iterations,
              minimum_score, search_below, window, lstep, angle, astep, radius, lsigma, priors, prior_weight):
    """match_one for every particle from poses[i], pulled towards priors[i], each against its own map
    (a match scoring below minimum_score keeps the guess), then the scan's log-likelihood at the
    pose kept."""
    n = poses.shape[0]
    out = poses.copy()
    scores = np.empty(n)
    loglik = np.empty(n)
    # one cache area for every particle (their guesses are close), emptied for each particle's map
    cache = field_cache(geo, px, py, poses, NODE_MARGIN + int(window * geo[2]))
    for i in range(n):
        cache[2][2], cache[2][3] = i + 1, 0
        x, y, th, score = _match_one(pool, hits, tables[i], geo, px, py, poses[i, 0], poses[i, 1], poses[i, 2],
                                     kernel, coarse_kernel, sigma, inv_l_occ, iterations, search_below, window,
                                     lstep, angle, astep, priors[i], prior_weight, cache)
        scores[i] = score
        if score >= minimum_score:
            out[i, 0], out[i, 1], out[i, 2] = x, y, th
        loglik[i] = log_likelihood(pool, tables[i], geo, px, py, out[i, 0], out[i, 1], out[i, 2],
                                   radius, lsigma, inv_l_occ)
    return out, scores, loglik


def gaussian_kernel(radius: int, delta: float, sigma: float) -> np.ndarray:
    """exp(−d²/2σ²) over a (2·radius + 1)² block of cells, d between cell centres."""
    offsets = np.arange(-radius, radius + 1) * delta
    d2 = offsets[:, None] ** 2 + offsets[None, :] ** 2
    return np.exp(-d2 / (2.0 * sigma * sigma))
