"""A Rao-Blackwellized particle filter for grid SLAM, in the manner of gmapping.

Each particle is a robot pose, a log-odds map of its own (tiles shared copy-on-write, grid.py) and
a trajectory (a node in a tree shared by all particles: resampling copies a reference, not a
history). On each scan after the robot has driven linearUpdate or turned angularUpdate (or after
temporalUpdate seconds), every particle

  1. moves by the odometry increment plus sampled noise (srr, srt, str, stt),
  2. is pulled onto its own map by the scan matcher — the improved proposal; a score below
     minimumScore keeps the odometry guess,
  3. is weighted by the scan's likelihood in its map at that pose (accumulated in log space,
     normalised with gain 1/(ogain · particles) as gmapping does, which tempers the weights),

then the particles are resampled (low variance) when the effective sample size falls below
resampleThreshold · particles, and each particle's map integrates the scan at its pose.
Scans in between move the particles by odometry only, as gmapping does.

mode "scan_matching" keeps one particle without noise or weights: hector-style scan-to-map
tracking, for robots whose odometry is poor or missing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry.se2 import compose, inverse, relative, wrap_angle
from ...schemas.messages import OccupancyGrid
from .particle_grids import GridGeometry, TiledGrids, cut_beams
from .params import SlamParams
from .scanmatch import gaussian_kernel, match_all


class _Nodes:
    """The trajectory tree: node k = (parent, scan index, pose); particles point at their newest.
    Branches of particles that resampling dropped are reclaimed whenever the arrays fill up, so
    the tree holds about one pose per processed scan plus the particles' recent branches."""

    def __init__(self, capacity: int = 1024):
        self.parent = np.empty(capacity, np.int64)
        self.scan = np.empty(capacity, np.int64)
        self.pose = np.empty((capacity, 3))
        self.count = 0

    def _compact(self, heads: np.ndarray) -> np.ndarray:
        """Keep the nodes some head still reaches; returns the heads' new ids."""
        alive = np.zeros(self.count, bool)
        for node in heads:
            while node >= 0 and not alive[node]:
                alive[node] = True
                node = self.parent[node]
        keep = np.nonzero(alive)[0]            # parents come before children: order is kept
        new_id = np.full(self.count, -1, np.int64)
        new_id[keep] = np.arange(len(keep))
        parents = self.parent[keep]
        self.parent[:len(keep)] = np.where(parents >= 0, new_id[np.maximum(parents, 0)], -1)
        self.scan[:len(keep)] = self.scan[keep]
        self.pose[:len(keep)] = self.pose[keep]
        self.count = len(keep)
        return np.where(heads >= 0, new_id[np.maximum(heads, 0)], -1)

    def add(self, heads: np.ndarray, scan: int, poses: np.ndarray) -> np.ndarray:
        """A node per particle, child of its head; returns the new heads."""
        n = len(heads)
        if self.count + n > len(self.parent):
            heads = self._compact(heads)
            if self.count + n > len(self.parent) // 2:  # keep room, so compaction stays rare
                grow = max(len(self.parent), n)
                self.parent = np.concatenate([self.parent, np.empty(grow, np.int64)])
                self.scan = np.concatenate([self.scan, np.empty(grow, np.int64)])
                self.pose = np.concatenate([self.pose, np.empty((grow, 3))])
        ids = np.arange(self.count, self.count + n)
        self.parent[ids], self.scan[ids], self.pose[ids] = heads, scan, poses
        self.count += n
        return ids

    def chain(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        """(scan indices, poses) from the first node to `node`, oldest first."""
        ids = []
        while node >= 0:
            ids.append(node)
            node = self.parent[node]
        ids = np.array(ids[::-1], np.int64)
        return self.scan[ids], self.pose[ids]


@dataclass
class ScanUpdate:
    """What one processed scan did, for diagnostics."""
    scan_index: int
    scores: np.ndarray          # matching score per particle (before resampling)
    neff: float
    resampled: bool


class Rbpf:
    """The filter. Feed it every scan with the odometry pose at the scan's stamp."""

    def __init__(self, params: SlamParams, angles, range_max: float, range_min: float = 0.0, start=(0.0, 0.0, 0.0)):
        self.params = p = params
        self.start = np.asarray(start, np.float64)   # the map-frame pose given to the first scan
        self.n = p.particles if p.mode == "rbpf" else 1
        self.angles = np.asarray(angles, np.float64)
        self.range_min = float(range_min)
        self.max_range = p.maxRange if p.maxRange is not None else float(range_max) - 0.01
        self.laser = np.array([p.laser_x, p.laser_y, p.laser_yaw])
        self.grids = TiledGrids(GridGeometry.from_extent(p.xmin, p.ymin, p.xmax, p.ymax, p.delta), self.n)
        g = self.grids.geometry
        self._geo = np.array([g.xmin, g.ymin, 1.0 / g.delta])
        self._kernel = gaussian_kernel(p.kernelSize, p.delta, p.sigma)
        # the coarse search steps lstep: a field twice as wide keeps its candidates from falling
        # between obstacles
        self._coarse_kernel = gaussian_kernel(p.kernelSize + 1, p.delta, 2 * p.sigma)
        # Cartographer's translation / rotation weights, squared: its residuals are weight · (pose − guess)
        self._prior_weight = np.array([p.translation_weight, p.translation_weight, p.rotation_weight]) ** 2
        self.poses = np.zeros((self.n, 3))
        self.log_weights = np.zeros(self.n)      # since the last resampling
        self.lineage_loglik = np.zeros(self.n)   # over the particle's whole ancestry
        self.weights = np.full(self.n, 1.0 / self.n)
        self.nodes = _Nodes()
        self.heads = np.full(self.n, -1, np.int64)
        self.rng = np.random.default_rng(p.seed)
        self.scan_count = 0
        self.updates = 0
        self.resamples = 0
        self._last_odom: np.ndarray | None = None   # odometry at the last processed scan
        self._last_stamp = 0
        self._odom: np.ndarray | None = None        # odometry at the latest scan

    # ------------------------------------------------------------ the estimate

    @property
    def best(self) -> int:
        """The particle whose ancestry explains the scans best (its weight alone says nothing
        right after a resampling)."""
        return int(np.argmax(self.lineage_loglik))

    def pose(self) -> np.ndarray:
        """The best particle's robot pose in the map frame at the latest scan."""
        return compose(self.poses[self.best], relative(self._last_odom, self._odom))

    def map_to_odom(self) -> np.ndarray:
        """The map → odom transform: the best pose composed with the inverse odometry pose."""
        return compose(self.pose(), inverse(self._odom))

    def covariance(self) -> np.ndarray:
        """The particles' weighted spread at their last update (headings about the best one's)."""
        poses, w = self.poses.copy(), self.weights
        best = poses[self.best]
        poses[:, 2] = best[2] + wrap_angle(poses[:, 2] - best[2])
        d = poses - w @ poses
        return (w[:, None] * d).T @ d

    def occupancy_grid(self, occ_thresh: float) -> OccupancyGrid:
        """The best particle's map."""
        return self.grids.occupancy_grid(self.best, occ_thresh)

    def trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """The best particle's (scan indices, poses) at the scans it processed, oldest first."""
        return self.nodes.chain(int(self.heads[self.best]))

    def bytes_per_particle(self) -> float:
        """Map memory (shared tiles counted once) plus trajectory nodes, per particle."""
        nodes = self.nodes.count * (8 + 8 + 24)
        return (self.grids.bytes_in_use() + nodes) / self.n

    # ------------------------------------------------------------ processing

    def _beams(self, ranges: np.ndarray):
        """The scan's beams for the maps (laser frame) and its end points for matching (robot frame)."""
        p = self.params
        beams = cut_beams(ranges, self.angles, self.range_min, self.max_range, p.maxUrange)
        idx = np.nonzero(beams[2])[0][::p.lskip + 1]
        points = compose(self.laser, np.stack([beams[0][idx], beams[1][idx], np.zeros(len(idx))], axis=-1))
        return beams, np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])

    def _integrate(self, beams, maps) -> None:
        """Integrate the scan into the given maps, each at its particle's pose."""
        p = self.params
        bx, by, hit = beams
        laser = compose(self.poses[maps], self.laser)
        c, s = np.cos(laser[:, 2:]), np.sin(laser[:, 2:])
        ends_x = laser[:, :1] + c * bx - s * by
        ends_y = laser[:, 1:2] + s * bx + c * by
        self.grids.integrate_all(laser[:, :2], ends_x, ends_y, hit, p.l_occ, p.l_free, p.l_max, maps)

    def _due(self, motion: np.ndarray, stamp_ns: int) -> bool:
        p = self.params
        if np.hypot(motion[0], motion[1]) >= p.linearUpdate or abs(motion[2]) >= p.angularUpdate:
            return True
        return p.temporalUpdate > 0 and (stamp_ns - self._last_stamp) * 1e-9 >= p.temporalUpdate

    def _motion_std(self, motion: np.ndarray) -> tuple[float, float]:
        """Standard deviations (m, rad) of the odometry's error over `motion` (gmapping's model)."""
        p = self.params
        dist, turn = float(np.hypot(motion[0], motion[1])), abs(float(motion[2]))
        return p.srr * dist + p.srt * turn, p.str * dist + p.stt * turn

    def _sample_motion(self, motion: np.ndarray) -> np.ndarray:
        moves = np.repeat(motion[None, :], self.n, axis=0)
        if self.params.mode == "rbpf":
            trans_std, rot_std = self._motion_std(motion)
            moves[:, :2] += self.rng.normal(0.0, 1.0, (self.n, 2)) * trans_std
            moves[:, 2] += self.rng.normal(0.0, 1.0, self.n) * rot_std
        return moves

    def _normalise(self) -> float:
        gain = 1.0 / (self.params.ogain * self.n)
        w = np.exp(gain * (self.log_weights - self.log_weights.max()))
        self.weights = w / w.sum()
        return float(1.0 / np.sum(self.weights ** 2))

    def _resample(self) -> None:
        """Low-variance resampling; every survivor starts again with equal weight."""
        start = self.rng.random() / self.n
        positions = start + np.arange(self.n) / self.n
        parents = np.minimum(np.searchsorted(np.cumsum(self.weights), positions), self.n - 1)
        self.poses = self.poses[parents]
        self.heads = self.heads[parents]
        self.lineage_loglik = self.lineage_loglik[parents]
        self.grids.resample(parents)
        self.log_weights = np.zeros(self.n)
        self.weights = np.full(self.n, 1.0 / self.n)
        self.resamples += 1

    def process(self, stamp_ns: int, odom_pose, ranges) -> ScanUpdate | None:
        """One scan with the robot's odometry pose at its stamp; returns what the update did, or
        None when the scan was not due (the robot had not moved enough)."""
        p = self.params
        odom = np.asarray(odom_pose, np.float64)
        index = self.scan_count
        self.scan_count += 1
        self._odom = odom
        beams, px, py = self._beams(ranges)
        if self._last_odom is None:  # the map frame: the first scan is at `start` (default: its own pose)
            self.poses[:] = self.start
            self._integrate(beams, np.array([0]))
            self.grids.resample(np.zeros(self.n, np.int64))  # every particle starts from this map
            self._finish(index, odom, stamp_ns)
            return ScanUpdate(index, np.ones(self.n), float(self.n), False)
        motion = relative(self._last_odom, odom)
        if not self._due(motion, stamp_ns):
            return None
        # each particle's match is pulled towards its pose moved by the odometry (translation_weight,
        # rotation_weight), not towards its noisy sample: that pull would make a random walk of the
        # directions the scan hardly constrains (along a corridor)
        predicted = compose(self.poses, motion)
        guesses = compose(self.poses, self._sample_motion(motion))
        # the search covers at least search_sigmas standard deviations of the odometry's error,
        # so a long odometry step (after a stall in the odometry stream) gets a wide search
        trans_std, rot_std = self._motion_std(motion)
        window = max(p.search_window, p.search_sigmas * trans_std) if p.search_window > 0 else 0.0
        angle = max(p.search_angle, p.search_sigmas * rot_std) if p.search_angle > 0 else 0.0
        poses, scores, loglik = match_all(
            self.grids.pool, self.grids.hits, self.grids.tables, self._geo, px, py, guesses, self._kernel,
            self._coarse_kernel, p.sigma, 1.0 / p.l_occ, p.iterations, p.minimumScore, p.search_below, window, p.lstep,
            angle, p.astep, p.kernelSize + 1, p.lsigma, predicted, self._prior_weight)
        poses[:, 2] = wrap_angle(poses[:, 2])
        self.poses = poses
        self.log_weights += loglik
        self.lineage_loglik += loglik
        neff = self._normalise()
        resampled = self.n > 1 and neff < p.resampleThreshold * self.n
        if resampled:
            self._resample()
        self._integrate(beams, np.arange(self.n))
        self._finish(index, odom, stamp_ns)
        return ScanUpdate(index, scores, neff, resampled)

    def _finish(self, index: int, odom: np.ndarray, stamp_ns: int) -> None:
        self.heads = self.nodes.add(self.heads, index, self.poses)
        self._last_odom = odom
        self._last_stamp = stamp_ns
        self.updates += 1
