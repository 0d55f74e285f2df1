"""The pedestrian core (sim/people): people walk, stop, wait, walk in groups, avoid each other, the walls
and (unless distracted) the robot, queue at a door, come in flows that are the same for the same seed,
and walk as fast as Weidmann's crowds do at each density."""
from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from omninav.sim.people.fundamental import corridor_speed, weidmann_speed
from omninav.sim.people.plans import Area, Crowd, Flow, PeopleSpec, Walker
from omninav.sim.people.social_force import Obstacles, PeopleParams, RobotShape, accelerations
from omninav.sim.people.spec import people_from_mapping
from omninav.sim.world import WorldError, _Keys, wall_rectangle

DT = 0.02
PARAMS = PeopleParams()
NO_GROUPS = dataclasses.replace(PARAMS, gaze_strength=0.0, attraction=0.0, group_repulsion=0.0)
# the mecanum robot's footprint, 0.832 m x 0.636 m, standing at (6, 0)
ROBOT = RobotShape(np.array([[0.416, 0.318], [-0.416, 0.318], [-0.416, -0.318], [0.416, -0.318]]) + (6.0, 0.0))


def walker(path, **kw) -> Walker:
    """A Walker; speed and radius may be one number."""
    path = np.asarray(path, np.float64)
    kw.update({key: (kw[key], kw[key]) for key in ("speed", "radius") if isinstance(kw.get(key), float)})
    return Walker(path=path, waits=np.asarray(kw.pop("waits", np.zeros(len(path))), np.float64), **kw)


def run(spec: PeopleSpec, seconds: float, obstacles=Obstacles(), robot=None, params=PARAMS):
    """Positions (T, N, 2), velocities (T, N, 2) and active masks (T, N) after each step, and the crowd."""
    crowd = Crowd(spec, params)
    positions, velocities, active = [], [], []
    for k in range(round(seconds / DT)):
        crowd.step(k * DT, DT, obstacles, robot)
        positions.append(crowd.state.position.copy())
        velocities.append(crowd.state.velocity.copy())
        active.append(crowd.state.active.copy())
    return np.array(positions), np.array(velocities), np.array(active), crowd


def solids_obstacles(*walls) -> Obstacles:
    """Walls [x1, y1, x2, y2] as the world builds them (0.1 m thick), as their counter-clockwise edges."""
    solids = np.array([wall_rectangle(*w) for w in walls])
    return Obstacles(segments=np.concatenate([solids, np.roll(solids, -1, axis=1)], axis=2).reshape(-1, 4))


