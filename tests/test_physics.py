"""The simulator's physics core: wheels, slip, sensors, contacts, clearance, movers, determinism."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omninav.services.chassis.follower_wheels import follower_odometry
from omninav.services.chassis.kinematics import ChassisParams
from omninav.services.chassis.odometry import wheel_odometry
from omninav.geometry.se2 import relative
from omninav.sim.body import BodyParams
from omninav.sim.physics import CONTACT_SLOP, SimParams, Simulation, occupied_rectangles, se2_log
from omninav.sim.world import YIELD_MARGIN, load_world, world_path
from omninav.geometry.polygons import point_segment_distance, points_in_polygons, transform_points

from conftest import SHARED_DATA

DT_NS = 10_000_000
NO_NOISE = SimParams().without_noise()


def make_world(tmp_path, text, name="w"):
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return load_world(path)


@pytest.fixture
def open_world(tmp_path):
    return make_world(tmp_path, "bounds: [14.0, 6.0]\nrobot: {start: [1.5, 3.0, 0.0]}\n")


@pytest.fixture
def wall_world(tmp_path):
    # a wall from y = 0.5 to 5.5 at x = 5 (0.1 m thick: its face towards the robot at x = 4.95)
    return make_world(tmp_path, "bounds: [8.0, 6.0]\nwalls: [[5.0, 0.5, 5.0, 5.5]]\n"
                                "robot: {start: [2.0, 3.0, 0.0]}\n")


def drive(sim, schedule, odometers=()):
    """Run (steps, twist) segments through the robot's IK; feed every odometer; return the readings."""
    out = []
    for steps, twist in schedule:
        sim.set_wheel_command(sim.kinematics.ik(twist))
        for _ in range(steps):
            r = sim.step()
            for odometer, field in odometers:
                odometer.update(sim.steps * DT_NS, getattr(r, field), r.gyro_z)
            out.append(r)
    return out


def odometers_for(sim):
    wheel = wheel_odometry(sim.chassis, sim.pose)
    follower = follower_odometry(sim.chassis, sim.pose)
    wheel.update(0, np.zeros(sim.kinematics.n_wheels))
    follower.update(0, np.zeros(2))
    return wheel, follower


STRAIGHT_5M = [(1000, (0.5, 0.0, 0.0)), (200, (0.0, 0.0, 0.0))]   # ramps at 60 rad/s^2: 5 m exactly


# ---------------------------------------------------------------- noise off: odometry is the truth

@pytest.mark.parametrize("drive_name", ["mecanum", "omni3", "diff"])
def test_noise_free_straight_drive_odometry_equals_truth(open_world, drive_name):
    sim = Simulation(open_world, dataclasses.replace(NO_NOISE, drive=drive_name))
    wheel, follower = odometers_for(sim)
    readings = drive(sim, STRAIGHT_5M, [(wheel, "encoder_positions"), (follower, "follower_positions")])
    truth = readings[-1].pose
    assert truth == pytest.approx([6.5, 3.0, 0.0], abs=0.01)     # 5 m along x, nothing else
    assert truth[1:] == pytest.approx([3.0, 0.0], abs=1e-12)
    # Both sides compute the same arcs from the same numbers; only rounding differs (~1e-16 per
    # step, 1200 steps, a few metres: ~1e-12). One step of lag or a chord instead of the arc would
    # already be 5e-3 m. So 1e-9 m / rad is tight and still robust.
    for odometer in (wheel, follower):
        error = relative(truth, odometer.pose)
        assert np.abs(error).max() < 1e-9
    assert sim.collisions == 0 and readings[-1].wheel_speeds == pytest.approx(0.0)


