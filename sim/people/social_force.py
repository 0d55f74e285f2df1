"""The social force model of pedestrian motion: what accelerates each person, for a caller to integrate.

Every active person i is a disc of radius r_i that wants to walk towards its target at its desired
speed, and its acceleration is the sum of (all per unit mass; docs/people.md gives the sources):
  - driving: (speed_i e_i − v_i)/τ, e_i the unit vector to the target (Helbing & Molnár 1995);
  - other people j, along n_ij (from j to i), d_ij the centre distance, r_ij = r_i + r_j:
    A¹ exp((r_ij − d_ij)/B¹) w(φ) + A² exp((r_ij − d_ij)/B²), w(φ) = λ + (1 − λ)(1 + cos φ)/2 with φ
    the angle between e_i and the direction to j — the circular specification with anisotropy
    (Helbing & Johansson 2009): the first term, tuned on Weidmann's diagram, is what slows a crowd
    (more from ahead than from behind), the second (Helbing et al. 2005) keeps bodies apart;
  - anticipation of each one closing in (Karamouzas, Skinner & Guy 2014): the gradient of the energy
    k τ⁻² exp(−τ/τ0) of the time τ until the two would touch, which points along where they would
    touch, so a person swerves early from someone coming the other way, a pillar or the robot —
    distance-based forces alone react only at arm's length, and two people head-on stood nose to
    nose; a sidestep to the right in proportion to the braking settles who goes which way;
  - on contact (g = r_ij − d_ij > 0) the body force k g n_ij and sliding friction κ g Δv^t_ji t_ij
    divided by the mass (Helbing, Farkas & Vicsek 2000);
  - walls and static circles: A_w exp((r_i − d_iW)/B_w) from the nearest point plus the same contact
    forces; a wall segment acts only on its outer side (segments are edges of counter-clockwise
    solids, as World.segments gives them), so a thin wall is felt once, not from its far face too;
  - the robot, to a reactive person only, as another pedestrian: its outline (a polygon at its
    pose) is the other body's surface, and the disc round it moving at its velocity is what the
    person anticipates; a distracted person feels nothing of it here (the simulator still collides
    the bodies);
  - its group (Moussaïd et al. 2010), instead of the personal distance kept from strangers: members
    closer than `group_gap` push apart (β3), one farther than (n − 1)/2 m from the group's centre is
    drawn to it (β2), and one who must turn its head more than `vision_angle` away from its walking
    direction to see the centre slows down (−β1 α v_i): the one ahead waits, so a group walks abreast.

`accelerations` is pure; `integrate` is a plain semi-implicit Euler step with the speed cap
(|v| ≤ max_speed_factor · v0) for using the model without the simulator (tests, the Weidmann check).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numba import njit

from ...parameters.declare import Parameters, param


@dataclass(frozen=True)
class PeopleParams(Parameters):
    """The social force model's parameters, and how people follow their plans (docs/people.md)."""
    mass: float = param(70.0, gt=0)                     # kg, of every person
    relaxation_time: float = param(0.5, gt=0)           # s, τ (Helbing, Farkas & Vicsek 2000)
    max_speed_factor: float = param(1.3, ge=1)          # a person never walks faster than this × its v0 (H&M 1995)
    # A¹, B¹ and λ tuned on Weidmann's diagram (docs/people.md) from Johansson, Helbing & Shukla 2007's
    # circular fit (0.42 m/s², 1.65 m, 0.12), whose long range stopped a crowd at 2.5 people/m²
    social_strength: float = param(1.5, ge=0)           # m/s², A¹
    social_range: float = param(0.46, gt=0)             # m, B¹
    anisotropy: float = param(0.2, ge=0, le=1)          # λ: weight of what is behind
    near_strength: float = param(3.0, ge=0)             # m/s², A² (Helbing, Buzna, Johansson & Werner 2005)
    near_range: float = param(0.2, gt=0)                # m, B² (same)
    wall_strength: float = param(5.0, ge=0)             # m/s², A_w (same)
    wall_range: float = param(0.1, gt=0)                # m, B_w (same)
    body_stiffness: float = param(1.2e5, ge=0)          # kg/s², k (Helbing, Farkas & Vicsek 2000)
    sliding_friction: float = param(2.4e5, ge=0)        # kg/(m s), κ (same)
    gaze_strength: float = param(4.0, ge=0)             # β1 (Moussaïd et al. 2010)
    vision_angle: float = param(math.pi / 2, gt=0, le=math.pi)   # rad, half the field of view (same)
    attraction: float = param(3.0, ge=0)                # m/s², β2 (same)
    group_repulsion: float = param(1.0, ge=0)           # m/s², β3 (same)
    group_gap: float = param(0.3, ge=0)                 # m between bodies below which members push apart
    anticipation_strength: float = param(1.5, ge=0)     # m²/s², k (Karamouzas, Skinner & Guy 2014)
    anticipation_time: float = param(3.0, gt=0)         # s, τ0 (same)
    anticipation_max: float = param(5.0, gt=0)          # m/s², the most one encounter makes a person swerve or brake
    right_preference: float = param(0.3, ge=0)          # sideways to the right per unit of braking for someone ahead
    sensing_range: float = param(10.0, gt=0)            # m: people farther apart ignore each other (the cost is N²)
    stop_deceleration: float = param(0.6, gt=0)         # m/s², how a person slows towards where it will stand
    waypoint_reach: float = param(0.5, gt=0)            # m from a waypoint (plus a group's spread) that counts as there


