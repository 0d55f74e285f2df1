"""The SLAM core's parameters: gmapping's names and defaults (ROS slam_gmapping) where it has one."""
from __future__ import annotations

from dataclasses import dataclass

from ...parameters.declare import Parameters, Rule, param

MODES = ("rbpf", "scan_matching")


@dataclass(frozen=True)
class SlamParams(Parameters):
    mode: str = param("rbpf", choices=MODES)           # rbpf | scan_matching (one pose, no motion noise: hector-like)
    particles: int = param(30, ge=1)
    # the map
    delta: float = param(0.05, gt=0)                   # m per cell
    xmin: float = -100.0                               # m: the map's extent (tiles are allocated only where seen)
    ymin: float = -100.0
    xmax: float = 100.0
    ymax: float = 100.0
    # gmapping's 0.25 is a threshold on its hit ratio (hits / beams through a cell); on a
    # log-odds cell, one pass of a beam already gives 0.4, so map_server's 0.65 is used instead
    occ_thresh: float = param(0.65, gt=0, lt=1)        # occupancy probability above which a published cell is occupied
    # the laser
    maxUrange: float = param(80.0, gt=0)               # m: beams are cut here; longer ones only clear free space
    maxRange: float | None = param(None, gt=0)         # m: beams at or beyond are dropped (None: the scan's range_max − 1 cm)
    lskip: int = param(0, ge=0)                        # use every (lskip+1)-th beam for matching and weighting
    # the scan matcher
    sigma: float = param(0.05, gt=0)                   # m: width of the matching field around occupied cells
    kernelSize: int = param(1, ge=0)                   # cells: how far from an endpoint an occupied cell is looked for
    lstep: float = param(0.05, gt=0)                   # m: linear step of the correlative search
    astep: float = param(0.05, gt=0)                   # rad: angular step of the correlative search
    iterations: int = param(5, ge=0)                   # refinement iterations (Gauss-Newton)
    lsigma: float = param(0.075, gt=0)                 # m: beam likelihood width, for the particle weights
    ogain: float = param(3.0, gt=0)                    # divides the log-likelihood before normalising (smooths resampling)
    minimumScore: float = 0.0                          # below this matching score the odometry guess is kept
    # motion model: odometry noise (gmapping: translation/rotation as a function of translation/rotation)
    srr: float = param(0.1, ge=0)                      # m/m
    srt: float = param(0.2, ge=0)                      # m/rad
    str: float = param(0.1, ge=0)                      # rad/m
    stt: float = param(0.2, ge=0)                      # rad/rad
    # when to process a scan
    linearUpdate: float = param(1.0, ge=0)             # m driven
    angularUpdate: float = param(0.5, ge=0)            # rad turned
    temporalUpdate: float = -1.0                       # s since the last update (≤ 0: never by time alone)
    resampleThreshold: float = param(0.5, ge=0, le=1)  # resample when Neff < resampleThreshold · particles
    # omninav additions (no gmapping equivalent)
    search_window: float = param(0.2, ge=0)            # m: half-width of the correlative search (0: refinement only)
    search_angle: float = param(0.2, ge=0)             # rad: half-width of its angular search
    search_sigmas: float = param(3.0, ge=0)            # ... widened to this many std of the odometry error (srr..stt)
    search_below: float = 0.5                          # run the search when refinement scores below this
    # the matcher's pull towards the odometry's pose, per m and per rad (Cartographer's names; 0: none).
    # For good odometry: the mapping in the simulator uses 10 / 40, MIT CSAIL's odometry fails with them
    translation_weight: float = param(0.0, ge=0)
    rotation_weight: float = param(0.0, ge=0)
    l_occ: float = param(0.85, gt=0)                   # log-odds added to a hit cell
    l_free: float = param(-0.4, lt=0)                  # log-odds added to a cell a beam passes through
    l_max: float = param(5.0, gt=0)                    # log-odds clamp
    laser_x: float = 0.0                               # m, m, rad: the laser's pose in the robot frame
    laser_y: float = 0.0
    laser_yaw: float = 0.0
    seed: int = 0                                      # of the filter's random generator

    rules = (Rule("xmax", lambda p: p.xmax > p.xmin, "> xmin ({p.xmin})"),
             Rule("ymax", lambda p: p.ymax > p.ymin, "> ymin ({p.ymin})"))
