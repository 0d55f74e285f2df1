"""Log-odds occupancy grids for many particles, sharing unchanged tiles copy-on-write.

Each map is a table of tile ids over a bounded extent (gmapping's xmin..xmax, ymin..ymax); a tile
is TILE × TILE cells of float32 log-odds in one pool shared by all maps, with a reference count.
A tile never seen has no id (id −1, every cell unknown, log-odds 0), so memory grows with the
area seen, not the extent. Resampling copies tables, not cells: a particle's child shares every
tile with it until one of them writes to a tile, which then gets its own copy. Memory is
therefore bounded by (particles × tiles one scan can touch) + the tiles all particles still share.

Cells follow the map_server convention (mapio): cell (row, col) covers
x in [xmin + col·delta, xmin + (col+1)·delta), y likewise from ymin, so the map's origin is
(xmin, ymin, 0). Grid coordinates (u, v) = ((x − xmin)/delta, (y − ymin)/delta) are in cells.

A beam updates the cells it crosses (Amanatides & Woo traversal) with l_free and the cell holding
its end with l_occ; a beam longer than maxUrange is cut there and only clears.

Each cell also keeps the mean of the end points that hit it (gmapping's PointAccumulator), so the
scan matcher sees where in the cell the surface lies, not only which cell it is in: a wall whose
surface runs along a cell border is hit in two cells, and their cell centres alone would leave
its position undetermined by half a cell. Stored beside the log-odds in `hits`, tile for tile:
the mean's offset in the cell along u and v in 1/HIT_SCALE of a cell, and the number of hits
(saturating), three uint16 per cell.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...schemas.messages import Header, MapMetaData, OccupancyGrid, Pose2D

TILE_BITS = 5
TILE = 1 << TILE_BITS
TILE_MASK = TILE - 1
HIT_SCALE = 65535           # a mean hit point's offset in its cell, in 1/HIT_SCALE of a cell
HIT_CENTRE = 32768          # the offset of a cell never hit: its centre
MAX_HITS = 65535
TILE_BYTES = TILE * TILE * (4 + 3 * 2)   # log-odds float32 + the mean hit point, 3 × uint16


@dataclass(frozen=True)
class GridGeometry:
    xmin: float
    ymin: float
    delta: float
    width: int       # cells along x
    height: int      # cells along y

    @classmethod
    def from_extent(cls, xmin: float, ymin: float, xmax: float, ymax: float, delta: float) -> GridGeometry:
        return cls(xmin, ymin, delta, int(math.ceil((xmax - xmin) / delta)), int(math.ceil((ymax - ymin) / delta)))

    @property
    def tiles_shape(self) -> tuple[int, int]:
        return (self.height + TILE - 1) // TILE, (self.width + TILE - 1) // TILE


def occupancy_data(log_odds: np.ndarray, occ_thresh: float) -> np.ndarray:
    """OccupancyGrid cells of log-odds: 100 where the occupancy probability is above occ_thresh,
    0 where it is below one half, −1 otherwise (never seen, or undecided)."""
    occupied = log_odds > math.log(occ_thresh / (1.0 - occ_thresh))
    return np.where(occupied, 100, np.where(log_odds < 0.0, 0, -1)).astype(np.int8)


# ---------------------------------------------------------------- kernels

@njit(cache=True, inline="always")
def cell_value(pool, table, row, col):
    """Log-odds of a cell; 0 (unknown) outside the grid or in a tile never written."""
    if row < 0 or col < 0:
        return np.float32(0.0)
    tr, tc = row >> TILE_BITS, col >> TILE_BITS
    if tr >= table.shape[0] or tc >= table.shape[1]:
        return np.float32(0.0)
    tile = table[tr, tc]
    if tile < 0:
        return np.float32(0.0)
    return pool[tile, row & TILE_MASK, col & TILE_MASK]


@njit(cache=True, _nrt=False)
def segment_cells(u0, v0, u1, v1, rows, cols):
    """The cells a segment from (u0, v0) to (u1, v1) crosses (4-connected, both ends included),
    into rows/cols (at least |Δcol| + |Δrow| + 1 long); returns how many."""
    col, row = int(math.floor(u0)), int(math.floor(v0))
    end_col, end_row = int(math.floor(u1)), int(math.floor(v1))
    du, dv = u1 - u0, v1 - v0
    step_c = 1 if du > 0 else -1
    step_r = 1 if dv > 0 else -1
    # t (0..1 along the segment) where the next column / row boundary is crossed
    next_u = ((col + 1 - u0) / du if du > 0 else (u0 - col) / -du) if du != 0.0 else np.inf
    next_v = ((row + 1 - v0) / dv if dv > 0 else (v0 - row) / -dv) if dv != 0.0 else np.inf
    delta_u = abs(1.0 / du) if du != 0.0 else np.inf
    delta_v = abs(1.0 / dv) if dv != 0.0 else np.inf
    n = 0
    rows[n], cols[n] = row, col
    n += 1
    # once a coordinate has reached its end it stops, so the loop ends after exactly
    # |Δcol| + |Δrow| steps whatever rounding does to next_u / next_v
    while row != end_row or col != end_col:
        if row == end_row or (col != end_col and next_u < next_v):
            col += step_c
            next_u += delta_u
        else:
            row += step_r
            next_v += delta_v
        rows[n], cols[n] = row, col
        n += 1
    return n


@njit(cache=True, _nrt=False)
def _mark_tiles(table, u0, v0, u_end, v_end, marked, tiles, rows, cols):
    """Every tile the beams cross, once each, into `tiles` (k, 2); returns k."""
    th, tw = table.shape
    k = 0
    scale = 1.0 / TILE
    for b in range(u_end.shape[0]):
        n = segment_cells(u0 * scale, v0 * scale, u_end[b] * scale, v_end[b] * scale, rows, cols)
        for i in range(n):
            r, c = rows[i], cols[i]
            if 0 <= r < th and 0 <= c < tw and not marked[r, c]:
                marked[r, c] = True
                tiles[k, 0], tiles[k, 1] = r, c
                k += 1
    return k


@njit(cache=True)
def _take_tile(refs, free, free_top):
    free_top[0] -= 1
    tile = free[free_top[0]]
    refs[tile] = 1
    return tile


@njit(cache=True, _nrt=False)
def _add_hit(cell, u_offset, v_offset):
    """Fold a hit at (u_offset, v_offset) (cells, in [0, 1)) into a cell's mean hit point."""
    n = min(int(cell[2]) + 1, MAX_HITS)
    for axis, offset in ((0, u_offset), (1, v_offset)):
        mean = int(cell[axis])
        target = min(max(offset, 0.0), 1.0) * HIT_SCALE
        cell[axis] = min(max(mean + int(math.floor((target - mean) / n + 0.5)), 0), HIT_SCALE)
    cell[2] = n


