"""The lidar node in-process: scans on the sim-time schedule, equal to a direct ray cast, movers
seen, seeded noise (and the rest of the sensor model) reproducible, a broken world refused clearly."""
import math

import numpy as np
import pytest

from omninav.schemas import decode
from omninav.schemas.messages import Header, Obstacles, Odometry, Pose2D
from omninav.services.lidar.node import LidarNode, LidarNodeParams
from omninav.services.runtime.node import NS_PER_S
from omninav.parameters.from_mapping import load_params
from omninav.services.runtime.run import build_node
from omninav.sim.lidar import LidarParams, scan
from omninav.sim.world import WorldError, load_world, world_path

STEP_NS = 10_000_000


def capture(node):
    out = []
    node.scan_pub.sink = lambda p, payload, stamp: out.append(payload)
    return out


def truth(t_ns, x, y, theta):
    return Odometry(header=Header(stamp_ns=t_ns, frame_id="world"), pose=Pose2D(x, y, theta))


def movers(t_ns, circles):
    circles = np.asarray(circles, float).reshape(-1, 3)
    return Obstacles(header=Header(stamp_ns=t_ns, frame_id="world"), circles=circles,
                     velocities=np.zeros((len(circles), 2)))


def path(t_ns):
    """A pose moving through the room (starts at the room's start, (1.2, 1.0, 0))."""
    s = t_ns / NS_PER_S
    return 1.2 + 0.4 * s, 1.0 + 0.2 * s, 0.5 * s


def feed(node, start_ns, steps, circles=((5.0, 4.0, 0.3),)):
    """Movers then truth every sim step, in the order replay (and the live merge) processes them."""
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    for k in range(steps):
        t = start_ns + k * STEP_NS
        node.process(index["omninav/sim/movers"], movers(t, circles))
        node.process(index["omninav/sim/r1/truth"], truth(t, *path(t)))


def test_inputs_are_movers_then_truth():
    node = LidarNode(LidarNodeParams())
    assert [(i.key, i.synced) for i in node.inputs] == [("omninav/sim/movers", True), ("omninav/sim/r1/truth", True)]


def test_scans_come_at_rate_hz_of_sim_time_and_equal_a_direct_cast():
    params = LidarNodeParams(noise_std=0.0, range_max=3.0, rate_hz=10.0)
    node = LidarNode(params)
    out = capture(node)
    start = 370_000_000                      # joins at 0.37 s: scans fall on multiples of 0.1 s
    feed(node, start, 105)
    scans = [decode(p) for p in out]
    assert [s.header.stamp_ns for s in scans] == [round(t * NS_PER_S) for t in np.arange(0.4, 1.45, 0.1)]
    world = load_world(world_path("room"))
    for s in scans:
        expected = scan(world, path(s.header.stamp_ns), np.array([[5.0, 4.0, 0.3]]), params, None)
        assert s.ranges.dtype == np.float32
        assert np.array_equal(s.ranges, expected.astype(np.float32))
        assert s.header.frame_id == "laser"
        assert (s.angle_min, s.angle_increment, s.range_min, s.range_max) == (
            params.angle_min, params.angle_increment, params.range_min, params.range_max)
        assert s.scan_time == pytest.approx(0.1) and len(s.ranges) == params.beams
    assert any(np.isinf(s.ranges).any() for s in scans)       # no return within 3 m: +inf
    assert decode(out[-1]).header.seq == len(scans)
    assert node.answer("omninav/r1/scan", {}).header.stamp_ns == scans[-1].header.stamp_ns


def test_a_mover_in_front_is_seen():
    params = LidarNodeParams(noise_std=0.0, beams=360)
    node = LidarNode(params)
    out = capture(node)
    index = {inp.key: i for i, inp in enumerate(node.inputs)}
    x, y = 2.0, 4.0                          # free space, nothing within 2.7 m ahead
    for stamp_ns, circles in ((0, []), (100_000_000, [[x + 1.5, y, 0.25]])):     # one scan period apart
        node.process(index["omninav/sim/movers"], movers(stamp_ns, circles))
        node.process(index["omninav/sim/r1/truth"], truth(stamp_ns, x, y, 0.0))
    forward = int(round(-params.angle_min / params.angle_increment))      # the beam at angle 0
    without, with_mover = (decode(p).ranges[forward] for p in out)
    assert with_mover == pytest.approx(1.25, abs=1e-6) and without > 1.5


def _noisy_run(seed, model):
    node = LidarNode(LidarNodeParams(seed=seed, **model))
    out = capture(node)
    feed(node, 0, 50)
    return out


@pytest.mark.parametrize("model", [dict(noise_std=0.05, dropout_prob=0.1),
                                   dict(noise_std=0.01, noise_std_per_m=0.005, dropout_prob=0.05, range_dropout_start=4.0,
                                        range_dropout_prob=0.5, incidence_dropout_start=1.0, incidence_dropout_prob=0.8,
                                        beam_divergence=0.01, mixed_pixel_prob=0.5)])
def test_noise_is_seeded_and_reproducible(model):
    first, again, other = _noisy_run(7, model), _noisy_run(7, model), _noisy_run(8, model)
    assert len(first) == 5 and first == again and first != other
    # the node's generator is exactly the documented one: default_rng(seed), drawn by each scan in turn
    params = LidarNodeParams(seed=7, **model)
    rng, world = np.random.default_rng(7), load_world(world_path("room"))
    for payload in first:
        s = decode(payload)
        expected = scan(world, path(s.header.stamp_ns), np.array([[5.0, 4.0, 0.3]]), params, rng)
        assert np.array_equal(s.ranges, expected.astype(np.float32))


def test_a_broken_world_is_refused_clearly(tmp_path):
    with pytest.raises(WorldError, match="nosuch.yaml: no such file"):
        LidarNode(LidarNodeParams(world=str(tmp_path / "nosuch.yaml")))
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nbounds: [10, -2]\nrobot: {start: [1, 1, 0]}\n")
    with pytest.raises(WorldError, match=r"bad.yaml: bounds"):
        build_node("lidar", None, {"world": str(bad)})


def test_parameters_extend_the_lidar_params():
    params = load_params(LidarNodeParams, {"beams": 90, "fov": math.pi, "world": "warehouse", "seed": 3})
    assert isinstance(params, LidarParams) and params.angle_min == pytest.approx(-math.pi / 2)
    node = LidarNode(params)
    assert node.world.name == "warehouse" and node.params.beams == 90