@dataclass
class State:
    """The people as the model sees them: fixed-size arrays, a person in slot i while active[i]."""
    position: np.ndarray     # (N, 2) m
    velocity: np.ndarray     # (N, 2) m/s
    radius: np.ndarray       # (N,) m
    v0: np.ndarray           # (N,) m/s, the person's own walking speed (the cap is a multiple of it)
    speed: np.ndarray        # (N,) m/s, desired speed now: v0, less when stopping, 0 while waiting
    target: np.ndarray       # (N, 2) where the person walks to
    group: np.ndarray        # (N,) int, the same number for members of one group; −1 alone
    reactive: np.ndarray     # (N,) bool: avoids the robot (False: distracted)
    active: np.ndarray       # (N,) bool

    @classmethod
    def empty(cls, n: int) -> State:
        return cls(position=np.zeros((n, 2)), velocity=np.zeros((n, 2)), radius=np.full(n, 0.25),
                   v0=np.zeros(n), speed=np.zeros(n), target=np.zeros((n, 2)), group=np.full(n, -1, np.int64),
                   reactive=np.ones(n, bool), active=np.zeros(n, bool))

    def __len__(self) -> int:
        return len(self.active)


@dataclass(frozen=True)
class Obstacles:
    """Static geometry: segments (S, 4) x1 y1 x2 y2, edges of counter-clockwise solids (a segment acts
    on its right-hand side), and circles (C, 3) x y r."""
    segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    circles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass(frozen=True)
class RobotShape:
    """The robot as people see it: its outline (P, 2) at its pose in the world frame, counter-clockwise,
    and its velocity (2,) in the world frame."""
    outline: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))


_NO_ROBOT = RobotShape(np.zeros((0, 2)))


# where each constant sits in the array the kernel takes (numba reads module-level ints as constants)
(INV_TAU, SOCIAL_A, SOCIAL_B, LAMBDA, NEAR_A, NEAR_B, WALL_A, WALL_B, STIFFNESS, FRICTION, GAZE, VISION, ATTRACT,
 GROUP_PUSH, GROUP_GAP, ANTICIPATE_K, ANTICIPATE_T, ANTICIPATE_MAX, RIGHT, SENSING) = range(20)
REACH = 10.0         # ranges (B) beyond which an exponential force is left out: exp(−10) of its strength