def wall_gap(points: np.ndarray, radius: np.ndarray, obstacles: Obstacles) -> np.ndarray:
    """Distance from each body's edge to the nearest wall face (negative: overlapping it)."""
    seg = obstacles.segments
    a, b = seg[None, :, :2], seg[None, :, 2:]
    ab = b - a
    t = np.clip(((points[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    return np.hypot(*(points[:, None] - (a + t[..., None] * ab)).transpose(2, 0, 1)).min(axis=1) - radius


def outline_gap(points: np.ndarray, radius: float, outline: np.ndarray) -> np.ndarray:
    """Distance from bodies' edges to a convex outline (negative inside or overlapping)."""
    a, b = outline, np.roll(outline, -1, axis=0)
    ab = b - a
    t = np.clip(((points[:, None] - a[None]) * ab[None]).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    d = np.hypot(*(points[:, None] - (a[None] + t[..., None] * ab[None])).transpose(2, 0, 1)).min(axis=1)
    inside = (((points[:, None] - a[None]) * np.stack([ab[:, 1], -ab[:, 0]], -1)[None]).sum(-1) <= 0).all(axis=1)
    return np.where(inside, -d, d) - radius


def test_a_lone_walker_accelerates_stops_to_wait_and_goes_on():
    spec = PeopleSpec(walkers=(walker([[0, 0], [10, 0], [20, 0]], waits=[0, 5.0, 0], speed=1.3),))
    pos, vel, active, _ = run(spec, 26.0)
    speed = np.hypot(*vel[:, 0].T)
    t = np.arange(len(speed)) * DT + DT
    assert speed[t < 0.3].max() < 0.8                      # it accelerates, no jump to full speed
    assert abs(speed[(t > 3) & (t < 6)].mean() - 1.3) < 0.02
    standing = (speed < 0.2) & (np.abs(pos[:, 0, 0] - 10.0) < 0.8) & active[:, 0]
    assert 5.0 <= standing.sum() * DT < 5.5                # stands there for its wait
    assert speed.max() <= 1.3 * PARAMS.max_speed_factor + 1e-9
    assert not active[-1, 0]                               # went on to the end and left
    assert pos[-1, 0, 0] > 19.0


def test_two_people_head_on_pass_each_other_without_touching():
    for offset in (0.0, 0.2):
        spec = PeopleSpec(walkers=(walker([[0, 0], [12, 0]], speed=1.3, radius=0.25),
                                   walker([[12, offset], [0, offset]], speed=1.3, radius=0.25)))
        pos, _, active, crowd = run(spec, 14.0)
        both = active.all(axis=1)
        gaps = np.hypot(*(pos[both, 0] - pos[both, 1]).T) - 0.5
        assert gaps.min() > 0.0, offset
        assert crowd.left == 2, offset                     # neither got stuck


@pytest.mark.parametrize("size", [2, 3, 4])
def test_a_group_walks_abreast(size):
    # lined up abreast at the start, the turn puts them in single file; the group's own forces bring
    # them abreast again, across the new walking direction (+y)
    spec = PeopleSpec(walkers=(walker([[0, 0], [6, 0], [6, 40]], group=size, speed=1.2),))
    for params, abreast in ((PARAMS, True), (NO_GROUPS, False)):
        pos, _, active, _ = run(spec, 25.0, params=params)
        late = pos[-1, active[-1]]
        along, across = np.ptp(late[:, 1]), np.ptp(late[:, 0])
        assert (across > 0.5 * (size - 1) and along < 0.3 * across) == abreast, (params, along, across)
        if abreast:
            gaps = np.hypot(*(late[:, None] - late[None]).transpose(2, 0, 1))[np.triu_indices(size, 1)]
            assert gaps.min() > 0.45 and np.sort(gaps)[size - 2] < 1.0    # side by side, not far apart


def test_a_waypoint_walked_past_is_not_walked_back_to():
    # the route's middle point is inside a pillar: nobody gets within reach of it, but walking past
    # it along the leg counts, so the person goes on instead of pressing against the pillar
    pillar = Obstacles(circles=np.array([[5.0, 0.0, 0.6]]))
    pos, _, active, crowd = run(PeopleSpec(walkers=(walker([[0, 0.1], [5, 0], [10, 0]], speed=1.3),)), 15.0, pillar)
    assert crowd.left == 1
    assert np.hypot(*(pos[active[:, 0], 0] - (5.0, 0.0)).T).min() > 0.6


def test_people_keep_off_walls():
    # a corridor 1.2 m wide whose route runs 0.2 m from the lower wall: the person walks off its line
    walls = solids_obstacles([0, 0, 20, 0], [0, 1.2, 20, 1.2])
    spec = PeopleSpec(walkers=(walker([[1, 0.6], [3, 0.25], [19, 0.25]], speed=1.3, radius=0.25),))
    for params, keeps_off in ((PARAMS, True), (dataclasses.replace(PARAMS, wall_strength=0.0), False)):
        pos, _, active, _ = run(spec, 16.0, walls, params=params)
        gaps = wall_gap(pos[active[:, 0], 0], np.array([0.25]), walls)
        assert (gaps.min() > 0.0) == keeps_off


def test_a_crowd_queues_at_a_one_metre_door():
    # a wall across a 10 m x 8 m hall at x = 5 with a door 1 m clear between y = 3.5 and 4.5; people
    # arrive at 4 a second, more than a door lets through
    walls = solids_obstacles([5, 0, 5, 3.45], [5, 4.55, 5, 8], [0, 0, 10, 0], [0, 8, 10, 8])
    flow = Flow(source=Area((1.5, 4.0), (2.0, 6.0)), goal=Area((9.0, 4.0), (0.5, 4.0)), via=np.array([[5.0, 4.0]]),
                rate_per_min=240.0, stop_s=20.0)
    pos, _, active, crowd = run(PeopleSpec(seed=1, flows=(flow,)), 30.0, walls)
    crossing = (active[1:] & active[:-1] & (pos[:-1, :, 0] < 5.0) & (pos[1:, :, 0] >= 5.0)).sum(axis=1)
    window = round(5.0 / DT)
    rates = crossing[:len(crossing) // window * window].reshape(-1, window).sum(axis=1) / 5.0
    waiting = ((pos[..., 0] < 5.0) & (pos[..., 0] > 3.0) & active).sum(axis=1)
    assert waiting.max() >= 10                              # a queue before the door
    # through a 1 m door at most 1.3 people/s per metre of its width less 0.15 m at each jamb (SFPE)
    assert 0.5 < rates.max() <= 1.6
    assert crowd.queued > 0                                 # and back to the source
    radius = crowd.state.radius
    for k in range(0, len(pos), 5):
        assert wall_gap(pos[k, active[k]], radius[active[k]], walls).min(initial=1.0) > -0.05


def test_a_reactive_person_swerves_round_the_robot_a_distracted_one_walks_into_it():
    for offset in (0.0, 0.15):
        for distracted in (False, True):
            spec = PeopleSpec(walkers=(walker([[0, offset], [12, offset]], speed=1.3, radius=0.25,
                                              distracted=distracted),))
            pos, _, active, crowd = run(spec, 12.0, robot=ROBOT)
            gap = outline_gap(pos[active[:, 0], 0], 0.25, ROBOT.outline).min()
            assert (gap < 0.0) == distracted, (offset, distracted, gap)
            assert crowd.left == 1                          # the reactive one got round


def test_flows_are_the_same_for_the_same_seed_and_walk_at_their_speeds():
    flows = (Flow(source=Area((1.0, 5.0), (1.0, 4.0)), goal=Area((19.0, 5.0), (1.0, 4.0)), rate_per_min=40.0,
                  groups=(0.5, 0.3, 0.1, 0.1), distracted=0.3),
             Flow(source=Area((19.0, 2.0), (1.0, 2.0)), goal=Area((1.0, 8.0), (1.0, 2.0)), rate_per_min=20.0,
                  via=np.array([[10.0, 5.0]]), regular=True))
    walls = solids_obstacles([0, 0, 20, 0], [20, 0, 20, 10], [20, 10, 0, 10], [0, 10, 0, 0])
    first = run(PeopleSpec(seed=3, flows=flows), 20.0, walls)
    again = run(PeopleSpec(seed=3, flows=flows), 20.0, walls)
    other = run(PeopleSpec(seed=4, flows=flows), 20.0, walls)
    assert np.array_equal(first[0], again[0]) and np.array_equal(first[2], again[2])
    assert not np.array_equal(first[0], other[0])
    crowd = first[3]
    assert crowd.spawned >= 10
    seen = first[2].any(axis=0)
    assert (crowd.state.v0[seen] >= 1.0).all() and (crowd.state.v0[seen] <= 1.5).all()
    assert len(np.unique(crowd.state.v0[seen])) > 3          # drawn, not one speed for all
    assert (~crowd.state.reactive[seen]).any() and crowd.state.reactive[seen].any()
    speeds = np.hypot(*first[1].transpose(2, 0, 1))
    assert speeds.max() <= 1.5 * PARAMS.max_speed_factor + 1e-9


def test_nobody_appears_on_top_of_someone_at_a_crowded_source():
    flow = Flow(source=Area((2.0, 2.0), (0.5, 0.5)), goal=Area((10.0, 2.0)), rate_per_min=300.0, stop_s=5.0)
    pos, _, active, crowd = run(PeopleSpec(flows=(flow,)), 6.0)
    assert crowd.queued > 0                                   # some wait at the source for room
    r = crowd.state.radius
    for k in range(len(pos)):
        on = np.flatnonzero(active[k])
        gaps = np.hypot(*(pos[k, on][:, None] - pos[k, on][None]).transpose(2, 0, 1)) - r[on][:, None] - r[on][None]
        assert gaps[np.triu_indices(len(on), 1)].min(initial=1.0) > -0.05


@pytest.mark.parametrize("density", [0.5, 1.5, 2.5])
def test_speed_at_a_density_is_weidmanns(density):
    measured = corridor_speed(density, PARAMS, seed=0, warm_s=10.0, measure_s=10.0)
    assert abs(measured - weidmann_speed(density)) < 0.15


def test_crowding_slows_people():
    """Without the interaction between people the speed at a density would be the free speed."""
    free = dataclasses.replace(PARAMS, social_strength=0.0, near_strength=0.0, anticipation_strength=0.0)
    assert corridor_speed(2.0, free, warm_s=5.0, measure_s=5.0) - weidmann_speed(2.0) > 0.5


def test_accelerations_are_zero_for_empty_slots_and_pure():
    spec = PeopleSpec(walkers=(walker([[0, 0], [5, 0]]), walker([[5, 0.1], [0, 0.1]])), max_people=4)
    crowd = Crowd(spec, PARAMS)
    crowd.update(0.0)
    before = {name: np.copy(getattr(crowd.state, name)) for name in ("position", "velocity", "target", "speed")}
    first = accelerations(crowd.state, Obstacles(), ROBOT, PARAMS)
    assert np.array_equal(first, accelerations(crowd.state, Obstacles(), ROBOT, PARAMS))
    assert not first[2:].any() and first[:2].any()
    assert all(np.array_equal(getattr(crowd.state, name), value) for name, value in before.items())


# ---------------------------------------------------------------- the world file's people: key

def test_the_people_key_reads_walkers_and_flows():
    spec = people_from_mapping({
        "seed": 3,
        "walkers": [{"path": [[1, 1], [5, 1]], "waits": {1: 4.0}, "loop": True, "group": 2, "speed": 1.3,
                     "radius": [0.2, 0.25], "distracted": True, "start_s": 2.0}],
        "flows": [{"source": {"center": [1, 1], "size": [1, 2]}, "goal": {"center": [9, 1]}, "via": [[5, 2]],
                   "rate_per_min": 12, "arrivals": "regular", "start_s": 1, "stop_s": 60,
                   "groups": {1: 0.6, 2: 0.3, 3: 0.1}, "distracted": 0.2, "speed": [1.1, 1.4]}],
    }, _Keys("w.yaml"))
    (w,), (f,) = spec.walkers, spec.flows
    assert spec.seed == 3 and w.loop and w.group == 2 and w.speed == (1.3, 1.3) and w.distracted
    assert list(w.waits) == [0.0, 4.0] and w.start_s == 2.0
    assert f.regular and f.groups == (0.6, 0.3, 0.1) and f.stop_s == 60 and f.goal.size == (0.0, 0.0)
    assert spec.capacity >= 2 + 3


@pytest.mark.parametrize("people, where", [
    ({"walkers": [{"path": []}]}, "people.walkers[0].path"),
    ({"walkers": [{"path": [[0, 0]], "group": 5}]}, "people.walkers[0].group"),
    ({"walkers": [{"path": [[0, 0]], "waits": {3: 1.0}}]}, "people.walkers[0].waits"),
    ({"walkers": [{"path": [[0, 0]], "speed": [1.5, 1.0]}]}, "people.walkers[0].speed"),
    ({"walkers": [{"path": [[0, 0]], "pace": 1.0}]}, "people.walkers[0]"),
    ({"flows": [{"source": {"center": [0, 0]}, "goal": {"center": [1, 1]}}]}, "people.flows[0].rate_per_min"),
    ({"flows": [{"source": {"center": [0, 0]}, "goal": {"center": [1, 1]}, "rate_per_min": 5,
                 "groups": {1: 0.0}}]}, "people.flows[0].groups"),
    ({"flows": [{"source": {"center": [0, 0]}, "goal": {"center": [1, 1]}, "rate_per_min": 5,
                 "distracted": 1.5}]}, "people.flows[0].distracted"),
    ({"flows": [{"source": {"center": [0, 0]}, "goal": {"center": [1, 1]}, "rate_per_min": 5,
                 "arrivals": "bursty"}]}, "people.flows[0].arrivals"),
    ({"max_people": 1, "walkers": [{"path": [[0, 0]], "group": 3}]}, "people.max_people"),
])
def test_a_bad_people_key_names_the_file_and_the_key(people, where):
    with pytest.raises(WorldError, match=rf"^w\.yaml: {re.escape(where)}: "):
        people_from_mapping(people, _Keys("w.yaml"))


def test_capacity_holds_what_a_flow_brings():
    flow = Flow(source=Area((0.0, 0.0)), goal=Area((30.0, 0.0)), rate_per_min=60.0)
    assert PeopleSpec(flows=(flow,)).capacity >= 30          # one a second for 30 s of walking at 1 m/s
    assert PeopleSpec(flows=(flow,), max_people=7).capacity == 7
    assert math.isinf(flow.stop_s)