@pytest.mark.parametrize("drive_name", ["mecanum", "omni3", "diff"])
def test_noise_free_curved_drive_odometry_equals_truth(open_world, drive_name):
    sideways = 0.0 if drive_name == "diff" else 0.2
    schedule = [(300, (0.4, 0.0, 0.6)), (300, (0.3, sideways, -0.8)), (200, (0.0, 0.0, 1.0)), (100, (0, 0, 0))]
    sim = Simulation(open_world, dataclasses.replace(NO_NOISE, drive=drive_name))
    wheel, follower = odometers_for(sim)
    readings = drive(sim, schedule, [(wheel, "encoder_positions"), (follower, "follower_positions")])
    truth = readings[-1].pose
    assert np.hypot(*(truth[:2] - open_world.robot.start[:2])) > 1.0     # it really went somewhere
    for odometer in (wheel, follower):
        assert np.abs(relative(truth, odometer.pose)).max() < 1e-9
    # the true twist is the mean over each step; with no noise, FK of the motors' speeds
    for r in readings[::50]:
        assert r.twist == pytest.approx(sim.kinematics.fk(r.wheel_speeds), abs=1e-9)


def test_motors_approach_the_command_at_their_acceleration_limit(open_world):
    sim = Simulation(open_world, NO_NOISE)
    target = sim.kinematics.ik((0.5, 0.0, 0.0))
    sim.set_wheel_command(target)
    first = sim.step().wheel_speeds
    assert first == pytest.approx(np.full(4, BodyParams().wheel_acc_limit * NO_NOISE.dt))
    for _ in range(200):
        r = sim.step()
    assert r.wheel_speeds == pytest.approx(target)
    sim.set_wheel_command(np.full(4, 1e3))                     # the motors top out at max_wheel_speed
    for _ in range(300):
        r = sim.step()
    assert r.wheel_speeds == pytest.approx(np.full(4, sim.chassis.max_wheel_speed))
    with pytest.raises(ValueError, match="4 wheels"):
        sim.set_wheel_command([1.0, 2.0])
    with pytest.raises(ValueError, match="finite"):
        sim.set_wheel_command([1.0, np.nan, 0.0, 0.0])


# ---------------------------------------------------------------- noise on

def straight_run_errors(world, seed):
    sim = Simulation(world, SimParams(seed=seed))
    wheel, _ = odometers_for(sim)
    readings = drive(sim, STRAIGHT_5M, [(wheel, "encoder_positions")])
    err = relative(readings[-1].pose, wheel.pose)
    return sim, readings, float(np.hypot(err[0], err[1])), float(abs(err[2]))


def predicted_errors(params: SimParams, chassis: ChassisParams, steps: int, speed: float):
    """Standard deviations of the position and heading error of mecanum wheel odometry after a
    straight drive, from the noise parameters, plus the quantisation terms (bounded, not random).

    Per step, wheel i's increment seen by odometry differs from the one the ground saw by
    omega·dt·slip_i (slip) and the encoder's random-walk step: s = sqrt((omega·dt·σ_slip)² + σ_enc²)
    rad. Mecanum FK: vx = r/4·Σw, wz = r/(4k)·(±w...), so per step the along/across error has std
    r·s/2 and the heading error r·s/(2k). Summed over N steps: heading σ_θ = r·s·√N/(2k); the
    heading walk turns into a lateral error of speed·dt·σ_step·√(N³/3).
    """
    r, k = chassis.wheel_radius, chassis.l1 + chassis.l2
    omega = speed / r
    s = math.hypot(omega * params.dt * params.wheel_slip_std, params.encoder_noise_std)
    along = r * s * math.sqrt(steps) / 2
    heading = r * s * math.sqrt(steps) / (2 * k)
    lateral = math.hypot(along, speed * params.dt * (r * s / (2 * k)) * math.sqrt(steps ** 3 / 3))
    tick = 2 * math.pi / params.encoder_ticks_per_rev
    distance = speed * steps * params.dt
    quant_position = r * tick / 2 + distance * r * tick / (2 * k)
    quant_heading = r * tick / (2 * k)
    return math.hypot(along, lateral), heading, quant_position, quant_heading