@lru_cache(maxsize=8)
def _coefficients(params: PeopleParams) -> np.ndarray:
    """The kernel's constants in one array (numba takes one array faster than twenty floats)."""
    p = params
    return np.array([1.0 / p.relaxation_time, p.social_strength, p.social_range, p.anisotropy, p.near_strength,
                     p.near_range, p.wall_strength, p.wall_range, p.body_stiffness / p.mass,
                     p.sliding_friction / p.mass, p.gaze_strength, p.vision_angle, p.attraction,
                     p.group_repulsion, p.group_gap, p.anticipation_strength, p.anticipation_time,
                     p.anticipation_max, p.right_preference, p.sensing_range])


def accelerations(state: State, obstacles: Obstacles, robot: RobotShape | None, params: PeopleParams) -> np.ndarray:
    """Every person's acceleration (N, 2), m/s²; zero for inactive slots."""
    robot = robot if robot is not None else _NO_ROBOT
    out = np.zeros((len(state), 2))
    _accelerations(state.position, state.velocity, state.radius, state.speed, state.target, state.group,
                   state.reactive, state.active, np.ascontiguousarray(obstacles.segments, np.float64),
                   np.ascontiguousarray(obstacles.circles, np.float64),
                   np.ascontiguousarray(robot.outline, np.float64), np.asarray(robot.velocity, np.float64),
                   _coefficients(params), out)
    return out


def cap_speed(velocity: np.ndarray, v0: np.ndarray, params: PeopleParams) -> np.ndarray:
    """The velocities (N, 2) shortened to at most max_speed_factor · v0 each."""
    limit = params.max_speed_factor * v0
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    scale = np.where(speed > limit, limit / np.maximum(speed, 1e-12), 1.0)
    return velocity * scale[:, None]


def integrate(state: State, acceleration: np.ndarray, dt: float, params: PeopleParams) -> None:
    """Advance the active people by dt in place: velocity first, capped, then position (semi-implicit
    Euler, stable for the contact stiffness at dt ≤ 0.02 s)."""
    a = state.active
    state.velocity[a] = cap_speed(state.velocity[a] + acceleration[a] * dt, state.v0[a], params)
    state.position[a] += state.velocity[a] * dt


@njit(cache=True)
def _contact(g, nx, ny, dvx, dvy, k, kappa):
    """Body force and sliding friction (per unit mass) of an overlap g along n, Δv the other's
    velocity less one's own."""
    tx, ty = -ny, nx
    slide = kappa * g * (dvx * tx + dvy * ty)
    return k * g * nx + slide * tx, k * g * ny + slide * ty


@njit(cache=True)
def _weight(nx, ny, ex, ey, c):
    """How much a body in direction −n counts for someone walking along e: 1 straight ahead, λ behind
    (zero e, standing: all around alike)."""
    if ex == 0.0 and ey == 0.0:
        return 1.0
    return c[LAMBDA] + (1.0 - c[LAMBDA]) * 0.5 * (1.0 - (nx * ex + ny * ey))


@njit(cache=True)
def _social(gap, nx, ny, ex, ey, c):
    """Repulsion (per unit mass) from a body `gap` m away (negative: overlapping) in direction −n,
    for someone walking along e."""
    f = c[SOCIAL_A] * math.exp(-gap / c[SOCIAL_B]) * _weight(nx, ny, ex, ey, c) + c[NEAR_A] * math.exp(-gap / c[NEAR_B])
    return f * nx, f * ny


@njit(cache=True)
def _anticipation(xx, xy, vx, vy, r, c):
    """Evasion (per unit mass) of a body at relative position x (from it to oneself) and relative
    velocity v (one's own less its) that one would touch, combined radius r, in τ seconds: the
    gradient of k τ⁻² exp(−τ/τ0) (Karamouzas, Skinner & Guy 2014), along where the contact would be
    — sideways for a near miss — capped at anticipation_max. The same for both of a pair, opposite."""
    a = vx * vx + vy * vy
    b = -(xx * vx + xy * vy)
    gap2 = xx * xx + xy * xy - r * r
    if a < 1e-12 or b <= 0.0 or gap2 <= 0.0:
        return 0.0, 0.0                   # not closing in, or touching already (the body force acts)
    disc = b * b - a * gap2
    if disc <= 0.0:
        return 0.0, 0.0                   # passes clear
    root = math.sqrt(disc)
    tau = (b - root) / a
    t0 = c[ANTICIPATE_T]
    f = c[ANTICIPATE_K] * math.exp(-tau / t0) * (2.0 / tau + 1.0 / t0) / (tau * tau * root)
    fx, fy = f * (xx + tau * vx), f * (xy + tau * vy)
    size = math.sqrt(fx * fx + fy * fy)
    if size > c[ANTICIPATE_MAX]:
        fx, fy = fx * c[ANTICIPATE_MAX] / size, fy * c[ANTICIPATE_MAX] / size
    return fx, fy


