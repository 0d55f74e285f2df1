"""The AMCL particle filter: KLD-adaptive resampling, recovery, clustering, the pose and map→odom.

It runs as ROS amcl's laser callback does (amcl_node.cpp, pf.c):
- the first scan after (re)initialisation only records the odometry pose and weighs the particles;
- later scans update the filter once the odometry has moved more than update_min_d along its x or
  y axis, or turned more than update_min_a, since the last update (or after
  request_nomotion_update): sample the motion model, weigh with the laser model, normalise, and
  track the average weight w_avg with a slow and a fast exponential filter;
- every resample_interval-th update resamples (unless selective_resampling finds the effective
  sample size above N/2).
Not in amcl (each off by default): with temporal_update > 0, a scan that comes that long after the
last update updates the filter without motion too, after spreading the particles by
temporal_update_jitter_* (see _jitter), so a robot that stopped on a wrong estimate still converges
to what its scans say; recovery_reset_after_injection false keeps w_slow and w_fast after an
injection (Augmented_MCL as Probabilistic Robotics has it), and recovery_local_share draws that
share of the random poses near the estimate, where a shoved robot is.

Resampling draws N particles, N chosen by KLD sampling (Fox 2003): samples are drawn one by one,
the 0.5 m × 0.5 m × 10° bins they fall in are counted (k), and drawing stops once the count
reaches the bound kld_limit(k) (clamped to min_particles..max_particles; amcl stops one sample
later). Each draw is, with probability w_diff = max(0, 1 − w_fast/w_slow), a uniformly random pose
in free space (Augmented MCL); when w_diff > 0 both averages are zeroed afterwards and restart at
the next update, as amcl does. That sequential pass only fixes N and the random poses; the other
particles are then taken by low-variance (systematic) resampling, so particle i is copied ⌊m·wᵢ⌋
or ⌈m·wᵢ⌉ times (m = N − random poses). amcl draws each sample independently instead because,
its comment says, the low-variance sampler does not combine easily with KLD sampling.

Differences from amcl, on purpose: w_avg is Σ wᵢ·pᵢ (weights summing to 1 before the update),
the average likelihood Probabilistic Robotics uses, where amcl divides it once more by N, which
makes its recovery react to changes of the particle count; angles are kept in [−π, π) and the
angle bins wrap around, so a cluster across ±π stays one cluster.

The estimate is amcl's: clusters are connected groups of occupied bins (26-neighbourhood); the
pose is the weighted mean of the heaviest cluster (circular mean for the angle), its covariance
the whole set's (x, y block and −2 ln R for the angle, R the mean resultant length).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from ...schemas.messages import OccupancyGrid
from ...geometry.grid import cell_to_world
from ...geometry.se2 import compose, inverse, wrap_angle
from . import motion, sensor
from .params import AmclParams
from .sensor import FREE, LaserModel, ScanBeams

BIN_XY = 0.5                    # m, KLD and cluster bins (amcl's pf_kdtree)
ANGLE_BINS = 36                 # 10° bins
CONVERGED_DISTANCE = 0.5        # m: every particle this close to the mean in x and y (amcl's dist_threshold)
_OFFSET = 1 << 20               # keeps bin indices non-negative inside the key
_STATS = 9                      # per cluster: w, Σwx, Σwy, Σw cos, Σw sin, Σwxx, Σwxy, Σwyy, count


@njit(cache=True)
def kld_limit(k: int, kld_err: float, kld_z: float, min_particles: int, max_particles: int) -> int:
    """Fox's bound on the particles needed for k occupied bins, clamped to [min, max]:

        n = ⌈ (k − 1)/(2ε) · (1 − 2/(9(k − 1)) + √(2/(9(k − 1)))·z)³ ⌉

    (the Wilson–Hilferty approximation of χ²_{k−1, 1−δ}/(2ε)); one bin needs max_particles, as in amcl.
    """
    if k <= 1:
        return max_particles
    b = 2.0 / (9.0 * (k - 1))
    x = 1.0 - b + math.sqrt(b) * kld_z
    n = int(math.ceil((k - 1) / (2.0 * kld_err) * x * x * x))
    return min(max(n, min_particles), max_particles)


# ---------------------------------------------------------------- bins: a reusable hash set

@njit(cache=True)
def _bin_key(x, y, theta):
    ix = int(math.floor(x / BIN_XY)) + _OFFSET
    iy = int(math.floor(y / BIN_XY)) + _OFFSET
    ia = int(math.floor((theta + math.pi) * ANGLE_BINS / (2.0 * math.pi))) % ANGLE_BINS
    return (ix * (1 << 21) + iy) * 64 + ia


@njit(cache=True)
def _key_parts(key):
    return key // 64 // (1 << 21), key // 64 % (1 << 21), key % 64


@njit(cache=True)
def _slot(keys, stamps, stamp, key):
    """The slot holding `key`, or the empty slot where it would go (open addressing)."""
    mask = keys.shape[0] - 1
    slot = (key * 0x5851F42D4C957F2D >> 17) & mask
    while stamps[slot] == stamp and keys[slot] != key:
        slot = (slot + 1) & mask
    return slot


@njit(cache=True)
def _insert(keys, values, stamps, stamp, key, value):
    """Store key → value unless present; returns (the stored value, whether it was new)."""
    slot = _slot(keys, stamps, stamp, key)
    if stamps[slot] == stamp:
        return values[slot], False
    keys[slot], values[slot], stamps[slot] = key, value, stamp
    return value, True


@njit(cache=True)
def _find(keys, values, stamps, stamp, key):
    slot = _slot(keys, stamps, stamp, key)
    return values[slot] if stamps[slot] == stamp else -1


@njit(cache=True)
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def _cluster_stats(poses, weights, n, keys, values, stamps, stamp, bin_key, parent, particle_bin, stats):
    """Cluster the particles by connected bins; fills stats[c] (see _STATS), returns the count."""
    # not 0: a counter starting at a literal 0 has numba compile _insert once more, for Literal[int](0)
    bins = np.int64(0)
    for i in range(n):
        key = _bin_key(poses[i, 0], poses[i, 1], poses[i, 2])
        b, new = _insert(keys, values, stamps, stamp, key, bins)
        if new:
            bin_key[bins] = key
            parent[bins] = bins
            bins += 1
        particle_bin[i] = b
    for b in range(bins):
        ix, iy, ia = _key_parts(bin_key[b])
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for da in range(-1, 2):
                    other = _find(keys, values, stamps, stamp,
                                  ((ix + dx) * (1 << 21) + iy + dy) * 64 + (ia + da) % ANGLE_BINS)
                    if other >= 0:
                        ra, rb = _root(parent, b), _root(parent, other)
                        if ra != rb:
                            parent[max(ra, rb)] = min(ra, rb)
    label = np.full(bins, -1, np.int64)  # root bin -> cluster
    clusters = 0
    stats[:bins] = 0.0
    for i in range(n):
        root = _root(parent, particle_bin[i])
        if label[root] < 0:
            label[root] = clusters
            clusters += 1
        c = label[root]
        w, x, y, a = weights[i], poses[i, 0], poses[i, 1], poses[i, 2]
        stats[c, 0] += w
        stats[c, 1] += w * x
        stats[c, 2] += w * y
        stats[c, 3] += w * math.cos(a)
        stats[c, 4] += w * math.sin(a)
        stats[c, 5] += w * x * x
        stats[c, 6] += w * x * y
        stats[c, 7] += w * y * y
        stats[c, 8] += 1.0
    return clusters


# ---------------------------------------------------------------- sampling kernels

@njit(cache=True)
def _random_pose(out, j, free_xy, col_step, row_step, rng):
    """A uniform pose over the free cells: a random cell, a random point in it, a random heading."""
    cell = min(int(rng.random() * free_xy.shape[0]), free_xy.shape[0] - 1)
    ju, jv = rng.random() - 0.5, rng.random() - 0.5
    out[j, 0] = free_xy[cell, 0] + ju * col_step[0] + jv * row_step[0]
    out[j, 1] = free_xy[cell, 1] + ju * col_step[1] + jv * row_step[1]
    out[j, 2] = rng.random() * 2.0 * math.pi - math.pi


@njit(cache=True)
def _recovery_pose(out, j, free_xy, col_step, row_step, rng, centre, local_share, local_std_xy, local_std_a):
    """A random pose for recovery: with probability local_share near `centre` (a Gaussian), else
    uniform over the free cells."""
    if local_share > 0.0 and rng.random() < local_share:
        out[j, 0] = centre[0] + rng.normal(0.0, local_std_xy)
        out[j, 1] = centre[1] + rng.normal(0.0, local_std_xy)
        out[j, 2] = (centre[2] + rng.normal(0.0, local_std_a) + math.pi) % (2.0 * math.pi) - math.pi
    else:
        _random_pose(out, j, free_xy, col_step, row_step, rng)


@njit(cache=True)
def _random_poses(out, count, free_xy, col_step, row_step, rng):
    for j in range(count):
        _random_pose(out, j, free_xy, col_step, row_step, rng)


@njit(cache=True)
def _normalise(weights, n, total):
    """Weights to sum 1 (uniform when total is not positive); returns Σ w²."""
    squares = 0.0
    if total > 0.0 and math.isfinite(total):
        for i in range(n):
            weights[i] /= total
            squares += weights[i] * weights[i]
    else:
        for i in range(n):
            weights[i] = 1.0 / n
        squares = 1.0 / n
    return squares


@njit(cache=True)
def _cumulative(weights, n, cum):
    acc = 0.0
    for i in range(n):
        acc += weights[i]
        cum[i] = acc
    return acc


@njit(cache=True)
def systematic_indices(cum, n, count, u0, out):
    """Low-variance (systematic) resampling: out[j] = the particle whose interval of the cumulative
    weights cum[:n] holds (u0 + j)/count of the total, u0 in [0, 1). Particle i is picked
    ⌊count·wᵢ⌋ or ⌈count·wᵢ⌉ times."""
    total = cum[n - 1]
    i = 0
    for j in range(count):
        u = (u0 + j) / count * total
        while i < n - 1 and cum[i] <= u:
            i += 1
        out[j] = i


@njit(cache=True)
def _kld_count(poses, weights, n, w_diff, rng, free_xy, col_step, row_step, centre, local_share, local_std_xy,
               local_std_a, random_out, keys, values, stamps, stamp, bin_cum, seen, kld_err, kld_z, min_particles,
               max_particles):
    """How many particles KLD sampling draws, and the random poses among them (in random_out).

    Only a draw's bin matters for the count, so the particles' weights are first summed per bin
    and the draws pick bins: the same distribution of occupied bins, for fewer steps per draw."""
    bins = np.int64(0)     # not 0: see _cluster_stats
    for i in range(n):
        b, new = _insert(keys, values, stamps, stamp, _bin_key(poses[i, 0], poses[i, 1], poses[i, 2]), bins)
        if new:
            bin_cum[bins] = 0.0
            seen[bins] = False
            bins += 1
        bin_cum[b] += weights[i]
    total = 0.0
    for b in range(bins):
        total += bin_cum[b]
        bin_cum[b] = total
    ids = bins      # bins first met through a random pose get ids from here on
    occupied = 0
    randoms = np.int64(0)  # not 0: see _cluster_stats (for _recovery_pose and _random_pose)
    count = 0
    while count < max_particles:
        if w_diff > 0.0 and rng.random() < w_diff:
            _recovery_pose(random_out, randoms, free_xy, col_step, row_step, rng, centre, local_share, local_std_xy,
                           local_std_a)
            key = _bin_key(random_out[randoms, 0], random_out[randoms, 1], random_out[randoms, 2])
            randoms += 1
            b, new = _insert(keys, values, stamps, stamp, key, ids)
            if new:
                seen[ids] = False
                ids += 1
        else:
            b = min(np.searchsorted(bin_cum[:bins], rng.random() * total, side="right"), bins - 1)
        if not seen[b]:
            seen[b] = True
            occupied += 1
        count += 1
        if count >= kld_limit(occupied, kld_err, kld_z, min_particles, max_particles):
            break
    return count, randoms


@njit(cache=True)
def _gather(src, idx, count, dst):
    for j in range(count):
        dst[j, 0], dst[j, 1], dst[j, 2] = src[idx[j], 0], src[idx[j], 1], src[idx[j], 2]


@njit(cache=True)
def _converged(poses, n, distance):
    mx, my = 0.0, 0.0
    for i in range(n):
        mx += poses[i, 0]
        my += poses[i, 1]
    mx, my = mx / n, my / n
    for i in range(n):
        if abs(poses[i, 0] - mx) > distance or abs(poses[i, 1] - my) > distance:
            return False
    return True


# ---------------------------------------------------------------- the filter

@dataclass(frozen=True)
class PoseEstimate:
    pose: np.ndarray          # (3,) x, y, θ: weighted mean of the heaviest cluster
    covariance: np.ndarray    # (3, 3): the whole set's, as amcl reports it
    weight: float             # weight of the heaviest cluster (weights sum to 1)
    clusters: int


def map_to_odom(map_pose, odom_pose) -> np.ndarray:
    """The odom frame's pose in the map frame, given the robot's pose in both (amcl's published tf)."""
    return compose(map_pose, inverse(odom_pose))


def free_cells(grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (F, 2) of the free cells, and the map-frame steps of one column and one row."""
    rows, cols = np.nonzero(np.asarray(grid.data) == FREE)
    xs, ys = cell_to_world(grid.info, rows, cols)
    x0, y0 = cell_to_world(grid.info, [0, 0, 1], [0, 1, 0])
    col_step = np.array([x0[1] - x0[0], y0[1] - y0[0]])
    row_step = np.array([x0[2] - x0[0], y0[2] - y0[0]])
    return np.column_stack([xs, ys]), col_step, row_step


class Amcl:
    """AMCL on one map. Randomness comes only from `rng`, advanced only by the filter's work."""

    def __init__(self, params: AmclParams, grid: OccupancyGrid, rng: np.random.Generator):
        self.params = params
        self.rng = rng
        self.laser = LaserModel(grid, params)
        self.motion = params.motion_params()    # the motion model's own group (its noise)
        self._free_xy, self._col_step, self._row_step = free_cells(grid)
        if self._free_xy.shape[0] == 0:
            raise ValueError("the map has no free cell (occupancy 0) to place particles in")
        size = params.max_particles
        self._poses = [np.zeros((size, 3)), np.zeros((size, 3))]
        self._weights = [np.zeros(size), np.zeros(size)]
        self._current = 0
        self.n = 0
        # scratch, sized once
        self._cum = np.zeros(size)
        self._bin_cum = np.zeros(size)
        self._seen = np.zeros(2 * size, np.bool_)
        self._index = np.zeros(size, np.int64)
        self._randoms = np.zeros((size, 3))
        self._bin_key = np.zeros(size, np.int64)
        self._parent = np.zeros(size, np.int64)
        self._particle_bin = np.zeros(size, np.int64)
        self._stats = np.zeros((size, _STATS))
        table = 1 << int(math.ceil(math.log2(4 * size)))
        self._keys = np.zeros(table, np.int64)
        self._values = np.zeros(table, np.int64)
        self._stamps = np.zeros(table, np.int64)
        self._stamp = 0
        # filter state
        self.w_slow = self.w_fast = 0.0
        self.w_avg = 0.0                  # average likelihood of the last update
        self.n_effective = 0.0
        self.converged = False
        self.resampled = False            # whether the last update resampled
        self.injected = 0                 # random poses among the particles of the last resampling
        self._odom = None                 # odometry pose at the last update; None: next scan starts
        self._update_s: float | None = None   # sim time of the last update (for temporal_update)
        self._updates = 0
        self._force_update = False
        self._estimate: PoseEstimate | None = None
        self.set_initial_pose((params.initial_pose_x, params.initial_pose_y, params.initial_pose_a),
                              np.diag([params.initial_cov_xx, params.initial_cov_yy, params.initial_cov_aa]))

    # ---- particles
    @property
    def poses(self) -> np.ndarray:
        return self._poses[self._current][:self.n]

    @property
    def weights(self) -> np.ndarray:
        return self._weights[self._current][:self.n]

    def _reset(self, count: int) -> None:
        self.n = count
        self._weights[self._current][:count] = 1.0 / count
        self.w_slow = self.w_fast = 0.0
        self.converged = False
        self._odom = None
        self._estimate = None
        self._updates = 0

    def set_initial_pose(self, pose, covariance) -> None:
        """max_particles drawn from a Gaussian (amcl's pf_init); the next scan restarts the filter."""
        size = self.params.max_particles
        draws = self.rng.multivariate_normal(np.asarray(pose, float), np.asarray(covariance, float), size,
                                             method="eigh")
        draws[:, 2] = wrap_angle(draws[:, 2])
        self._poses[self._current][:size] = draws
        self._reset(size)
        if self.params.force_update_after_initialpose:
            self._force_update = True

    def global_localization(self) -> None:
        """max_particles spread uniformly over the free cells, headings uniform."""
        size = self.params.max_particles
        _random_poses(self._poses[self._current], size, self._free_xy, self._col_step, self._row_step, self.rng)
        self._reset(size)

    def request_nomotion_update(self) -> None:
        """Update at the next scan even without motion (amcl's request_nomotion_update)."""
        self._force_update = True

    # ---- the update
    def update(self, odom_pose, scan: ScanBeams, stamp_s: float | None = None) -> bool:
        """Process one scan taken at odometry pose `odom_pose` (sim time `stamp_s`, needed only for
        temporal updates); True when the filter updated."""
        p = self.params
        odom_pose = np.asarray(odom_pose, np.float64)
        self.resampled = False
        if self._odom is None:
            self._odom = odom_pose.copy()
        else:
            dx, dy, da = motion.odom_delta(self._odom, odom_pose)
            moved = abs(dx) > p.update_min_d or abs(dy) > p.update_min_d or abs(da) > p.update_min_a
            temporal = not (moved or self._force_update) and self._temporal_update_due(stamp_s)
            if not (moved or self._force_update or temporal):
                return False
            self._force_update = False  # as in amcl, only a scan after the first one uses it up
            step = motion.decompose(p.odom_model_type, self._odom, odom_pose, self.motion.alphas)
            motion.sample_motion(self._poses[self._current], self.n, step, self.rng)
            if temporal:
                self._jitter()
        self._weigh(scan)
        self._odom = odom_pose.copy()
        self._update_s = stamp_s
        self._updates += 1
        if self._updates % p.resample_interval == 0:
            self.resample()
        return True

    def _temporal_update_due(self, stamp_s: float | None) -> bool:
        p = self.params
        return (p.temporal_update > 0 and stamp_s is not None and self._update_s is not None
                and stamp_s - self._update_s >= p.temporal_update)

    def _jitter(self) -> None:
        """Spread the particles a little: the motion model adds (almost) no noise without motion, so
        weighing the same view again and resampling would otherwise shrink the set onto the few
        particles that fit it best (particle deprivation), and no particle would move towards a
        better pose between them."""
        p, poses = self.params, self._poses[self._current][:self.n]
        noise = self.rng.standard_normal((self.n, 3))
        poses[:, :2] += noise[:, :2] * p.temporal_update_jitter_xy
        poses[:, 2] = wrap_angle(poses[:, 2] + noise[:, 2] * p.temporal_update_jitter_a)

    def _weigh(self, scan: ScanBeams) -> None:
        poses, weights = self._poses[self._current], self._weights[self._current]
        total = self.laser.weigh(poses, self.n, scan, weights, self.converged)
        self.n_effective = 1.0 / _normalise(weights, self.n, total)
        self._estimate = None
        if not (total > 0.0 and math.isfinite(total)):
            return
        # total = Σ wᵢ pᵢ with Σ wᵢ = 1 before the update: the average likelihood
        p = self.params
        self.w_avg = total
        self.w_slow = total if self.w_slow == 0.0 else self.w_slow + p.recovery_alpha_slow * (total - self.w_slow)
        self.w_fast = total if self.w_fast == 0.0 else self.w_fast + p.recovery_alpha_fast * (total - self.w_fast)

    def resample(self) -> None:
        """KLD-sized low-variance resampling with random-pose injection (see the module docstring)."""
        p = self.params
        if p.selective_resampling and self.n_effective > 0.5 * self.n:
            return
        poses, weights = self._poses[self._current], self._weights[self._current]
        w_diff = max(0.0, 1.0 - self.w_fast / self.w_slow) if self.w_slow > 0.0 else 0.0
        # before taking a fresh stamp: the estimate fills the bin table under its own
        centre = self.estimate().pose if w_diff > 0.0 and p.recovery_local_share > 0.0 else np.zeros(3)
        _cumulative(weights, self.n, self._cum)
        self._stamp += 1
        count, randoms = _kld_count(poses, weights, self.n, w_diff, self.rng, self._free_xy, self._col_step,
                                    self._row_step, centre, p.recovery_local_share, p.recovery_local_std_xy,
                                    p.recovery_local_std_a, self._randoms, self._keys, self._values, self._stamps,
                                    self._stamp, self._bin_cum, self._seen, p.kld_err, p.kld_z,
                                    p.min_particles, p.max_particles)
        drawn = count - randoms
        systematic_indices(self._cum, self.n, drawn, self.rng.random(), self._index)
        target = 1 - self._current
        _gather(poses, self._index, drawn, self._poses[target])
        self._poses[target][drawn:count] = self._randoms[:randoms]
        self._weights[target][:count] = 1.0 / count
        self._current, self.n = target, count
        if w_diff > 0.0 and p.recovery_reset_after_injection:
            self.w_slow = self.w_fast = 0.0
        self.converged = _converged(self._poses[target], count, CONVERGED_DISTANCE)
        self.resampled = True
        self.injected = randoms
        self._estimate = None

    # ---- results
    def estimate(self) -> PoseEstimate:
        """The pose (heaviest cluster's mean) and the covariance of the current particle set."""
        if self._estimate is None:
            self._estimate = self._compute_estimate()
        return self._estimate

    def map_to_odom(self) -> np.ndarray:
        """The map→odom transform of the estimate, against the odometry pose of the last update."""
        return map_to_odom(self.estimate().pose, self._odom if self._odom is not None else np.zeros(3))

    def pose_at(self, odom_pose) -> np.ndarray:
        """The robot's map pose now: the estimate carried forward by the odometry since the update."""
        return compose(self.map_to_odom(), np.asarray(odom_pose, np.float64))

    def _compute_estimate(self) -> PoseEstimate:
        self._stamp += 1
        count = _cluster_stats(self.poses, self.weights, self.n, self._keys, self._values, self._stamps,
                               self._stamp, self._bin_key, self._parent, self._particle_bin, self._stats)
        stats = self._stats[:count]
        best = stats[int(np.argmax(stats[:, 0]))]
        pose = np.array([best[1] / best[0], best[2] / best[0], math.atan2(best[4], best[3])])
        whole = stats.sum(axis=0)
        weight = whole[0]
        mean_x, mean_y = whole[1] / weight, whole[2] / weight
        covariance = np.zeros((3, 3))
        covariance[0, 0] = whole[5] / weight - mean_x * mean_x
        covariance[0, 1] = covariance[1, 0] = whole[6] / weight - mean_x * mean_y
        covariance[1, 1] = whole[7] / weight - mean_y * mean_y
        resultant = math.hypot(whole[3], whole[4]) / weight
        covariance[2, 2] = -2.0 * math.log(max(resultant, 1e-300))
        return PoseEstimate(pose=pose, covariance=covariance, weight=float(best[0] / weight), clusters=count)


def warm_up() -> None:
    """Compile (or load from cache) every kernel the filter uses, so no update pays for it."""
    motion.warm_up()
    sensor.warm_up()
    grid = OccupancyGrid()
    grid.data = np.zeros((4, 4), np.int8)
    grid.info.width = grid.info.height = 4
    amcl = Amcl(AmclParams(min_particles=4, max_particles=8, resample_interval=1, recovery_alpha_slow=0.001,
                           recovery_alpha_fast=0.1), grid, np.random.default_rng(0))
    scan = sensor.prepare_scan(np.ones(3), -1.0, 1.0, 0.05, 5.0, amcl.params)
    amcl.update((0.0, 0.0, 0.0), scan)
    amcl.w_slow, amcl.w_fast = 1.0, 0.5  # make the injection path compile too
    amcl.resample()
    amcl.params = replace(amcl.params, recovery_local_share=0.5)
    amcl.w_slow, amcl.w_fast = 1.0, 0.5
    amcl.resample()
    amcl.estimate()
    amcl.global_localization()