def test_default_noise_straight_drive_stays_within_the_derived_bound(open_world):
    params, chassis = SimParams(), ChassisParams()
    sigma_pos, sigma_heading, quant_pos, quant_heading = predicted_errors(params, chassis, 1200, 0.5)
    position_errors, heading_errors = [], []
    for seed in range(8):
        sim, readings, position_error, heading_error = straight_run_errors(open_world, seed)
        # 4 sigma of the random part plus the worst case of the quantisation
        assert position_error < 4 * sigma_pos + quant_pos
        assert heading_error < 4 * sigma_heading + quant_heading
        position_errors.append(position_error)
        heading_errors.append(heading_error)
    # and the noise is really there, at the size its parameters say (8 samples: a loose band)
    rms_heading = math.sqrt(np.mean(np.square(heading_errors)))
    assert 0.4 * sigma_heading < rms_heading < 2.0 * sigma_heading
    assert min(position_errors) > 1e-5


def test_encoders_are_quantised_and_the_gyro_has_its_bias_and_noise(open_world):
    params = SimParams(seed=3)
    sim = Simulation(open_world, params)
    readings = drive(sim, [(2000, (0.3, 0.1, 0.4))])
    tick = 2 * np.pi / params.encoder_ticks_per_rev
    for r in readings[::97]:
        for values in (r.encoder_positions, r.follower_positions):
            assert np.allclose(values / tick, np.round(values / tick), atol=1e-6)
    gyro_error = np.array([r.gyro_z - r.twist[2] for r in readings])   # twist: the true mean rate
    assert gyro_error.mean() == pytest.approx(params.gyro_bias, abs=4 * params.gyro_noise_std / np.sqrt(2000))
    assert gyro_error.std() == pytest.approx(params.gyro_noise_std, rel=0.1)


# ---------------------------------------------------------------- contacts

def penetration(world, pose, wall_face_x=4.95):
    return float(transform_points(world.robot.footprint, pose)[0][:, 0].max() - wall_face_x)


@pytest.mark.parametrize("twist", [(1.0, 0.0, 0.0), (0.6, 0.4, 0.0), (0.8, -0.2, 0.15)])
def test_driving_into_a_wall_counts_a_collision_and_never_passes_it(wall_world, twist):
    sim = Simulation(wall_world, NO_NOISE)
    kin = sim.kinematics
    deepest = -np.inf
    sim.set_wheel_command(kin.ik(kin.saturate(twist)))
    for _ in range(800):
        r = sim.step()
        deepest = max(deepest, penetration(wall_world, r.pose))
        assert r.pose[0] < 4.95                                  # the centre stays on its side
    # the solver sees a contact one step after it happens: at most one step of the fastest
    # footprint point (all wheels at their limit: translation plus turn at the farthest corner)
    top = sim.chassis.wheel_radius * sim.chassis.max_wheel_speed
    reach = np.hypot(*wall_world.robot.footprint.T).max()
    fastest = (np.hypot(top, top) + top / (sim.chassis.l1 + sim.chassis.l2) * reach) * sim.params.dt
    assert 0 < deepest <= fastest + CONTACT_SLOP
    assert sim.collisions >= 1                 # turning along the wall it may lift off and hit again
    assert 0 < sim.contact_steps < 800 and r.in_contact
    assert sim.min_clearance == 0.0


def test_wheels_spin_against_a_wall_and_a_second_hit_counts_again(wall_world):
    sim = Simulation(wall_world, NO_NOISE)
    wheel, _ = odometers_for(sim)
    first = drive(sim, [(700, (0.8, 0.0, 0.0))], [(wheel, "encoder_positions")])
    # the wheels kept turning (odometry: 5.6 m less the ramp) while the body stopped at the wall
    assert wheel.pose[0] - 2.0 > 5.0 and first[-1].pose[0] < 4.95 - 0.416 + CONTACT_SLOP + 1e-3
    assert sim.collisions == 1
    drive(sim, [(300, (-0.5, 0.0, 0.0)), (700, (0.8, 0.0, 0.0))])
    assert sim.collisions == 2


def test_min_clearance_is_the_minimum_over_every_step(tmp_path):
    # the gate that skips the exact query must never hide a new minimum: compare with brute force
    for name, schedule in [("room", [(250, (0.4, 0.2, 0.3)), (250, (0.3, -0.1, -0.6))]),
                           ("warehouse", [(300, (0.5, 0.0, 0.0)), (200, (0.3, 0.3, 0.2))])]:
        world = load_world(world_path(name))
        sim = Simulation(world, NO_NOISE)
        brute = float(world.footprint_clearance(sim.pose, sim.mover_circles))
        for r in drive(sim, schedule):
            brute = min(brute, float(world.footprint_clearance(r.pose, r.mover_circles)))
        assert sim.min_clearance == brute


