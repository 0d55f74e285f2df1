"""A layered costmap after ROS costmap_2d's LayeredCostmap: layers combined in order into a master
grid of uint8 costs (255 = NO_INFORMATION), updated incrementally.

Geometry: a global costmap takes the static map's grid (origin yaw included); a rolling window
(`rolling_window: true`, width × height metres) follows the robot in its global frame (odom for a
local costmap), its origin moving in whole cells so the retained cells keep their values.

An update asks every layer which cells it changed (a box), grows that box by the inflation radius,
recombines only that window from the layers and re-inflates it from the lethal cells within one
more inflation radius. Cells outside the window cannot have changed: their costs depend only on
layer cells and lethal cells within the inflation radius, none of which moved. So an incremental
update gives exactly what a full recompute gives (tests/test_costmap.py checks it).
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ...schemas.messages import Header, LaserScan, MapMetaData, OccupancyGrid, Pose2D
from ..map_server.mapio import load_map
from ...geometry.grid import cell_to_world, in_grid, world_to_cell
from ...geometry.footprint import Footprint, make_footprint
from .layers import (FREE_SPACE, NO_INFORMATION, Box, InflationLayer, KeepoutLayer, ObstacleLayer, StaticLayer,
                     View, grow, same_geometry, shift_grid, union, whole)
from .mover_layer import MoverLayer
from .params import (CostmapParams, InflationLayerParams, KeepoutLayerParams, MoverLayerParams, ObstacleLayerParams,
                     StaticLayerParams)

_CELLS_EPSILON = 1e-9   # width / resolution = 119.99999999 still means 120 cells


def occupancy_values() -> np.ndarray:
    """ROS Costmap2DPublisher's table from costs to OccupancyGrid values (for viewers)."""
    table = np.zeros(256, np.int8)
    table[1:253] = 1 + (97 * (np.arange(1, 253) - 1)) // 251
    table[253], table[254], table[255] = 99, 100, -1
    return table


def _load_mask(path: str) -> OccupancyGrid | None:
    """A mask image's map YAML (map_server format), read relative to the working directory."""
    return load_map(Path(path)) if path else None


def _exposed(shift: int, size: int) -> tuple[int, int]:
    """The cells [first, last) of an axis that a shift of the window by `shift` cells uncovers."""
    return (max(size - shift, 0), size) if shift > 0 else (0, min(-shift, size))


