"""Access control on the bus: Zenoh user/password identities per process and the router's ACL built
from each service's declarations; only the right process moves the robot."""
import threading
from pathlib import Path

import numpy as np
import pytest
import yaml
import zenoh

from omninav.cli.navigate import compose_for, map_for
from omninav.schemas import decode
from omninav.schemas.codec import encode
from omninav.schemas.keys import KeyLayout
from omninav.schemas.messages import Header, Twist
from omninav.services.runtime.acl import (OPERATOR, TELEOP, TOOL, Grants, access_control, publishers_of,
                                          read_credentials, write_credentials)
from omninav.services.runtime.compose import load_compose
from omninav.services.runtime.launcher import identities
from omninav.services.runtime.zenoh_config import client_config, free_loopback_endpoint, open_client, open_router
from omninav.sim.world import load_world, world_path

from conftest import REPO, wait_alive, wait_until

KEYS = KeyLayout("r1")
GATED = """\
    services:
      - name: sim
        service: sim
        params: {world: sim/worlds/room.yaml}
      - name: chassis
        service: chassis
      - name: lidar
        service: lidar
        params: {world: sim/worlds/room.yaml}
      - name: cmd_vel_mux
        service: cmd_vel_mux
      - name: velocity_smoother
        service: velocity_smoother
      - name: collision_monitor
        service: collision_monitor
    """


def shipped_and_mission_composes(tmp_path: Path) -> list[Path]:
    world = load_world(world_path("room"))
    mission = compose_for(world, Path(world.source), map_for(world, "room", tmp_path), "diff", "amcl",
                          tmp_path / "run.mcap", seed=1, rate=1.0, robot="r1")
    (tmp_path / "mission.yaml").write_text(yaml.safe_dump(mission, sort_keys=False))
    return [*sorted((REPO / "compose").glob("*.yaml")), tmp_path / "mission.yaml"]


def test_every_shipped_compose_file_and_a_mission_build_an_acl_the_router_accepts(tmp_path):
    for path in shipped_and_mission_composes(tmp_path):
        grants = identities(load_compose(path))
        dictionary = write_credentials(tmp_path / path.stem, grants)
        with open_router(free_loopback_endpoint(), dictionary, access_control(grants)):
            pass
        assert not grants[TOOL].put, "tools are read-only"
        if "sim" not in grants and "ros2_bridge" not in grants:     # the demo's talker is its clock
            continue
        putters = {key: sorted(user for user, g in grants.items() if key in g.put)
                   for key in (KEYS.robot("cmd_vel"), KEYS.robot("wheel_cmd"), KEYS.sim("clock"), KEYS.sim_robot("truth"))}
        # on a ROS 2 robot (ros2_robot.yaml) the bridge publishes the robot's time in the sim's place
        clock = "sim" if "sim" in grants else "ros2_bridge"
        owners = {"cmd_vel": "collision_monitor", "wheel_cmd": "chassis", "clock": clock, "truth": "sim"}
        for key, users in putters.items():      # the motion chain is closed: one writer per key, or none
            assert users in ([], [owners[key.rsplit("/", 1)[1]]]), (path.name, key, users)


def test_identity_files_are_private_and_unreadable_ones_give_one_line(tmp_path):
    dictionary = write_credentials(tmp_path / "ids", {"sim": Grants(put=(KEYS.sim("clock"),)), TOOL: Grants()})
    assert oct((tmp_path / "ids").stat().st_mode & 0o777) == "0o700"
    for path in (dictionary, tmp_path / "ids" / "sim", tmp_path / "ids" / TOOL):
        assert oct(path.stat().st_mode & 0o777) == "0o600"
    user, password = read_credentials(tmp_path / "ids" / "sim")
    assert user == "sim" and len(password) >= 24 and f"sim:{password}" in dictionary.read_text()
    (tmp_path / "bad").write_text("no colon here")
    with pytest.raises(ValueError, match="expected one line 'user:password'"):
        read_credentials(tmp_path / "bad")
    with pytest.raises(ValueError, match="cannot read it"):
        read_credentials(tmp_path / "missing")
    assert publishers_of(tmp_path / "ids", {KEYS.sim("clock")}) == {KEYS.sim("clock"): tmp_path / "ids" / "sim"}
    with pytest.raises(ValueError, match="no identity of this run may put omninav/r1/cmd_vel"):
        publishers_of(tmp_path / "ids", {KEYS.sim("clock"), KEYS.robot("cmd_vel")})


