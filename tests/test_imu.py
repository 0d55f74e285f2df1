"""The simulated IMU (sim/imu.py) and the sim publishing it: bias, rate, centripetal term, a push
the wheels miss, determinism, and its parameters refused when malformed."""
import math

import numpy as np
import pytest

from omninav.cli.profile import load_profile
from omninav.parameters.declare import ParamError
from omninav.parameters.from_mapping import load_params
from omninav.schemas import decode
from omninav.schemas.messages import Header, Imu, WheelCommand
from omninav.sim.imu import ImuModel, ImuParams
from omninav.sim.node import SimNode, SimNodeParams
from omninav.sim.physics import SimParams, Simulation
from omninav.sim.world import load_world, world_path

NOISELESS = ImuParams(gyroscope_noise_density=0.0, gyroscope_random_walk=0.0, gyroscope_bias=0.0,
                      accelerometer_noise_density=0.0, accelerometer_random_walk=0.0, accelerometer_bias=(0.0, 0.0))


def readings_of(sim: Simulation, imu: ImuModel, twist, steps: int):
    """Drive `twist` through the robot's IK for `steps` steps: (sim readings, IMU readings)."""
    sim.set_wheel_command(sim.kinematics.ik(twist))
    out = [(r, imu.step(r.twist)) for r in (sim.step() for _ in range(steps))]
    return [r for r, _ in out], [reading for _, reading in out]


def test_standing_still_the_gyro_and_accelerometer_read_their_bias_within_noise():
    sim = Simulation(load_world(world_path("room")), SimParams(seed=4))
    params = ImuParams()
    imu = ImuModel(params, sim.params.dt, np.random.default_rng(4))
    _, readings = readings_of(sim, imu, (0.0, 0.0, 0.0), 2000)
    seconds = 2000 * sim.params.dt
    gyro = np.array([r.angular_velocity_z for r in readings])
    accel = np.array([r.linear_acceleration for r in readings])
    # the mean of N readings: the white noise's σ/√N, plus what the bias drifted (σ_b √T)
    gyro_slack = 4 * (imu.gyro_std / math.sqrt(len(gyro)) + params.gyroscope_random_walk * math.sqrt(seconds))
    accel_slack = 4 * (imu.accel_std / math.sqrt(len(accel)) + params.accelerometer_random_walk * math.sqrt(seconds))
    assert gyro.mean() == pytest.approx(params.gyroscope_bias, abs=gyro_slack)
    assert accel.mean(axis=0) == pytest.approx(params.accelerometer_bias, abs=accel_slack)
    assert gyro.std() == pytest.approx(imu.gyro_std, rel=0.1) and accel.std(axis=0) == pytest.approx(imu.accel_std, rel=0.1)


def test_turning_at_a_known_rate_the_gyro_reads_it():
    sim = Simulation(load_world(world_path("room")), SimParams(seed=2))     # wheel slip included
    imu = ImuModel(ImuParams(), sim.params.dt, np.random.default_rng(2))
    _, readings = readings_of(sim, imu, (0.0, 0.0, 0.8), 400)
    turning = np.array([r.angular_velocity_z for r in readings[100:]])      # past the motors' spin-up
    assert turning.mean() == pytest.approx(0.8 + ImuParams().gyroscope_bias, abs=0.01)


def test_on_an_arc_the_accelerometer_reads_the_centripetal_acceleration():
    imu = ImuModel(NOISELESS, 0.01, np.random.default_rng(0))
    readings = [imu.step(np.array([0.5, 0.0, 0.4])) for _ in range(5)]
    # v·ω to the left (the first step also holds the start from rest: 0.5 m/s in 10 ms)
    assert readings[0].linear_acceleration[0] == pytest.approx(50.0)
    for reading in readings[1:]:
        assert reading.linear_acceleration == pytest.approx([0.0, 0.5 * 0.4])
        assert reading.angular_velocity_z == pytest.approx(0.4)