@njit(cache=True)
def _update(pool, hits, refs, free, free_top, table, u0, v0, u_end, v_end, hit, l_occ, l_free, l_max):
    """Integrate one scan into one map. Returns 0, or the number of free tiles it needs when the
    pool has fewer (then nothing was changed: grow the pool and call again)."""
    marked = np.zeros(table.shape, np.bool_)
    longest = 0.0
    for b in range(u_end.shape[0]):
        longest = max(longest, abs(u_end[b] - u0) + abs(v_end[b] - v0))
    buf = int(longest) + 4
    rows, cols = np.empty(buf, np.int64), np.empty(buf, np.int64)
    tiles = np.empty((table.shape[0] * table.shape[1], 2), np.int64)
    k = _mark_tiles(table, u0, v0, u_end, v_end, marked, tiles, rows, cols)
    need = 0
    for i in range(k):
        tile = table[tiles[i, 0], tiles[i, 1]]
        if tile < 0 or refs[tile] > 1:
            need += 1
    if need > free_top[0]:
        return need
    for i in range(k):  # make every tile the scan touches this map's own
        tr, tc = tiles[i, 0], tiles[i, 1]
        tile = table[tr, tc]
        if tile < 0:
            fresh = _take_tile(refs, free, free_top)
            pool[fresh] = 0.0
            hits[fresh, :, :, :2] = HIT_CENTRE
            hits[fresh, :, :, 2] = 0
            table[tr, tc] = fresh
        elif refs[tile] > 1:
            fresh = _take_tile(refs, free, free_top)
            pool[fresh] = pool[tile]
            hits[fresh] = hits[tile]
            refs[tile] -= 1
            table[tr, tc] = fresh
    _trace(pool, hits, table, u0, v0, u_end, v_end, hit, l_occ, l_free, l_max, rows, cols)
    return 0


