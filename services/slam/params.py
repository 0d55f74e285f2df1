"""The SLAM core's parameters: gmapping's names and defaults (ROS slam_gmapping) where it has one."""
from __future__ import annotations

from dataclasses import dataclass

MODES = ("rbpf", "scan_matching")


@dataclass(frozen=True)
class SlamParams:
    mode: str = "rbpf"                 # rbpf | scan_matching (one pose, no motion noise: hector-like)
    particles: int = 30
    # the map
    delta: float = 0.05                # m per cell
    xmin: float = -100.0               # m: the map's extent (tiles are allocated only where seen)
    ymin: float = -100.0
    xmax: float = 100.0
    ymax: float = 100.0
    # gmapping's 0.25 is a threshold on its hit ratio (hits / beams through a cell); on a
    # log-odds cell, one pass of a beam already gives 0.4, so map_server's 0.65 is used instead
    occ_thresh: float = 0.65           # occupancy probability above which a published cell is occupied
    map_update_interval: float = 5.0   # s of sim time between published maps (for the node)
    # the laser
    maxUrange: float = 80.0            # m: beams are cut here; longer ones only clear free space
    maxRange: float | None = None      # m: beams at or beyond are dropped (None: the scan's range_max − 1 cm)
    lskip: int = 0                     # use every (lskip+1)-th beam for matching and weighting
    # the scan matcher
    sigma: float = 0.05                # m: width of the matching field around occupied cells
    kernelSize: int = 1                # cells: how far from an endpoint an occupied cell is looked for
    lstep: float = 0.05                # m: linear step of the correlative search
    astep: float = 0.05                # rad: angular step of the correlative search
    iterations: int = 5                # refinement iterations (Gauss-Newton)
    lsigma: float = 0.075              # m: beam likelihood width, for the particle weights
    ogain: float = 3.0                 # divides the log-likelihood before normalising (smooths resampling)
    minimumScore: float = 0.0          # below this matching score the odometry guess is kept
    # motion model: odometry noise (gmapping: translation/rotation as a function of translation/rotation)
    srr: float = 0.1                   # m/m
    srt: float = 0.2                   # m/rad
    str: float = 0.1                   # rad/m
    stt: float = 0.2                   # rad/rad
    # when to process a scan
    linearUpdate: float = 1.0          # m driven
    angularUpdate: float = 0.5         # rad turned
    temporalUpdate: float = -1.0       # s since the last update (≤ 0: never by time alone)
    resampleThreshold: float = 0.5     # resample when Neff < resampleThreshold · particles
    # omninav additions (no gmapping equivalent)
    search_window: float = 0.2         # m: half-width of the correlative search (0: refinement only)
    search_angle: float = 0.2          # rad: half-width of its angular search
    search_sigmas: float = 3.0         # ... widened to this many std of the odometry error (srr..stt)
    search_below: float = 0.5          # run the search when refinement scores below this
    # the matcher's pull towards the odometry's pose, per m and per rad (Cartographer's names; 0: none).
    # For good odometry: the mapping in the simulator uses 10 / 40, MIT CSAIL's odometry fails with them
    translation_weight: float = 0.0
    rotation_weight: float = 0.0
    l_occ: float = 0.85                # log-odds added to a hit cell
    l_free: float = -0.4               # log-odds added to a cell a beam passes through
    l_max: float = 5.0                 # log-odds clamp
    laser_x: float = 0.0               # m, m, rad: the laser's pose in the robot frame
    laser_y: float = 0.0
    laser_yaw: float = 0.0
    seed: int = 0                      # of the filter's random generator

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        if self.particles < 1:
            raise ValueError(f"particles must be at least 1, got {self.particles}")
        if self.delta <= 0:
            raise ValueError(f"delta must be positive, got {self.delta}")
        if self.xmax <= self.xmin or self.ymax <= self.ymin:
            raise ValueError("the map extent needs xmin < xmax and ymin < ymax")
        if self.maxUrange <= 0 or (self.maxRange is not None and self.maxRange <= 0):
            raise ValueError("maxUrange and maxRange must be positive")
        if self.lskip < 0 or self.kernelSize < 0 or self.iterations < 0:
            raise ValueError("lskip, kernelSize and iterations must be ≥ 0")
        for name in ("sigma", "lsigma", "ogain", "lstep", "astep"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("srr", "srt", "str", "stt", "linearUpdate", "angularUpdate", "search_window", "search_angle",
                     "search_sigmas", "translation_weight", "rotation_weight"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be ≥ 0, got {getattr(self, name)}")
        if not 0 <= self.resampleThreshold <= 1:
            raise ValueError(f"resampleThreshold must be in [0, 1], got {self.resampleThreshold}")
        if not 0 < self.occ_thresh < 1:
            raise ValueError(f"occ_thresh must be in (0, 1), got {self.occ_thresh}")
        if not (self.l_occ > 0 > self.l_free and self.l_max > 0):
            raise ValueError("need l_occ > 0 > l_free and l_max > 0")