def _try_connect(endpoint: str, credentials: Path | None) -> bool:
    conf = client_config(endpoint, str(credentials) if credentials else None)
    conf.insert_json5("connect/timeout_ms", "1500")         # here: give up instead of waiting forever
    try:
        zenoh.open(conf).close()
    except zenoh.ZError:
        return False
    return True


def test_without_credentials_or_with_a_wrong_password_nothing_connects(tmp_path, monkeypatch):
    monkeypatch.delenv("OMNINAV_CREDENTIALS", raising=False)
    grants = identities(load_compose(REPO / "compose" / "demo.yaml"))
    dictionary = write_credentials(tmp_path / "ids", grants)
    (tmp_path / "forged").write_text("talker:not-its-password\n")
    endpoint = free_loopback_endpoint()
    with open_router(endpoint, dictionary, access_control(grants)):
        assert not _try_connect(endpoint, None)
        assert not _try_connect(endpoint, tmp_path / "forged")
        assert _try_connect(endpoint, tmp_path / "ids" / "talker")


class Commander:
    """Puts a Twist on a key at 20 Hz of wall time from one identity, stamped with the latest clock."""

    def __init__(self, session: zenoh.Session, clock: list, topic: str, vx: float):
        self.session, self.clock, self.key, self.vx = session, clock, KEYS.robot(topic), vx

    def drive(self, seconds: float) -> None:
        stop = threading.Event()
        for _ in range(round(seconds * 20)):
            msg = Twist(header=Header(stamp_ns=self.clock[-1], frame_id="base_link"), linear_x=self.vx)
            self.session.put(self.key, encode(msg))
            stop.wait(0.05)


def test_injected_cmd_vel_does_not_move_the_robot_and_teleop_through_the_mux_does(up, endpoint):
    launcher = up(GATED)
    names = [s["name"] for s in yaml.safe_load(GATED)["services"]]
    wait_alive(endpoint, names)
    creds = up.credentials
    truths, clock = [], [0]
    with open_client(endpoint) as tool, open_client(endpoint, str(creds / OPERATOR)) as operator, \
            open_client(endpoint, str(creds / TELEOP)) as teleop:
        tool.declare_subscriber(KEYS.sim_robot("truth"), lambda s: truths.append(decode(s.payload.to_bytes())))
        tool.declare_subscriber(KEYS.sim("clock"), lambda s: clock.append(decode(s.payload.to_bytes()).header.stamp_ns))
        wait_until(lambda: len(truths) > 10, 60, what="the sim's ground truth")

        def position() -> np.ndarray:
            return np.array([truths[-1].pose.x, truths[-1].pose.y])

        start = position()
        for session in (tool, operator, teleop):     # every identity but the collision monitor's is refused
            Commander(session, clock, "cmd_vel", 0.4).drive(1.0)
        assert np.linalg.norm(position() - start) < 1e-3, "an injected cmd_vel moved the robot"
        Commander(tool, clock, "cmd_vel_teleop", 0.4).drive(1.0)    # the tool may not drive by hand either
        assert np.linalg.norm(position() - start) < 1e-3

        Commander(teleop, clock, "cmd_vel_teleop", 0.3).drive(2.0)  # the one way in: mux, smoother, monitor
        wait_until(lambda: np.linalg.norm(position() - start) > 0.1, 20, what="teleop moving the robot")
    assert up.procs.stop(launcher) == 0
