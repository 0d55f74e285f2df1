"""The honest world's physics: contacts looked for in substeps, judged every substep and timed,
the robot's real body (skid steer, rollers, traction)."""
import dataclasses
import math

import numpy as np
import pytest

from omninav.services.chassis.kinematics import ChassisParams
from omninav.sim.body import GRAVITY, BodyParams
from omninav.sim.contacts import REJOIN_S, ContactLedger
from omninav.sim.physics import SimParams, Simulation
from omninav.sim.world import load_world

NO_NOISE = SimParams().without_noise()


def make_world(tmp_path, text, name="w"):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return load_world(path)


def drive(sim, schedule):
    out = []
    for steps, twist in schedule:
        sim.set_wheel_command(sim.kinematics.ik(twist))
        out += [sim.step() for _ in range(steps)]
    return out


# ---------------------------------------------------------------- contacts between steps

def graze_world(tmp_path):
    """A cylinder (r 0.075 m) reaching 2 mm over the line the mecanum robot's front-right corner
    draws when it drives diagonally (+x, +y) from (2, 2): the corner is inside the cylinder along
    3.46 cm of that line, centred 3.02 m along it — between two 20 ms steps at 2 m/s (4 cm)."""
    corner = np.array([2.0 + 0.416, 2.0 - 0.318])
    along, out = np.array([1.0, 1.0]) / math.sqrt(2), np.array([1.0, -1.0]) / math.sqrt(2)
    centre = corner + 3.02 * along + (0.075 - 0.002) * out
    return make_world(tmp_path, f"bounds: [12.0, 12.0]\ncircles: [{{center: [{centre[0]}, {centre[1]}], radius: 0.075}}]\n"
                                "robot: {start: [2.0, 2.0, 0.0]}\n")


@pytest.mark.parametrize("max_substep, touches", [(0.002, True), (0.02, False)])
def test_a_2mm_graze_at_2m_per_s_is_a_contact(tmp_path, max_substep, touches):
    world = graze_world(tmp_path)
    body = BodyParams(wheel_acc_limit=1e5)                        # at 2 m/s from the first step
    chassis = ChassisParams(max_wheel_speed=60.0)
    sim = Simulation(world, dataclasses.replace(NO_NOISE, dt=0.02, max_substep=max_substep), chassis, body=body)
    readings = drive(sim, [(120, (2.0 / math.sqrt(2), 2.0 / math.sqrt(2), 0.0))])
    assert np.hypot(*(readings[-1].pose[:2] - [2.0, 2.0])) > 4.0   # it drove past the cylinder
    assert (sim.collisions >= 1) == touches                        # one 20 ms step jumps over the graze
    assert (sim.min_clearance == 0.0) == touches


# ---------------------------------------------------------------- whose contact, and how long

STANDING_PERSON = ("bounds: [10.0, 6.0]\nrobot: {start: [2.0, 3.0, 0.0]}\n"
                   "movers: [{radius: 0.3, speed: 0.0, path: [[2.9, 3.0], [3.0, 3.0]]}]\n")


def test_creeping_at_1cm_per_s_into_a_standing_person_is_the_robots(tmp_path):
    # the robot's front (x 2.416) is 18.4 cm from the person (x 2.6); it creeps on into them
    world = make_world(tmp_path, STANDING_PERSON)
    sim = Simulation(world, NO_NOISE)
    drive(sim, [(2500, (0.01, 0.0, 0.0))])
    assert sim.collisions >= 1 and sim.robot_fault_collisions == sim.collisions
    assert sim.contacts.robot_contact_s > 5.0


def test_braking_into_a_standing_person_is_the_robots(tmp_path):
    # 0.5 m/s towards the person, then a stop command the motors follow at their limit (4.6 m/s^2
    # at the rim): the robot touches 5 steps into braking, still rolling at 9 cm/s
    world = make_world(tmp_path, STANDING_PERSON)
    sim = Simulation(world, NO_NOISE)
    readings = drive(sim, [(38, (0.5, 0.0, 0.0)), (100, (0.0, 0.0, 0.0))])
    touching = next(r for r in readings if r.in_contact)
    assert 0.0 < touching.twist[0] < 0.2 and touching.wheel_speeds[0] < readings[37].wheel_speeds[0]
    assert sim.collisions == 1 and sim.robot_fault_collisions == 1


PASSER_BY = ("bounds: [12.0, 6.0]\nrobot: {start: [5.0, 3.0, 0.0]}\n"
             "movers: [{radius: 0.4, speed: 0.8, path: [[1.0, 4.3], [4.6, 4.3], [4.6, 2.5]], loop: false}]\n")


def test_pressing_on_after_a_person_touched_first_is_the_robots(tmp_path):
    # the person walks past 0.58 m above the robot's side, then turns into it 0.73 s before
    # touching it (theirs: no way to see it coming) and pushes it; then the robot drives into
    # them while they still touch: from then on the contact is the robot's too
    world = make_world(tmp_path, PASSER_BY)
    sim = Simulation(world, NO_NOISE)
    readings = drive(sim, [(600, (0.0, 0.0, 0.0))])
    first = next(i for i, r in enumerate(readings) if r.in_contact)
    assert readings[-1].pose[1] < 3.0 - 0.1                        # pushed down out of their way
    assert sim.collisions == 1 and sim.robot_fault_collisions == 0 and readings[-1].in_contact
    drive(sim, [(50, (0.0, 0.2, 0.0))])                             # strafe up into the person
    assert sim.collisions == 1 and sim.robot_fault_collisions == 1
    assert 0 < sim.contacts.robot_contact_s <= 0.5 + 1e-9 < sim.contacts.contact_s
    assert sim.contacts.contact_s == pytest.approx((650 - first) * NO_NOISE.dt, abs=0.05)