@njit(cache=True)
def _sidestep(fx, fy, ex, ey, c):
    """An evasion plus a step to the right in proportion to how much it brakes someone walking along
    e, so two people exactly head-on do not stop nose to nose."""
    braking = -(fx * ex + fy * ey)
    if braking > 0.0:
        fx += c[RIGHT] * braking * ey
        fy -= c[RIGHT] * braking * ex
    return fx, fy


@njit(cache=True)
def _nearest_on_segment(px, py, ax, ay, bx, by):
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 == 0.0 else min(1.0, max(0.0, ((px - ax) * ex + (py - ay) * ey) / length2))
    return ax + t * ex, ay + t * ey


@njit(cache=True)
def _unit(dx, dy, fallback_x, fallback_y):
    d = math.sqrt(dx * dx + dy * dy)
    if d < 1e-12:
        return fallback_x, fallback_y, 0.0
    return dx / d, dy / d, d


@njit(cache=True)
def _accelerations(pos, vel, radius, speed, target, group, reactive, active, segments, circles, outline,
                   robot_vel, c, out):
    n = pos.shape[0]
    disc = disc_around(outline)
    walk = np.zeros((n, 2))                   # walking directions
    members = np.ones(n)                      # group members, and the sum of their positions
    centre = pos.copy()
    for i in range(n):
        if active[i]:
            walk[i, 0], walk[i, 1], _ = _unit(target[i, 0] - pos[i, 0], target[i, 1] - pos[i, 1], 0.0, 0.0)
            out[i, 0] = (speed[i] * walk[i, 0] - vel[i, 0]) * c[INV_TAU]
            out[i, 1] = (speed[i] * walk[i, 1] - vel[i, 1]) * c[INV_TAU]
    # each pair once: the distance terms, the contact and the time to collision are the same for both
    # of a pair (opposite), only the weights and the sidesteps differ
    for i in range(n):
        if not active[i]:
            continue
        for j in range(i + 1, n):
            if not active[j]:
                continue
            friends = group[i] >= 0 and group[j] == group[i]
            dx, dy = pos[i, 0] - pos[j, 0], pos[i, 1] - pos[j, 1]
            if not friends and dx * dx + dy * dy > c[SENSING] * c[SENSING]:
                continue
            # coincident centres: a fixed direction, so the pair still separates
            nx, ny, d = _unit(dx, dy, 1.0, 0.0)
            gap = d - radius[i] - radius[j]
            if gap < 0.0:
                fx, fy = _contact(-gap, nx, ny, vel[j, 0] - vel[i, 0], vel[j, 1] - vel[i, 1], c[STIFFNESS],
                                  c[FRICTION])
                out[i, 0] += fx
                out[i, 1] += fy
                out[j, 0] -= fx
                out[j, 1] -= fy
            if friends:
                # friends keep no personal distance from each other: the group's own terms space them
                members[i] += 1.0
                members[j] += 1.0
                centre[i, 0] += pos[j, 0]
                centre[i, 1] += pos[j, 1]
                centre[j, 0] += pos[i, 0]
                centre[j, 1] += pos[i, 1]
                if gap < c[GROUP_GAP]:
                    out[i, 0] += c[GROUP_PUSH] * nx
                    out[i, 1] += c[GROUP_PUSH] * ny
                    out[j, 0] -= c[GROUP_PUSH] * nx
                    out[j, 1] -= c[GROUP_PUSH] * ny
                continue
            fi = fj = 0.0
            if gap < REACH * max(c[SOCIAL_B], c[NEAR_B]):
                social = c[SOCIAL_A] * math.exp(-gap / c[SOCIAL_B])
                near = c[NEAR_A] * math.exp(-gap / c[NEAR_B])
                fi = social * _weight(nx, ny, walk[i, 0], walk[i, 1], c) + near
                fj = social * _weight(-nx, -ny, walk[j, 0], walk[j, 1], c) + near
            gx, gy = _anticipation(dx, dy, vel[i, 0] - vel[j, 0], vel[i, 1] - vel[j, 1], radius[i] + radius[j],
                                   c)
            hx, hy = _sidestep(gx, gy, walk[i, 0], walk[i, 1], c)
            out[i, 0] += fi * nx + hx
            out[i, 1] += fi * ny + hy
            hx, hy = _sidestep(-gx, -gy, walk[j, 0], walk[j, 1], c)
            out[j, 0] += -fj * nx + hx
            out[j, 1] += -fj * ny + hy
    for i in range(n):
        if active[i]:
            _surroundings(i, pos, vel, radius, walk, members, centre, reactive[i], segments, circles, outline,
                          robot_vel, disc, c, out)


