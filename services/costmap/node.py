"""The costmap service: ROS costmap_2d's global and local costmaps around the layered core.

Each costmap is configured by ROS costmap parameter files, loaded as move_base loads them (common
file first, then the costmap's own; see docs/costmap_and_planner.md): by default the samples in
compose/params, which make the global costmap static + obstacle + inflation in the map frame and
the local one a 6 m rolling window of obstacle + inflation in the odom frame.

Inputs, in merge order: odom, then the scan topic of every observation source (synced); map,
tf/map_odom and costmap/clear (sporadic). A scan is placed with the latest odometry at or before its stamp (the sim
stamps both alike): laser → base_link by the laser_* mount, → odom by the odometry, → map by
map→odom, which is the initial_pose_* until a localizer publishes tf/map_odom (frames.py).

Each costmap updates every 1/update_frequency and publishes (costmap/global, costmap/local: raw
costs, the whole grid) every 1/publish_frequency of sim time, as ROS (publish_frequency 0: never
published, only answered); `get` on either key answers its costs after the last update. Both are
stamped with the sim time they are sent at, which runs up to a scan period behind the clock: the
node waits for the scans (consumers defer them, see global_planner/node.py).

A costmap with a mover layer (mover_layer.py), or an obstacle layer with skip_tracked, also takes
the tracker's tracks (sporadic, held tracks_delay_s as the local planner holds them): at each of
its update cycles the tracks in effect are predicted to the cycle's time and carried into its
frame; tracks older than tracks_timeout_s (a tracker that stopped) are dropped rather than walked
on for ever.

costmap/clear (ClearCostmaps, the navigator's clear_costmaps recovery) forgets the obstacle layers'
cells outside the square of side reset_distance around the robot, in both costmaps, as move_base's
clear_costmap_recovery. A clear stamped t takes effect at each costmap's first update cycle stamped
after t + request_delay_s (the navigator's commands follow the odometry, which the cycles may have
passed): whenever it arrives within that delay, the costmaps come out the same, and replay is
exact. A costmap that never cycles (update_frequency 0) never clears.

A map is applied at the costmap's next update; before its first update cycle (no sim clock yet, or
update_frequency 0) a new map updates the costmap at once and publishes it, so map_server +
costmap + global_planner serve plans without a sim. A map equal to the current one changes
nothing (map_server may republish). A costmap with a static layer waits for its map, a rolling
window for odometry.

The Diagnostic carries, per costmap and layer, the median wall time of its last updates
(`update_ms/global/static_layer`, ...): instrumentation, which replay does not compare.
"""
from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from ...schemas import MessageError
from ...schemas.keys import type_for_key
from ...schemas.messages import Costmap as CostmapMsg
from ...schemas.messages import ClearCostmaps, Diagnostic, Header, LaserScan, OccupancyGrid, Tracks, Transform
from ...geometry.movers import movers_at, tracks_problem
from ..map_server.mapio import MapError, load_map
from ..runtime.deferred import Deferred
from ..runtime.node import NS_PER_S, Node, QueryError
from ...geometry.se2 import compose
from .costmap import Costmap
from ...geometry.frames import FrameParams, LASER_MOUNT
from .layers import same_geometry, warm_up
from .params import CostmapParams, ObstacleLayerParams, StaticLayerParams, load_costmap_params
from ...parameters.declare import param

SAMPLES = "compose/params/"
TIMES_KEPT = 10_000     # update times per layer kept for the diagnostic's medians


@dataclass(frozen=True)
class CostmapNodeParams(FrameParams):
    # ROS costmap parameter files, later ones overriding earlier ones (relative: to the working
    # directory, else to the checkout, where the samples are)
    global_costmap_files: tuple[str, ...] = (SAMPLES + "costmap_common_params.yaml",
                                             SAMPLES + "costmap_global_params.yaml")
    local_costmap_files: tuple[str, ...] = (SAMPLES + "costmap_common_params.yaml",
                                            SAMPLES + "costmap_local_params.yaml")
    map_file: str = ""          # a map_server YAML read at start, instead of the map key ("": the map key)
    laser_x: float = LASER_MOUNT[0]     # m: the laser in base_link (the simulated lidar's mount)
    laser_y: float = LASER_MOUNT[1]
    laser_yaw: float = LASER_MOUNT[2]
    request_delay_s: float = param(0.3, ge=0)  # sim s from a costmap/clear stamp to its effect
    tracks_delay_s: float = param(0.3, ge=0)   # sim s from a tracks stamp to its effect (mover layers only)
    tracks_timeout_s: float = param(1.0, gt=0)  # sim s after which tracks in effect are forgotten