@njit(cache=True, _nrt=False)
def _trace(pool, hits, table, u0, v0, u_end, v_end, hit, l_occ, l_free, l_max, rows, cols):
    """_update's beams into the map's own tiles, apart because it allocates nothing: so no reference
    counting slows its loops."""
    th, tw = table.shape
    for b in range(u_end.shape[0]):
        n = segment_cells(u0, v0, u_end[b], v_end[b], rows, cols)
        for i in range(n):
            r, c = rows[i], cols[i]
            if r < 0 or c < 0 or (r >> TILE_BITS) >= th or (c >> TILE_BITS) >= tw:
                continue
            end = hit[b] and i == n - 1
            tile = table[r >> TILE_BITS, c >> TILE_BITS]
            value = pool[tile, r & TILE_MASK, c & TILE_MASK] + (l_occ if end else l_free)
            pool[tile, r & TILE_MASK, c & TILE_MASK] = min(max(value, -l_max), l_max)
            if end:
                _add_hit(hits[tile, r & TILE_MASK, c & TILE_MASK], u_end[b] - c, v_end[b] - r)


@njit(cache=True)
def _update_maps(pool, hits, refs, free, free_top, tables, first, u0, v0, u_end, v_end, hit, l_occ, l_free, l_max):
    """Integrate scan k into map k for k = first, first + 1, ...; returns (k, tiles needed) at the
    first map the pool has too few free tiles for, or (number of maps, 0) when all are done."""
    for k in range(first, tables.shape[0]):
        need = _update(pool, hits, refs, free, free_top, tables[k], u0[k], v0[k], u_end[k], v_end[k], hit,
                       l_occ, l_free, l_max)
        if need:
            return k, need
    return tables.shape[0], 0


@njit(cache=True)
def _retable(tables, parents, refs, free, free_top):
    """Maps become copies of maps `parents` (resampling): only tile references move."""
    new = np.empty_like(tables)
    for i in range(parents.shape[0]):
        new[i] = tables[parents[i]]
    for tile in new.ravel():
        if tile >= 0:
            refs[tile] += 1
    for tile in tables.ravel():
        if tile >= 0:
            refs[tile] -= 1
            if refs[tile] == 0:
                free[free_top[0]] = tile
                free_top[0] += 1
    return new


def cut_beams(ranges, angles, range_min: float, max_range: float, max_urange: float):
    """The beams a scan contributes to a map, in the laser frame: (x, y, hit). Beams that are not
    finite, at or below range_min or at or beyond max_range (no return) are dropped; longer than
    max_urange they are cut there and only clear (hit False)."""
    r = np.asarray(ranges, np.float64)
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(r) & (r > range_min) & (r < max_range)
    r, a = r[usable], np.asarray(angles, np.float64)[usable]
    hit = r < max_urange
    r = np.minimum(r, max_urange)
    return r * np.cos(a), r * np.sin(a), hit


# ---------------------------------------------------------------- the maps