def test_min_clearance_passing_a_box_at_a_known_gap(tmp_path):
    # the footprint's top side (y + 0.318) passes 0.2 m below a box whose bottom is at y = 4.0
    world = make_world(tmp_path, "bounds: [12.0, 8.0]\nboxes: [{center: [6.0, 4.5], size: [1.0, 1.0]}]\n"
                                 "robot: {start: [1.416, 3.482, 0.0]}\n")
    sim = Simulation(world, NO_NOISE)
    assert sim.min_clearance == pytest.approx(1.0, abs=1e-9)       # the left outer wall at x = 0
    drive(sim, [(1500, (0.5, 0.0, 0.0))])
    assert sim.min_clearance == pytest.approx(0.2, abs=1e-9)
    assert sim.collisions == 0


def test_concave_footprint_collides_with_its_real_outline(tmp_path):
    # an L-shaped robot whose notch (x > 0, y > 0) is empty; a pillar above the lower arm fits in
    # the notch. The convex hull would hit it at x = 4.11, the L's upright arm hits it at x = 4.4.
    world = make_world(tmp_path, "bounds: [8.0, 6.0]\ncircles: [{center: [4.5, 3.15], radius: 0.1}]\n"
                                 "robot: {start: [3.0, 3.0, 0.0], footprint: "
                                 "[[-0.4, -0.4], [0.4, -0.4], [0.4, 0.0], [0.0, 0.0], [0.0, 0.4], [-0.4, 0.4]]}\n")
    sim = Simulation(world, NO_NOISE)
    assert len(sim.robot.shapes) == 2
    r = drive(sim, [(250, (0.5, 0.0, 0.0))])[-1]
    assert 4.15 < r.pose[0] < 4.35 and sim.collisions == 0
    drive(sim, [(200, (0.5, 0.0, 0.0))])
    assert sim.collisions == 1


# ---------------------------------------------------------------- movers

def test_movers_follow_their_paths_and_push_the_robot(tmp_path):
    world = load_world(world_path("warehouse"))
    sim = Simulation(world, NO_NOISE)
    for r in drive(sim, [(300, (0.0, 0.0, 0.0))])[::37]:
        assert r.mover_circles[:, :2] == pytest.approx(world.movers.pose_at(r.time), abs=1e-12)
        assert r.mover_circles[:, 2] == pytest.approx(world.movers.radius)
    # straight segments: the mean velocity over a step is the path velocity
    assert r.mover_velocities[1:] == pytest.approx(world.movers.velocity_at(r.time)[1:], abs=1e-9)

    # a mover crossing a parked robot pushes it aside; they never overlap by more than a step's travel
    world = make_world(tmp_path, "bounds: [12.0, 6.0]\nrobot: {start: [5.0, 3.0, 0.0]}\n"
                                 "movers: [{radius: 0.4, speed: 0.8, path: [[1.0, 3.5], [11.0, 3.5]], loop: false}]\n")
    sim = Simulation(world, NO_NOISE)
    deepest = 0.0
    for r in drive(sim, [(900, (0.0, 0.0, 0.0))]):
        outline = transform_points(world.robot.footprint, r.pose)[0]
        centre = r.mover_circles[0, :2]
        to_edges = point_segment_distance(centre, outline, np.roll(outline, -1, axis=0)).min()
        assert not points_in_polygons(centre[None], outline[None])[0, 0]
        deepest = max(deepest, 0.4 - to_edges)
    assert 0 < deepest <= 0.8 * sim.params.dt + CONTACT_SLOP + 1e-3
    assert sim.collisions >= 1 and r.pose[1] < 3.5 - 0.4 - 0.318 + 0.01   # pushed out of its way