class ServedCostmap:
    """One costmap as the node runs it: the core, its publisher, when it last updated, how long its
    layers took."""

    def __init__(self, name: str, params: CostmapParams, static_map: OccupancyGrid | None, publisher,
                 clear_delay_s: float):
        self.name = name
        self.core = Costmap(params, static_map)
        self.frame = params.global_frame
        self.publisher = publisher
        self.needs_map = any(isinstance(l, StaticLayerParams) and l.enabled for l in params.layers)
        self.needs_tracks = self.core.needs_tracks
        self.has_map = static_map is not None
        self.cycles = 0                         # update cycles run (by the timer)
        self.updated_ns: int | None = None      # sim time of the last update
        self.times: dict[str, deque[float]] = {}
        self.clears = Deferred(clear_delay_s)   # ClearCostmaps requests not yet in effect

    def waiting_for(self, robot) -> str:
        """What keeps this costmap from updating, or ''."""
        if self.needs_map and not self.has_map:
            return "the map (map key, or the map_file parameter)"
        if self.core.params.rolling_window and robot is None:
            return "odometry (a rolling window follows the robot)"
        return ""

    def update(self, robot, frame_in_map, now_ns: int) -> None:
        self.core.update(robot, frame_in_map)
        self.updated_ns = now_ns
        layers = self.core.layer_times_s
        for name, seconds in (*layers.items(), ("total", sum(layers.values()))):
            self.times.setdefault(name, deque(maxlen=TIMES_KEPT)).append(seconds * 1e3)

    def message(self, stamp_ns: int) -> CostmapMsg:
        info = self.core.info
        return CostmapMsg(header=Header(stamp_ns=stamp_ns, frame_id=self.frame),
                          info=replace(info, origin=replace(info.origin)), data=self.core.costs.copy())