def test_a_push_shows_in_the_accelerometer_in_its_step_while_the_wheels_stand_still(tmp_path):
    # a mover walks into the back of a parked robot (wheels commanded still) and shoves it on
    path = tmp_path / "push.yaml"
    path.write_text("bounds: [8.0, 6.0]\nrobot: {start: [4.0, 3.0, 0.0]}\n"
                    "movers: [{radius: 0.3, speed: 0.8, path: [[1.0, 3.0], [7.0, 3.0]], loop: false}]\n")
    sim = Simulation(load_world(path), SimParams(seed=1).without_noise())
    imu = ImuModel(ImuParams(), sim.params.dt, np.random.default_rng(1))
    sim_readings, readings = readings_of(sim, imu, (0.0, 0.0, 0.0), 400)
    first = next(k for k, r in enumerate(sim_readings) if r.in_contact)
    bias = np.array(ImuParams().accelerometer_bias)
    loudest_noise = 5 * imu.accel_std
    before = np.array([r.linear_acceleration for r in readings[:first]]) - bias
    assert np.abs(before).max() < loudest_noise                           # quiet until the mover arrives
    assert abs(readings[first].linear_acceleration[0] - bias[0]) > 10 * loudest_noise    # the push, in its step
    assert sim_readings[-1].pose[0] > 4.0 + 0.1                            # it was shoved on
    for r in sim_readings:
        assert not r.encoder_positions.any() and not r.wheel_speeds.any()  # wheel odometry saw nothing


def run_node(**params):
    """A sim node turning slowly for 50 steps: its outputs by key, in order."""
    node = SimNode(SimNodeParams(world="room", **params))
    out: dict[str, list] = {}
    for pub in node.outputs.values():
        pub.sink = lambda p, payload, stamp: out.setdefault(p.key, []).append(decode(payload))
    node.process(0, WheelCommand(header=Header(), drive=node.sim.drive,
                                 velocities=node.sim.kinematics.ik((0.3, 0.0, 0.5))))
    for _ in range(50):
        node.tick()
    return node, out


def test_the_same_seed_gives_the_same_readings_and_leaves_the_other_outputs_as_they_were():
    _, first = run_node(seed=7)
    _, again = run_node(seed=7)
    _, other = run_node(seed=8)
    imu = "omninav/r1/imu"
    assert len(first[imu]) == 50 and all(isinstance(m, Imu) for m in first[imu])
    assert first[imu] == again[imu] and first[imu] != other[imu]
    # the IMU draws from its own stream of the seed: the wheels read as a simulator without it
    bare = Simulation(load_world(world_path("room")), SimParams(seed=7))
    bare.set_wheel_command(bare.kinematics.ik((0.3, 0.0, 0.5)))
    for state in first["omninav/r1/wheel_state"]:
        assert state.positions.tolist() == bare.step().encoder_positions.tolist()


@pytest.mark.parametrize("dt, update_rate, every", [(0.01, 100.0, 1), (0.005, 100.0, 2), (0.01, 50.0, 2),
                                                     (0.02, 100.0, 1)])
def test_readings_come_at_the_update_rate_or_every_longer_step(dt, update_rate, every):
    node, out = run_node(dt=dt, imu={"update_rate": update_rate, "frame_id": "imu_link"})
    step_ns = round(dt * 1e9)
    stamps = [m.header.stamp_ns for m in out["omninav/r1/imu"]]
    assert stamps == [k * step_ns for k in range(every, 51, every)]
    reading = out["omninav/r1/imu"][-1]
    assert reading.header.frame_id == "imu_link"
    assert reading.angular_velocity_z_variance == pytest.approx(node.imu_model.gyro_std ** 2)
    # white noise over a longer reading is smaller: density / √period
    assert node.imu_model.accel_std == pytest.approx(ImuParams().accelerometer_noise_density / math.sqrt(every * dt))


@pytest.mark.parametrize("imu, named", [({"gyro_noise": 0.1}, "gyro_noise"),
                                        ({"update_rate": 0.0}, "update_rate"),
                                        ({"accelerometer_bias": [0.1]}, "accelerometer_bias"),
                                        ({"gyroscope_noise_density": -1.0}, "gyroscope_noise_density"),
                                        ({"frame_id": ""}, "frame_id")])
def test_a_malformed_or_unknown_imu_parameter_is_refused_naming_it(imu, named):
    with pytest.raises(ParamError, match=named) as err:
        SimNodeParams(imu=imu)
    assert "sim.imu" in str(err.value)


def test_the_jackal_profile_gives_its_simulator_an_imu():
    values = load_profile("jackal").params["sim"]["imu"]
    assert load_params(ImuParams, values, "jackal sim.imu").frame_id == "imu_link"