LANE_WORLD = ("bounds: [12.0, 6.0]\nrobot: {start: [5.0, 3.0, 0.0]}\n"
              "movers: [{radius: 0.4, speed: 0.8, path: [[1.0, 3.5], [11.0, 3.5]], loop: false%s}]\n")


def gap_to_mover(world, r):
    """Distance between the robot's footprint and mover 0's circle (negative: overlapping)."""
    outline = transform_points(world.robot.footprint, r.pose)[0]
    centre, radius = r.mover_circles[0, :2], r.mover_circles[0, 2]
    return point_segment_distance(centre, outline, np.roll(outline, -1, axis=0)).min() - radius


def test_a_yielding_mover_waits_before_a_robot_in_its_lane_and_goes_on_when_it_has_left(tmp_path):
    world = make_world(tmp_path, LANE_WORLD % ", yield_distance: 1.0")
    sim = Simulation(world, NO_NOISE)
    parked = drive(sim, [(900, (0.0, 0.0, 0.0))])
    assert sim.collisions == 0
    stopped = parked[-1]
    assert stopped.mover_velocities == pytest.approx(np.zeros((1, 2)))
    assert parked[-300].mover_circles == pytest.approx(stopped.mover_circles)     # waiting, not creeping
    # it stopped as the robot came within yield_distance + YIELD_MARGIN ahead of it, not earlier
    assert 1.0 < gap_to_mover(world, stopped) <= 1.0 + YIELD_MARGIN
    assert stopped.mover_circles[0, 0] + 0.4 < stopped.pose[0] - 0.416

    left = drive(sim, [(400, (0.0, -0.5, 0.0)), (700, (0.0, 0.0, 0.0))])        # strafe out of the lane
    assert left[-1].pose[1] < 3.5 - 0.4 - 0.318 - YIELD_MARGIN
    assert left[-1].mover_circles[0, 0] > stopped.pose[0] + 1.0                # it went on past the robot
    assert sim.collisions == 0


def test_yielding_depends_only_on_the_seed_and_the_commands(tmp_path):
    world = make_world(tmp_path, LANE_WORLD % ", yield_distance: 1.0")
    schedule = [(500, (0.0, 0.0, 0.0)), (300, (0.1, -0.4, 0.0)), (300, (0.0, 0.0, 0.0))]
    runs = [np.array([r.mover_circles for r in drive(Simulation(world, SimParams(seed=3)), schedule)])
            for _ in range(2)]
    assert np.array_equal(runs[0], runs[1])
    assert np.ptp(runs[0][300:500, 0, 0]) == 0.0 and runs[0][-1, 0, 0] > runs[0][500, 0, 0] + 1.0   # waited, went on


def test_a_mover_without_yield_distance_drives_into_the_robot(tmp_path):
    world = make_world(tmp_path, LANE_WORLD % "")
    sim = Simulation(world, NO_NOISE)
    readings = drive(sim, [(900, (0.0, 0.0, 0.0))])
    assert sim.collisions >= 1 and min(gap_to_mover(world, r) for r in readings) < 0.01


def test_a_parked_robot_in_the_lane_of_a_mover_it_saw_coming_shares_the_contact(tmp_path):
    # the mover walks straight at the robot for seconds: the robot could have moved clear
    world = make_world(tmp_path, LANE_WORLD % "")
    sim = Simulation(world, NO_NOISE)
    drive(sim, [(900, (0.0, 0.0, 0.0))])
    assert sim.collisions >= 1 and sim.robot_fault_collisions == sim.collisions
    # without foresight the same contacts are the mover's alone
    blind = Simulation(world, dataclasses.replace(NO_NOISE, foresight_s=0.0))
    drive(blind, [(900, (0.0, 0.0, 0.0))])
    assert blind.collisions >= 1 and blind.mover_fault_collisions == blind.collisions