class CostmapNode(Node):
    service = "costmap"
    Params = CostmapNodeParams

    def setup(self) -> None:
        p = self.params
        warm_up()   # compile (or load) the raytracing and inflation kernels now, never inside a cycle
        self.frames = p.robot_frames()
        self.laser = np.array([p.laser_x, p.laser_y, p.laser_yaw])
        static_map = self._read_map_file()
        self.map: OccupancyGrid | None = static_map
        self.costmaps: dict[str, ServedCostmap] = {}
        for name, files in (("global", p.global_costmap_files), ("local", p.local_costmap_files)):
            params = load_costmap_params(files, f"{name}_costmap")      # ParamError names the file and key
            self.frames.check_frame(params.global_frame, f"{name}_costmap: global_frame")
            try:
                served = ServedCostmap(name, params, static_map, self.publisher(f"costmap/{name}"), p.request_delay_s)
            except ValueError as exc:     # a keepout mask that cannot be read, a map it cannot take
                raise ValueError(f"{name}_costmap: {exc}") from None
            self.costmaps[name] = served
            self.queryable(f"costmap/{name}", lambda _params, s=served: self._current(s))
        self.map_key = self.keys.resolve("map")
        self.tf_key = self.keys.resolve("tf/map_odom")
        self.subscribe("odom", self.frames.set_odom)
        for topic in self._scan_topics():
            self.subscribe(topic, lambda msg, t=topic: self.on_scan(t, msg))
        if not p.map_file:
            self.subscribe("map", self.on_map, synced=False)
        self.subscribe("tf/map_odom", self.on_map_odom, synced=False)
        self.clear_key = self.keys.resolve("costmap/clear")
        self.subscribe("costmap/clear", self.on_clear, synced=False, max_delay_s=p.request_delay_s)
        self.pending_tracks = Deferred(p.tracks_delay_s)
        self.tracks: Tracks | None = None       # in effect
        if any(served.needs_tracks for served in self.costmaps.values()):
            self.subscribe_deferred("tracks", self.pending_tracks, check=self._tracks_problem)
        # updates before publishes: a publish due at the same instant sends that update
        for served in self.costmaps.values():
            if served.core.params.update_frequency > 0:
                self.every(1.0 / served.core.params.update_frequency, lambda s=served: self.on_cycle(s))
        for served in self.costmaps.values():
            if served.core.params.publish_frequency > 0:
                self.every(1.0 / served.core.params.publish_frequency, lambda s=served: self.publish(s))

    def _read_map_file(self) -> OccupancyGrid | None:
        if not self.params.map_file:
            return None
        try:
            return load_map(self.params.map_file)
        except MapError as exc:
            raise ValueError(f"parameter 'map_file': {exc}") from None

    def _scan_topics(self) -> list[str]:
        """The topics the observation sources read, each checked to be a LaserScan key."""
        topics = sorted({source.topic.lstrip("/") for served in self.costmaps.values()
                         for layer in served.core.params.layers if isinstance(layer, ObstacleLayerParams)
                         and layer.enabled for source in layer.observation_sources})
        for topic in topics:
            try:
                key = self.keys.resolve(topic)
            except KeyError as exc:
                raise ValueError(f"observation source topic {topic!r}: {exc.args[0]}") from None
            if type_for_key(key) is not LaserScan:
                raise ValueError(f"observation source topic {topic!r}: {key} does not carry LaserScan")
        return topics

    # ------------------------------------------------------------ inputs

    def on_scan(self, topic: str, msg: LaserScan) -> None:
        if self.frames.odom is None:
            self.counters["scans_before_odometry"] += 1
            return
        laser = compose(self.frames.odom, self.laser)
        for served in self.costmaps.values():
            served.core.add_scan(msg, self.frames.in_frame(served.frame, laser), topic)

    def _tracks_problem(self, msg: Tracks) -> str:
        if msg.header.frame_id != self.frames.odom_frame:
            return f"tracks in frame {msg.header.frame_id!r}, expected the odom frame {self.frames.odom_frame!r}"
        return tracks_problem(msg)

    def on_map(self, msg: OccupancyGrid) -> None:
        if self.map is not None and same_geometry(msg.info, self.map.info) and np.array_equal(msg.data, self.map.data):
            self.counters["maps_unchanged"] += 1
            return
        try:
            for served in self.costmaps.values():
                if served.needs_map:
                    served.core.set_static_map(msg)
                    served.has_map = True
        except ValueError as exc:    # e.g. a map of no cells
            self.reject(self.map_key, MessageError(str(exc), type_name="OccupancyGrid", key=self.map_key))
            return
        self.map = msg
        self.counters["maps"] += 1
        for served in self.costmaps.values():
            if served.needs_map and served.cycles == 0:   # nothing would apply it: no clock (yet)
                self._update(served)
                if served.core.params.publish_frequency > 0:
                    self.publish(served)

    def on_map_odom(self, msg: Transform) -> None:
        problem = self.frames.transform_problem(msg)
        if problem:
            self.reject(self.tf_key, MessageError(problem, type_name="Transform", key=self.tf_key))
        else:
            self.frames.set_map_odom(msg)

    def on_clear(self, msg: ClearCostmaps) -> None:
        if not msg.reset_distance >= 0:
            self.reject(self.clear_key, MessageError(f"reset_distance {msg.reset_distance} is negative",
                                                     type_name="ClearCostmaps", key=self.clear_key))
            return
        for served in self.costmaps.values():
            served.clears.hold(msg)

    # ------------------------------------------------------------ cycles

    def on_cycle(self, served: ServedCostmap) -> None:
        served.cycles += 1
        self._apply_clears(served)
        if served.needs_tracks:
            served.core.set_movers(self._movers_in(served.frame), self.now_ns)
        self._update(served)

    def _movers_in(self, frame: str):
        """The tracks in effect, predicted to now in `frame`; None without tracks or when they are stale."""
        for _, msg in self.pending_tracks.due(self.now_ns):
            self.tracks = msg
        if self.tracks is None or self.now_ns - self.tracks.header.stamp_ns > self.params.tracks_timeout_s * NS_PER_S:
            return None
        return movers_at(self.tracks, self.now_ns / NS_PER_S, self.frames.in_frame(frame, (0.0, 0.0, 0.0)), 0.0)

    def _apply_clears(self, served: ServedCostmap) -> None:
        """The clears stamped before now − request_delay_s, around the robot where it is now."""
        for _, request in served.clears.due(self.now_ns):
            robot = self.frames.robot(served.frame)
            if robot is None:
                self.counters[f"clears_before_odometry/{served.name}"] += 1
                continue
            served.core.clear_outside(robot[0], robot[1], request.reset_distance)
            self.counters[f"clears/{served.name}"] += 1

    def _update(self, served: ServedCostmap) -> None:
        robot = self.frames.robot(served.frame)
        if served.waiting_for(robot):
            return
        served.update(robot, self.frames.frame_in_map(served.frame), self.now_ns)
        self.counters[f"updates/{served.name}"] += 1

    def publish(self, served: ServedCostmap) -> None:
        if served.updated_ns is not None:
            served.publisher.publish(served.message(self.now_ns))

    def _current(self, served: ServedCostmap) -> CostmapMsg:
        if served.updated_ns is None:
            why = served.waiting_for(self.frames.robot(served.frame)) or "its first update (the sim clock)"
            raise QueryError(f"{served.publisher.key}: no costmap yet, waiting for {why}")
        return served.message(self.now_ns)

    def diagnostic(self) -> Diagnostic:
        diag = super().diagnostic()
        for served in self.costmaps.values():
            for layer, times in served.times.items():
                diag.values[f"update_ms/{served.name}/{layer}"] = statistics.median(times)
        return diag