def test_contact_seconds_last_as_long_as_the_robot_presses_on_a_wall(tmp_path):
    world = make_world(tmp_path, "bounds: [8.0, 6.0]\nwalls: [[5.0, 0.5, 5.0, 5.5]]\nrobot: {start: [4.0, 3.0, 0.0]}\n")
    sim = Simulation(world, NO_NOISE)
    readings = drive(sim, [(400, (0.3, 0.0, 0.0))])
    first = next(i for i, r in enumerate(readings) if r.in_contact)
    assert sim.collisions == 1 and sim.robot_fault_collisions == 1
    assert sim.contacts.contact_s == pytest.approx((400 - first) * NO_NOISE.dt, abs=0.02)
    assert sim.contacts.longest_s == pytest.approx(sim.contacts.contact_s)


# ---------------------------------------------------------------- the body on the floor

JACKAL_WHEELS = {"wheel_radius": 0.098, "l2": 0.187795, "max_wheel_speed": 20.4}


def test_a_skid_steer_turns_by_its_track_multiplier(tmp_path):
    world = make_world(tmp_path, "bounds: [8.0, 8.0]\nrobot: {start: [4.0, 4.0, 0.0], drive: diff}\n")
    chassis = ChassisParams(drive="diff", **JACKAL_WHEELS)
    turns = {}
    for multiplier in (1.0, 1.5):
        sim = Simulation(world, NO_NOISE, chassis, body=BodyParams(track_multiplier=multiplier))
        readings = drive(sim, [(100, (0.0, 0.0, 1.0))])
        turns[multiplier] = readings[-1].twist[2]
    assert turns[1.0] == pytest.approx(1.0, rel=1e-9)
    assert turns[1.5] == pytest.approx(1.0 / 1.5, rel=1e-9)      # wheels that turn the ideal drive at 1 rad/s


def test_mecanum_rollers_lose_part_of_a_strafe(tmp_path):
    world = make_world(tmp_path, "bounds: [8.0, 8.0]\nrobot: {start: [4.0, 4.0, 0.0]}\n")
    sim = Simulation(world, NO_NOISE, body=BodyParams(lateral_efficiency=0.8))
    twist = drive(sim, [(100, (0.3, 0.4, 0.0))])[-1].twist
    assert twist == pytest.approx([0.3, 0.32, 0.0], abs=1e-9)


def test_traction_bounds_the_bodys_acceleration_and_the_wheels_spin(tmp_path):
    world = make_world(tmp_path, "bounds: [14.0, 8.0]\nrobot: {start: [2.0, 4.0, 0.0], drive: diff}\n")
    chassis = ChassisParams(drive="diff", **JACKAL_WHEELS)
    body = BodyParams(traction_mu=0.5, wheel_acc_limit=1e4, mass=18.4, inertia=0.55)
    sim = Simulation(world, NO_NOISE, chassis, body=body)
    readings = drive(sim, [(10, (1.9, 0.0, 0.0))])
    reach = 0.5 * GRAVITY * 0.1                                            # μ g t: the floor's limit
    assert reach * 0.9 < readings[-1].twist[0] < reach                     # the mean over the last step
    assert readings[-1].wheel_speeds == pytest.approx([1.9 / 0.098] * 2)   # the wheels already at 1.9 m/s
    travelled = readings[-1].pose[0] - 2.0
    assert readings[-1].encoder_positions[0] * 0.098 > 3 * travelled       # what odometry would believe
    # the ideal body follows its wheels at once
    ideal = Simulation(world, NO_NOISE, chassis, body=dataclasses.replace(body, traction_mu=0.0))
    assert drive(ideal, [(10, (1.9, 0.0, 0.0))])[-1].twist[0] == pytest.approx(1.9)


def test_the_body_outline_is_what_the_world_touches(tmp_path):
    # a post 2.5 cm beside the footprint's side: the body's wheels, 4.3 cm wider, hit it
    world = make_world(tmp_path, "bounds: [8.0, 6.0]\ncircles: [{center: [4.0, 3.24], radius: 0.05}]\n"
                                 "robot: {start: [2.0, 3.0, 0.0], drive: diff, footprint: "
                                 "[[-0.21, -0.165], [0.21, -0.165], [0.21, 0.165], [-0.21, 0.165]]}\n")
    chassis = ChassisParams(drive="diff", **JACKAL_WHEELS)
    wide = BodyParams(outline=((-0.229, -0.208), (0.229, -0.208), (0.229, 0.208), (-0.229, 0.208)))
    for body, touches in ((BodyParams(), False), (wide, True)):
        sim = Simulation(world, NO_NOISE, chassis, body=body)
        drive(sim, [(600, (0.5, 0.0, 0.0))])
        assert (sim.collisions >= 1) == touches


def test_touching_the_same_thing_again_at_once_continues_the_contact():
    ledger = ContactLedger()
    ledger.begin(3, 1.00)
    ledger.substep({3: False}, 0.002)
    ledger.end(3, 1.002)
    ledger.begin(3, 1.05)                    # pushed off and met again: the same push
    ledger.substep({3: True}, 0.002)
    ledger.end(3, 1.052)
    assert (ledger.contacts, ledger.robot_contacts) == (1, 1)
    assert ledger.longest_s == pytest.approx(0.004)
    ledger.begin(3, 1.052 + REJOIN_S + 0.01)  # later: a new contact
    assert ledger.contacts == 2