@njit(cache=True)
def _surroundings(i, pos, vel, radius, walk, members, centre, reactive, segments, circles, outline, robot_vel, disc,
                  c, out):
    """What person i's group, the walls, the static circles and the robot do to it."""
    px, py, vx, vy, ri = pos[i, 0], pos[i, 1], vel[i, 0], vel[i, 1], radius[i]
    ex, ey = walk[i, 0], walk[i, 1]
    ax, ay = out[i, 0], out[i, 1]
    if members[i] > 1.0:
        ux, uy, dist = _unit(centre[i, 0] / members[i] - px, centre[i, 1] / members[i] - py, 0.0, 0.0)
        if dist > 0.5 * (members[i] - 1.0):
            ax += c[ATTRACT] * ux
            ay += c[ATTRACT] * uy
        v = math.sqrt(vx * vx + vy * vy)
        if v > 1e-9 and dist > 0.0:
            turn = math.acos(min(1.0, max(-1.0, (vx * ux + vy * uy) / v))) - c[VISION]
            if turn > 0.0:
                ax -= c[GAZE] * turn * vx
                ay -= c[GAZE] * turn * vy

    reach = ri + REACH * c[WALL_B]
    for s in range(segments.shape[0]):
        x1, y1, x2, y2 = segments[s, 0], segments[s, 1], segments[s, 2], segments[s, 3]
        if (px + reach < min(x1, x2) or px - reach > max(x1, x2) or py + reach < min(y1, y2)
                or py - reach > max(y1, y2)):
            continue                          # too far to be felt
        if (px - x1) * (y2 - y1) - (py - y1) * (x2 - x1) < 0.0:
            continue                          # inside the solid's half-plane: its near face acts
        qx, qy = _nearest_on_segment(px, py, x1, y1, x2, y2)
        outward_x, outward_y, _ = _unit(y2 - y1, x1 - x2, 0.0, 0.0)
        nx, ny, d = _unit(px - qx, py - qy, outward_x, outward_y)
        ax, ay = _wall(ax, ay, d - ri, nx, ny, vx, vy, c)
    for m in range(circles.shape[0]):
        nx, ny, d = _unit(px - circles[m, 0], py - circles[m, 1], 1.0, 0.0)
        ax, ay = _wall(ax, ay, d - circles[m, 2] - ri, nx, ny, vx, vy, c)
        # a pillar in one's way is walked round, not into
        fx, fy = _anticipation(px - circles[m, 0], py - circles[m, 1], vx, vy, ri + circles[m, 2], c)
        fx, fy = _sidestep(fx, fy, ex, ey, c)
        ax += fx
        ay += fy

    if reactive and outline.shape[0] >= 3:
        fx, fy = _robot(px, py, vx, vy, ri, ex, ey, outline, robot_vel, disc, c)
        ax += fx
        ay += fy
    out[i, 0] = ax
    out[i, 1] = ay