class Costmap:
    """One costmap (global or local) with its layers, in the order of params.layers."""

    def __init__(self, params: CostmapParams, static_map: OccupancyGrid | None = None):
        self.params = params
        self.footprint: Footprint = make_footprint(params.footprint, params.robot_radius, params.footprint_padding)
        self.default = NO_INFORMATION if params.track_unknown_space else FREE_SPACE
        self.layers = [self._make_layer(p) for p in params.layers if p.enabled]
        self.inflation = next((l for l in self.layers if isinstance(l, InflationLayer)), None)
        self.layer_times_s: dict[str, float] = {}   # wall time of each layer in the last update
        self._resize(self._initial_geometry())
        if static_map is not None:
            self.set_static_map(static_map)

    # ------------------------------------------------------------ construction

    def _make_layer(self, p):
        if isinstance(p, StaticLayerParams):
            return StaticLayer(p)
        if isinstance(p, ObstacleLayerParams):
            return ObstacleLayer(p, self.params.track_unknown_space, self.footprint.body)
        if isinstance(p, InflationLayerParams):
            return InflationLayer(p, self.footprint.inscribed_radius, self.params.resolution)
        if isinstance(p, KeepoutLayerParams):
            return KeepoutLayer(p, _load_mask(p.mask), _load_mask(p.speed_limit_mask))
        if isinstance(p, MoverLayerParams):
            return MoverLayer(p, self.footprint.inscribed_radius)
        raise TypeError(f"no layer for {type(p).__name__}")

    def _initial_geometry(self) -> MapMetaData:
        p = self.params
        return MapMetaData(resolution=p.resolution, width=int(p.width / p.resolution + _CELLS_EPSILON),
                           height=int(p.height / p.resolution + _CELLS_EPSILON),
                           origin=Pose2D(p.origin_x, p.origin_y, 0.0))

    def _resize(self, info: MapMetaData) -> None:
        if info.width < 1 or info.height < 1:
            raise ValueError(f"costmap of {info.width} x {info.height} cells is empty")
        if self.inflation is not None and not math.isclose(info.resolution, self.params.resolution):
            # the inflation kernel is in cells; a map at another resolution needs it rebuilt
            index = self.layers.index(self.inflation)
            self.inflation = InflationLayer(self.inflation.params, self.footprint.inscribed_radius, info.resolution)
            self.layers[index] = self.inflation
        self.info = MapMetaData(resolution=info.resolution, width=info.width, height=info.height,
                                origin=Pose2D(info.origin.x, info.origin.y, info.origin.theta))
        self.costs = np.full((info.height, info.width), self.default, np.uint8)
        self._composed = self.costs.copy()   # the master before the inflation layer
        for layer in self.layers:
            if not isinstance(layer, InflationLayer):
                layer.resize(self.info)
        self._pending: Box | None = whole(self.info)

    # ------------------------------------------------------------ inputs

    def set_static_map(self, grid: OccupancyGrid) -> None:
        """A new map for the static layer(s); a non-rolling costmap takes its geometry."""
        static = [l for l in self.layers if isinstance(l, StaticLayer)]
        if not static:
            return
        for layer in static:
            layer.set_map(grid)
        if not self.params.rolling_window and not same_geometry(grid.info, self.info):
            self._resize(grid.info)   # as ROS: a map of another size or origin resets every layer

    def set_masks(self, keepout: OccupancyGrid | None, speed: OccupancyGrid | None = None) -> None:
        """Replace the keepout and speed masks (map frame) of the keepout layer(s)."""
        for layer in self.layers:
            if isinstance(layer, KeepoutLayer):
                layer.set_masks(keepout, speed)

    @property
    def needs_tracks(self) -> bool:
        """Whether a layer reads the tracks: a mover layer, or an obstacle layer that skips them."""
        return any(isinstance(layer, MoverLayer) or (isinstance(layer, ObstacleLayer) and layer.params.skip_tracked)
                   for layer in self.layers)

    def set_movers(self, movers, stamp_ns: int = 0) -> None:
        """The tracks (geometry/movers.py Movers, None: none) at the coming update's time stamp_ns
        in the global frame, for the mover layer(s) and the obstacle layers that skip them."""
        for layer in self.layers:
            if isinstance(layer, MoverLayer):
                layer.set_movers(movers)
            elif isinstance(layer, ObstacleLayer):
                layer.set_movers(movers, stamp_ns)

    def add_scan(self, scan: LaserScan, sensor_pose, topic: str = "scan") -> int:
        """Feed a scan (sensor pose x, y, yaw in this costmap's global frame) to every observation
        source subscribed to `topic`; returns how many took it."""
        taken = 0
        for layer in self.layers:
            if isinstance(layer, ObstacleLayer):
                for source in layer.sources.values():
                    if source.topic.lstrip("/") == topic.lstrip("/"):
                        layer.add_scan(source.name, scan, sensor_pose)
                        taken += 1
        return taken

    def clear(self) -> None:
        """Forget every obstacle seen (the 'clear costmaps' recovery)."""
        for layer in self.layers:
            if isinstance(layer, ObstacleLayer):
                layer.reset()
        self._pending = whole(self.info)

    def clear_outside(self, x: float, y: float, side: float) -> None:
        """Forget the obstacles seen in cells whose centres lie outside the axis-aligned square of
        `side` metres centred on (x, y) in the global frame (ROS clear_costmap_recovery resetting
        its obstacle layers around the robot). Buffered scans stay, as in ROS."""
        rows, cols = np.indices(self.costs.shape)
        cx, cy = cell_to_world(self.info, rows, cols)
        outside = (np.abs(cx - x) > side / 2) | (np.abs(cy - y) > side / 2)
        for layer in self.layers:
            if isinstance(layer, ObstacleLayer):
                layer.costs[outside] = layer.default
        self._pending = whole(self.info)

    # ------------------------------------------------------------ updating

    def _follow(self, robot_pose) -> Box | None:
        """Move a rolling window so the robot is at its centre; returns the cells it exposed."""
        info = self.info
        new_x = robot_pose[0] - info.width * info.resolution / 2
        new_y = robot_pose[1] - info.height * info.resolution / 2
        dc = int((new_x - info.origin.x) / info.resolution)   # truncation, as Costmap2D::updateOrigin
        dr = int((new_y - info.origin.y) / info.resolution)
        if dr == 0 and dc == 0:
            return None
        info.origin = Pose2D(info.origin.x + dc * info.resolution, info.origin.y + dr * info.resolution, 0.0)
        for grid in (self.costs, self._composed):
            shift_grid(grid, dr, dc, self.default)
        for layer in self.layers:
            if not isinstance(layer, InflationLayer):
                layer.shift(dr, dc)
        height, width = self.costs.shape
        strips = None
        if dr:
            first, last = _exposed(dr, height)
            strips = union(strips, (first, 0, last, width))
        if dc:
            first, last = _exposed(dc, width)
            strips = union(strips, (0, first, height, last))
        return strips

    def update(self, robot_pose=None, frame_in_map: Pose2D | None = None) -> Box | None:
        """One update cycle. robot_pose (x, y, yaw) in the global frame moves a rolling window and
        clears the footprint; frame_in_map is the global frame's pose in the map frame, for a
        costmap that is not in the map frame but has map-frame layers (static, keepout).
        Returns the window of cells that was recomputed, or None."""
        box, self._pending = self._pending, None
        if self.params.rolling_window and robot_pose is not None:
            box = union(box, self._follow(robot_pose))
        view = View(self.info, None if robot_pose is None else tuple(float(v) for v in robot_pose), frame_in_map)
        times = {}
        for layer in self.layers:
            if not isinstance(layer, InflationLayer):
                start = time.perf_counter()
                box = union(box, layer.update_bounds(view))
                times[layer.name] = time.perf_counter() - start
        if box is None:
            self.layer_times_s = times
            return None
        window = grow(box, self.inflation.cell_radius, self.costs.shape) if self.inflation else box
        r0, c0, r1, c1 = window
        self.costs[r0:r1, c0:c1] = self.default
        for layer in self.layers:
            start = time.perf_counter()
            if isinstance(layer, InflationLayer):
                self._composed[r0:r1, c0:c1] = self.costs[r0:r1, c0:c1]
                layer.inflate(self._composed, self.costs, window)
            else:
                layer.update_costs(self.costs, window)
            times[layer.name] = times.get(layer.name, 0.0) + time.perf_counter() - start
        self.layer_times_s = times
        return window

    def recompute(self, robot_pose=None, frame_in_map: Pose2D | None = None) -> Box:
        """A full update: every cell recombined and re-inflated."""
        self._pending = whole(self.info)
        return self.update(robot_pose, frame_in_map)

    # ------------------------------------------------------------ reading

    def cost_at(self, x, y) -> np.ndarray:
        """Costs at world points of the global frame (NO_INFORMATION off the grid)."""
        rows, cols = world_to_cell(self.info, x, y)
        inside = in_grid(self.info, rows, cols)
        out = np.full(np.shape(rows), NO_INFORMATION, np.uint8)
        out[inside] = self.costs[rows[inside], cols[inside]]
        return out

    def speed_limit_at(self, x, y) -> np.ndarray:
        """Speed limits at world points (inf: none); percent of the maximum speed or m/s, as the
        keepout layer's speed_limit_percentage says."""
        rows, cols = world_to_cell(self.info, x, y)
        inside = in_grid(self.info, rows, cols)
        out = np.full(np.shape(rows), np.inf, np.float32)
        for layer in self.layers:
            if isinstance(layer, KeepoutLayer) and layer.speed_limits is not None:
                out[inside] = np.minimum(out[inside], layer.speed_limits[rows[inside], cols[inside]])
        return out

    def to_occupancy_grid(self, stamp_ns: int = 0) -> OccupancyGrid:
        """The costs as ROS publishes a costmap for viewers (0..100, −1 unknown; lossy)."""
        return OccupancyGrid(header=Header(stamp_ns=stamp_ns, frame_id=self.params.global_frame),
                             info=MapMetaData(resolution=self.info.resolution, width=self.info.width,
                                              height=self.info.height, origin=Pose2D(self.info.origin.x,
                                              self.info.origin.y, self.info.origin.theta)),
                             data=occupancy_values()[self.costs])
