"""People in the simulator: 70 kg bodies walked by the social force model, pushing and pushed."""
import dataclasses

import numpy as np
import pytest

from omninav.services.chassis.kinematics import ChassisParams
from omninav.sim.body import GRAVITY, BodyParams
from omninav.sim.people.social_force import PeopleParams
from omninav.sim.physics import SimParams, Simulation
from omninav.sim.world import world_from_mapping

NO_NOISE = SimParams().without_noise()
BOX = ((-0.25, -0.2), (0.25, -0.2), (0.25, 0.2), (-0.25, 0.2))
WHEELS = {"wheel_radius": 0.1, "l2": 0.2, "max_wheel_speed": 20.0}
ROBOT_KG, MU = 20.0, 0.5           # kg, the floor's friction coefficient


def world(people: dict, robot_x: float = 5.0, movers: list | None = None):
    doc = {"bounds": [12.0, 6.0], "robot": {"start": [robot_x, 3.0, 0.0], "drive": "diff", "footprint": [list(p) for p in BOX]},
           "people": people}
    if movers:
        doc["movers"] = movers
    return world_from_mapping(doc, "people.yaml")


def parked(w, body: BodyParams | None = None) -> Simulation:
    sim = Simulation(w, NO_NOISE, ChassisParams(drive="diff", **WHEELS),
                     body=body or BodyParams(mass=ROBOT_KG, traction_mu=MU))
    sim.set_wheel_command(np.zeros(2))
    return sim


def walker(speed: float, distracted: bool = True, path=((1.0, 3.0), (11.0, 3.0))) -> dict:
    return {"walkers": [{"path": [list(p) for p in path], "speed": speed, "radius": 0.2, "distracted": distracted}]}


def push_speed(readings, since: int) -> float:
    """The robot's mean speed along +x over the readings after `since` (m/s)."""
    return float(np.mean([r.twist[0] for r in readings[since:]]))


@pytest.mark.parametrize("robot_kg", [10.0, 20.0])
def test_a_person_pushing_the_robot_moves_it_as_a_70kg_body_would(robot_kg):
    # a distracted person walks from behind into the parked robot's back and keeps walking: the
    # floor holds the robot back with mu m g, the person drives on with 70 kg (v0 - v) / tau, so
    # they move together at v0 - mu m_robot g tau / 70 kg (pymunk's penetration correction adds a
    # few cm/s: 0.862 for 0.850 m/s, 0.534 for 0.499)
    v0 = 1.2
    sim = parked(world(walker(v0)), body=BodyParams(mass=robot_kg, traction_mu=MU))
    readings = [sim.step() for _ in range(600)]
    touching = [i for i, r in enumerate(readings) if r.in_contact]
    assert touching and sim.collisions == 1
    tau, person = PeopleParams().relaxation_time, PeopleParams().mass
    expected = v0 - MU * robot_kg * GRAVITY * tau / person
    assert push_speed(readings, touching[0] + 100) == pytest.approx(expected, abs=0.05)
    # a mover of infinite mass (the kinematic movers of before) carries it along at its own speed
    wall = parked(world({}, movers=[{"radius": 0.2, "speed": v0, "path": [[1.0, 3.0], [11.0, 3.0]], "loop": False}]),
                  body=BodyParams(mass=robot_kg, traction_mu=MU))
    readings = [wall.step() for _ in range(600)]
    first = next(i for i, r in enumerate(readings) if r.in_contact)
    assert push_speed(readings, first + 100) == pytest.approx(v0, rel=0.02)


def test_a_robot_with_wheels_that_never_slip_is_hardly_moved_by_a_person():
    sim = parked(world(walker(1.2)), body=BodyParams(mass=ROBOT_KG))          # traction_mu 0: ideal wheels
    readings = [sim.step() for _ in range(500)]
    assert sim.collisions == 1 and abs(readings[-1].pose[0] - 5.0) < 0.05


def test_a_reactive_person_walks_round_the_robot_a_distracted_one_into_it():
    for distracted, touches in ((False, False), (True, True)):
        sim = parked(world(walker(1.3, distracted)))
        readings = [sim.step() for _ in range(1000)]
        assert (sim.collisions > 0) == touches
        farthest = max(r.mover_circles[0, 0] for r in readings if len(r.mover_circles))
        if not touches:                                   # it went on past the robot
            assert farthest > 7.0 and len(readings[-1].mover_circles) == 0    # and left at its route's end


def test_the_same_people_seed_gives_the_same_people_and_they_come_and_go():
    flow = {"flows": [{"source": {"center": [1.0, 1.5], "size": [0.5, 1.0]}, "goal": {"center": [11.0, 4.5]},
                       "rate_per_min": 30, "groups": {1: 0.5, 2: 0.5}}]}

    def run(seed):
        sim = parked(world({"seed": seed, **flow}, robot_x=6.0))
        return [r.mover_circles for r in (sim.step() for _ in range(1500))]

    first, again, other = run(1), run(1), run(2)
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    assert not all(a.shape == b.shape and np.array_equal(a, b) for a, b in zip(first, other))
    counts = [len(c) for c in first]
    assert max(counts) >= 2 and counts[0] <= max(counts)                    # people arrived
    radii = np.concatenate([c[:, 2] for c in first])
    assert radii.min() >= 0.2 and radii.max() <= 0.25


def test_people_walk_at_human_speed():
    sim = parked(world(walker(1.4, path=((1.0, 1.0), (11.0, 1.0)))))
    readings = [sim.step() for _ in range(300)]
    speed = np.hypot(*readings[-1].mover_velocities[0])
    assert speed == pytest.approx(1.4, abs=0.05)
    assert sim.collisions == 0


def test_noise_free_odometry_is_exact_with_people_about():
    # the people's bodies share the robot's Space: with no contact the robot moves as before
    sim = Simulation(world(walker(1.2, path=((1.0, 1.0), (11.0, 1.0)))), NO_NOISE,
                     ChassisParams(drive="diff", **WHEELS), body=BodyParams(mass=ROBOT_KG))
    plain = Simulation(world({}), NO_NOISE, ChassisParams(drive="diff", **WHEELS), body=BodyParams(mass=ROBOT_KG))
    for s in (sim, plain):
        s.set_wheel_command(s.kinematics.ik((0.3, 0.0, 0.2)))
    poses = [(sim.step().pose, plain.step().pose) for _ in range(200)]
    assert all(np.array_equal(a, b) for a, b in poses)
    assert sim.collisions == 0 and dataclasses.asdict(sim.params) == dataclasses.asdict(plain.params)