@pytest.mark.parametrize("robot_x, mover_from, mover_speed, robot_speed, robots_fault", [
    (1.5, 3.0, 0.2, 0.6, True),      # the robot drives after a slow mover walking away and runs into it
    (3.0, 1.0, 0.8, 0.2, False),     # a fast mover catches up from behind with a robot driving away
])
def test_who_moved_into_whom_decides_the_fault(tmp_path, robot_x, mover_from, mover_speed, robot_speed, robots_fault):
    world = make_world(tmp_path, f"bounds: [14.0, 6.0]\nrobot: {{start: [{robot_x}, 3.0, 0.0]}}\nmovers: [{{radius: 0.3, "
                                 f"speed: {mover_speed}, path: [[{mover_from}, 3.0], [13.0, 3.0]], loop: false}}]\n")
    sim = Simulation(world, NO_NOISE)
    drive(sim, [(400, (robot_speed, 0.0, 0.0))])
    assert sim.collisions >= 1
    assert (sim.robot_fault_collisions, sim.mover_fault_collisions) == ((sim.collisions, 0) if robots_fault
                                                                        else (0, sim.collisions))


def test_every_wall_contact_the_robot_drives_into_is_its_fault(wall_world):
    sim = Simulation(wall_world, NO_NOISE)
    drive(sim, [(700, (0.8, 0.0, 0.0)), (300, (-0.5, 0.0, 0.0)), (700, (0.8, 0.0, 0.0))])
    assert sim.robot_fault_collisions == sim.collisions == 2 and sim.mover_fault_collisions == 0


def test_a_parked_robot_shoved_into_a_wall_by_a_mover_is_not_the_robots_wall_contact(tmp_path):
    # the robot parked 0.13 m before a wall (face at x = 4.95), a mover walking into its back: the
    # mover's contact the robot saw coming (its share), the wall's not (its wheels stood still)
    world = make_world(tmp_path, "bounds: [8.0, 6.0]\nwalls: [[5.0, 0.5, 5.0, 5.5]]\nrobot: {start: [4.4, 3.0, 0.0]}\n"
                                 "movers: [{radius: 0.3, speed: 0.8, path: [[1.0, 3.0], [7.0, 3.0]], loop: false}]\n")
    sim = Simulation(world, NO_NOISE)
    readings = drive(sim, [(700, (0.0, 0.0, 0.0))])
    assert readings[-1].pose[0] > 4.4 + 0.05                    # shoved towards the wall
    assert (sim.collisions, sim.robot_fault_collisions, sim.mover_fault_collisions, sim.shoved_collisions) == (2, 1, 1, 1)


def test_a_robot_behind_or_beside_a_yielding_mover_does_not_stop_it(tmp_path):
    # both start touching the robot (front x = 2.416, left side y = 3.318) and walk away along +x:
    # one from right ahead of it, the other from beside its front corner, 6 cm to its left
    world = make_world(tmp_path, "bounds: [12.0, 6.0]\nrobot: {start: [2.0, 3.0, 0.0]}\n"
                                 "movers: [{radius: 0.3, speed: 0.5, path: [[2.716, 3.0], [11.0, 3.0]],"
                                 " loop: false, yield_distance: 1.0},\n"
                                 "         {radius: 0.3, speed: 0.5, path: [[2.416, 3.68], [11.0, 3.68]],"
                                 " loop: false, yield_distance: 1.0}]\n")
    sim = Simulation(world, NO_NOISE)
    readings = drive(sim, [(400, (0.0, 0.0, 0.0))])
    assert readings[-1].mover_circles[:, 0] == pytest.approx([2.716 + 2.0, 2.416 + 2.0])   # never stopped
    assert sim.collisions == 0


# ---------------------------------------------------------------- teleport, determinism, maps

def test_teleport_moves_the_robot_without_turning_a_wheel(open_world):
    sim = Simulation(open_world, NO_NOISE)
    before = drive(sim, [(100, (0.3, 0.0, 0.2)), (60, (0.0, 0.0, 0.0))])[-1]
    sim.teleport((10.0, 2.0, 1.0))
    assert sim.pose == pytest.approx([10.0, 2.0, 1.0])
    after = sim.step()
    assert after.pose == pytest.approx([10.0, 2.0, 1.0], abs=1e-12)
    assert after.encoder_positions == pytest.approx(before.encoder_positions)
    assert after.follower_positions == pytest.approx(before.follower_positions)
    assert after.gyro_z == pytest.approx(0.0) and after.twist == pytest.approx(np.zeros(3))
    moved = drive(sim, [(100, (0.5, 0.0, 0.0))])[-1].pose[:2] - [10.0, 2.0]   # drives on from there
    assert np.hypot(*moved) > 0.4 and np.arctan2(moved[1], moved[0]) == pytest.approx(1.0)
    sim.teleport((0.9, 1.0, 0.0))                              # next to the left wall: clearance updates
    assert sim.min_clearance == pytest.approx(0.9 - 0.416)