class TiledGrids:
    """`n_maps` log-odds grids over one geometry, sharing tiles copy-on-write."""

    def __init__(self, geometry: GridGeometry, n_maps: int = 1, capacity: int = 256):
        self.geometry = geometry
        self.tables = np.full((n_maps, *geometry.tiles_shape), -1, np.int32)
        self.pool = np.zeros((capacity, TILE, TILE), np.float32)
        self.hits = np.zeros((capacity, TILE, TILE, 3), np.uint16)
        self.refs = np.zeros(capacity, np.int32)
        self.free = np.arange(capacity - 1, -1, -1, dtype=np.int32)  # a stack; pops low ids first
        self.free_top = np.array([capacity], np.int64)

    @property
    def n_maps(self) -> int:
        return self.tables.shape[0]

    def _grow(self, need: int) -> None:
        old = self.pool.shape[0]
        new = max(2 * old, old + need)
        pool = np.zeros((new, TILE, TILE), np.float32)
        pool[:old] = self.pool
        hits = np.zeros((new, TILE, TILE, 3), np.uint16)
        hits[:old] = self.hits
        refs = np.zeros(new, np.int32)
        refs[:old] = self.refs
        free = np.empty(new, np.int32)
        top = int(self.free_top[0])
        free[:top] = self.free[:top]
        added = np.arange(new - 1, old - 1, -1, dtype=np.int32)
        free[top:top + len(added)] = added
        self.pool, self.hits, self.refs, self.free = pool, hits, refs, free
        self.free_top[0] = top + len(added)

    def grid_coords(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        g = self.geometry
        return (np.asarray(x, np.float64) - g.xmin) / g.delta, (np.asarray(y, np.float64) - g.ymin) / g.delta

    def integrate(self, index: int, origin_xy, end_x, end_y, hit, l_occ: float, l_free: float, l_max: float) -> None:
        """Integrate beams from the laser at origin_xy (world) to (end_x, end_y) (world, already cut
        to maxUrange) into map `index`; hit[b] says whether beam b's end cell is an obstacle."""
        origin = np.asarray(origin_xy, np.float64).reshape(1, 2)
        self.integrate_all(origin, np.reshape(end_x, (1, -1)), np.reshape(end_y, (1, -1)), hit,
                           l_occ, l_free, l_max, maps=[index])

    def integrate_all(self, origins, end_x, end_y, hit, l_occ: float, l_free: float, l_max: float,
                      maps=None) -> None:
        """One scan into several maps at once: row k of origins (k, 2) and end_x, end_y (k, beams),
        world coordinates, into map maps[k] (default: map k)."""
        maps = np.arange(self.n_maps) if maps is None else np.asarray(maps, np.int64)
        tables = np.ascontiguousarray(self.tables[maps])
        u0, v0 = self.grid_coords(origins[:, 0], origins[:, 1])
        u_end, v_end = self.grid_coords(end_x, end_y)
        args = (np.ascontiguousarray(u0), np.ascontiguousarray(v0), np.ascontiguousarray(u_end),
                np.ascontiguousarray(v_end), np.ascontiguousarray(hit, np.bool_),
                np.float32(l_occ), np.float32(l_free), np.float32(l_max))
        done = 0
        while done < len(maps):
            done, need = _update_maps(self.pool, self.hits, self.refs, self.free, self.free_top, tables, done, *args)
            if need:
                self._grow(need)
        self.tables[maps] = tables

    def resample(self, parents) -> None:
        """Map i becomes a copy of map parents[i]."""
        self.tables = _retable(self.tables, np.asarray(parents, np.int64), self.refs, self.free, self.free_top)

    def logodds(self, index: int) -> np.ndarray:
        """The whole map as a dense (height, width) float32 array (0: unknown)."""
        g = self.geometry
        table = self.tables[index]
        padded = np.zeros((table.shape[0] * TILE, table.shape[1] * TILE), np.float32)
        tr, tc = np.nonzero(table >= 0)
        view = padded.reshape(table.shape[0], TILE, table.shape[1], TILE)
        view[tr, :, tc, :] = self.pool[table[tr, tc]]
        return padded[:g.height, :g.width]

    def mean_hit(self, index: int, row: int, col: int) -> tuple[float, float, int]:
        """The mean of the end points that hit cell (row, col) of map `index` (world coordinates; the
        cell's centre if none did) and how many did."""
        g = self.geometry
        tile = self.tables[index, row >> TILE_BITS, col >> TILE_BITS]
        if tile < 0:
            u_off, v_off, n = HIT_CENTRE, HIT_CENTRE, 0
        else:
            u_off, v_off, n = self.hits[tile, row & TILE_MASK, col & TILE_MASK]
        return (g.xmin + (col + u_off / HIT_SCALE) * g.delta, g.ymin + (row + v_off / HIT_SCALE) * g.delta, int(n))

    def known_box(self, index: int) -> tuple[int, int, int, int] | None:
        """(row0, row1, col0, col1) cell bounds of the tiles written in map `index` (None: none)."""
        tr, tc = np.nonzero(self.tables[index] >= 0)
        if len(tr) == 0:
            return None
        g = self.geometry
        return (tr.min() * TILE, min((tr.max() + 1) * TILE, g.height),
                tc.min() * TILE, min((tc.max() + 1) * TILE, g.width))

    def occupancy_grid(self, index: int, occ_thresh: float, stamp_ns: int = 0) -> OccupancyGrid:
        """The map cropped to what was seen: 100 where the occupancy probability is above
        occ_thresh, 0 where it is below one half, −1 otherwise (never seen, or undecided)."""
        g = self.geometry
        box = self.known_box(index) or (0, 1, 0, 1)
        r0, r1, c0, c1 = box
        data = occupancy_data(self.logodds(index)[r0:r1, c0:c1], occ_thresh)
        info = MapMetaData(resolution=g.delta, width=data.shape[1], height=data.shape[0],
                           origin=Pose2D(g.xmin + c0 * g.delta, g.ymin + r0 * g.delta, 0.0))
        return OccupancyGrid(header=Header(stamp_ns=stamp_ns, frame_id="map"), info=info, data=data)

    def tiles_in_use(self) -> int:
        return int(np.count_nonzero(self.refs > 0))

    def bytes_in_use(self) -> int:
        """Memory the maps hold: tiles referenced by any map (log-odds and mean hit points), plus the
        tile tables."""
        return self.tiles_in_use() * TILE_BYTES + self.tables.nbytes