@njit(cache=True)
def _wall(ax, ay, gap, nx, ny, vx, vy, c):
    f = c[WALL_A] * math.exp(-gap / c[WALL_B])
    ax += f * nx
    ay += f * ny
    if gap < 0.0:
        fx, fy = _contact(-gap, nx, ny, -vx, -vy, c[STIFFNESS], c[FRICTION])
        ax += fx
        ay += fy
    return ax, ay


@njit(cache=True)
def _nearest_on_outline(px, py, outline):
    """The point of a polygon's boundary nearest to (px, py), and whether (px, py) is inside it."""
    best, qx, qy, inside = np.inf, px, py, False
    p = outline.shape[0]
    for e in range(p):
        x1, y1 = outline[e, 0], outline[e, 1]
        x2, y2 = outline[(e + 1) % p, 0], outline[(e + 1) % p, 1]
        sx, sy = _nearest_on_segment(px, py, x1, y1, x2, y2)
        d2 = (px - sx) ** 2 + (py - sy) ** 2
        if d2 < best:
            best, qx, qy = d2, sx, sy
        if (y1 > py) != (y2 > py) and px < x1 + (py - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return qx, qy, inside


@njit(cache=True)
def outline_distance(points, outline):
    """Distance from points (K, 2) to a polygon (P, 2), 0 inside it."""
    out = np.zeros(points.shape[0])
    for k in range(points.shape[0]):
        qx, qy, inside = _nearest_on_outline(points[k, 0], points[k, 1], outline)
        if not inside:
            out[k] = math.hypot(points[k, 0] - qx, points[k, 1] - qy)
    return out


@njit(cache=True)
def disc_around(outline):
    """(x, y, r): the circle round a polygon (P, 2) from its vertices' mean; zeros for none."""
    disc = np.zeros(3)
    p = outline.shape[0]
    if p == 0:
        return disc
    for e in range(p):
        disc[0] += outline[e, 0] / p
        disc[1] += outline[e, 1] / p
    for e in range(p):
        disc[2] = max(disc[2], math.hypot(outline[e, 0] - disc[0], outline[e, 1] - disc[1]))
    return disc


@njit(cache=True)
def _robot(px, py, vx, vy, ri, ex, ey, outline, robot_vel, disc, c):
    """The robot's push on one reactive person, as another pedestrian's: its outline is the body's
    surface, and the disc round it (x, y, r) with its velocity what the person sees coming."""
    qx, qy, inside = _nearest_on_outline(px, py, outline)
    nx, ny, d = _unit(px - qx, py - qy, 1.0, 0.0)
    if inside:
        nx, ny, d = -nx, -ny, -d
    gap = d - ri
    fx, fy = _social(gap, nx, ny, ex, ey, c)
    gx, gy = _anticipation(px - disc[0], py - disc[1], vx - robot_vel[0], vy - robot_vel[1], ri + disc[2], c)
    gx, gy = _sidestep(gx, gy, ex, ey, c)
    fx += gx
    fy += gy
    if gap < 0.0:
        gx, gy = _contact(-gap, nx, ny, robot_vel[0] - vx, robot_vel[1] - vy, c[STIFFNESS], c[FRICTION])
        fx += gx
        fy += gy
    return fx, fy


def warm_up() -> None:
    """Compile the kernels (or load them from numba's cache) before the first step."""
    state = State.empty(2)
    state.active[:] = True
    state.position[1] = (1.0, 0.0)
    state.group[:] = 0
    outline = np.array([[3.0, 0.0], [4.0, 0.0], [4.0, 1.0]])
    accelerations(state, Obstacles(np.array([[0.0, -1.0, 1.0, -1.0]]), np.array([[0.0, 2.0, 0.3]])),
                  RobotShape(outline), PeopleParams())
    outline_distance(state.position, outline)
    disc_around(outline)