def test_same_seed_and_commands_give_identical_outputs(tmp_path):
    world = load_world(world_path("warehouse"))
    schedule = [(150, (0.5, 0.1, 0.2)), (150, (0.2, -0.3, -0.5)), (200, (-0.8, 0.0, 0.0))]
    runs = []
    for seed in (7, 7, 8):
        sim = Simulation(world, SimParams(seed=seed))
        readings = drive(sim, schedule)
        runs.append(([dataclasses.astuple(r) for r in readings], sim.collisions, sim.contact_steps, sim.min_clearance))

    def same(a, b):
        return all(all(np.array_equal(x, y) for x, y in zip(ra, rb)) for ra, rb in zip(a[0], b[0])) and a[1:] == b[1:]

    assert same(runs[0], runs[1])
    assert not same(runs[0], runs[2])


def test_drive_override_and_parameter_checks(open_world):
    sim = Simulation(open_world, dataclasses.replace(NO_NOISE, drive="diff"))
    assert sim.drive == "diff" and sim.kinematics.n_wheels == 2 and sim.chassis.drive == "diff"
    assert Simulation(open_world).drive == open_world.robot.drive
    for bad in [dict(dt=0), dict(dt=0.0100000001), dict(drive="tank"), dict(wheel_slip_std=-1.0),
                dict(encoder_ticks_per_rev=-1), dict(max_substep=0.0), dict(seed=-1)]:
        with pytest.raises(ValueError):
            SimParams(**bad)


def test_se2_log_inverts_se2_exp():
    from omninav.geometry.se2 import se2_exp
    rng = np.random.default_rng(0)
    for motion in np.vstack([rng.normal(size=(200, 3)), [[0.3, -0.2, 0.0], [1.0, 0.0, 1e-12]]]):
        assert se2_log(se2_exp(motion)) == pytest.approx(motion, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(st.booleans(), min_size=7, max_size=7), min_size=1, max_size=9))
def test_occupied_rectangles_cover_exactly_the_occupied_cells(rows):
    occupied = np.array(rows, dtype=bool)
    covered = np.zeros(occupied.shape, int)
    for row0, row1, col0, col1 in occupied_rectangles(occupied):
        covered[row0:row1, col0:col1] += 1
    assert np.array_equal(covered, occupied.astype(int))     # every cell once, nothing else


@pytest.mark.skipif(not (SHARED_DATA / "maps" / "willow-full-0.05.yaml").is_file(), reason="no shared map data")
def test_map_world_walls_stop_the_robot():
    world = load_world(world_path("willow"))
    sim = Simulation(world, NO_NOISE)
    assert len(sim.space.shapes) < world.grid_occupied.sum() / 2       # merged runs, not one box per cell
    readings = drive(sim, [(600, (0.0, 0.8, 0.0))])                  # sideways into the corridor wall
    assert sim.collisions >= 1 and sim.min_clearance == 0.0
    # the footprint shrunk by 2 cm (more than a step's travel plus slop) never touches a map cell
    half = world.robot.footprint.max(axis=0) - 0.02
    edge = np.linspace(-1, 1, 80)[:, None]
    outline = np.vstack([np.hstack([edge * half[0], np.full_like(edge, s * half[1])]) for s in (-1, 1)] +
                        [np.hstack([np.full_like(edge, s * half[0]), edge * half[1]]) for s in (-1, 1)])
    for r in readings[-100:]:
        assert world.distance(transform_points(outline, r.pose)[0]).min() > 0.0
    assert readings[-1].pose[1] == pytest.approx(17.6 + 0.95 - 0.318, abs=0.02)   # resting on the wall
