"""`bridge ros2` logs in to the robot's router as rmw_zenoh's security does (usrpwd, or a Zenoh config
file with usrpwd or TLS), refuses a config that opens more than loopback, and ends with one line when
the router refuses it. The robot's router is a Zenoh router in this process with a usrpwd dictionary,
as `up`'s router is configured (zenoh_config.router_config). No TLS end-to-end test: no certificate
can be made here without a new dependency (python `cryptography` is not installed); TLS is tested as
configuration only."""
from __future__ import annotations

import pytest

from omninav.services.runtime.zenoh_config import checked_login_config, foreign_client_config, open_router

from conftest import free_port
from test_ros2_bridge import stack_args

NO_SCAN = "no /scan seen"       # what a bridge that got in says next: this robot publishes nothing


@pytest.fixture
def robot(tmp_path):
    """(the robot's router endpoint, a file with the right password, one with a wrong one)."""
    dictionary = tmp_path / "robot.dict"
    dictionary.write_text("robot:s3cret-passw0rd\n")
    right, wrong = tmp_path / "right", tmp_path / "wrong"
    right.write_text("s3cret-passw0rd\n")
    wrong.write_text("guessed\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with open_router(endpoint, dictionary):
        yield endpoint, right, wrong


def bridge(capsys, **options) -> tuple[int, str]:
    from omninav.cli.bridge import main
    code = main(stack_args(tf_timeout=5.0, **options))
    return code, capsys.readouterr().err


def test_the_right_user_and_password_get_in(robot, capsys, tmp_path):
    endpoint, right, _ = robot
    code, err = bridge(capsys, router=endpoint, user="robot", password_file=str(right))
    assert code == 2 and NO_SCAN in err
    config = tmp_path / "rmw_zenoh_session.json5"     # as zenoh_security_tools writes it: usrpwd, the router
    config.write_text(f'{{mode: "peer", connect: {{endpoints: ["{endpoint}"]}}, listen: {{endpoints: '
                      f'["tcp/localhost:0"]}}, scouting: {{multicast: {{enabled: false}}, gossip: {{enabled: false}}}},'
                      f' transport: {{auth: {{usrpwd: {{user: "robot", password: "s3cret-passw0rd"}}}}}}}}')
    code, err = bridge(capsys, zenoh_config=str(config))
    assert code == 2 and NO_SCAN in err


@pytest.mark.parametrize("login, said", [({}, "without credentials"), ({"user": "robot", "wrong": True}, "as user robot")])
def test_no_or_a_wrong_login_is_refused_in_one_line(robot, capsys, login, said):
    endpoint, _, wrong = robot
    options = {"user": "robot", "password_file": str(wrong)} if login else {}
    for laser in (None, [0.0, 0.0, 0.0]):       # finding the laser on the robot, or given (the stack not started)
        code, err = bridge(capsys, router=endpoint, laser=laser, **options)
        assert (code, err) == (2, f"error: the robot's router at {endpoint} refused the bridge's login ({said})\n")


def test_the_bridge_service_refused_by_the_robot_exits_non_zero(robot, processes):
    endpoint, _, wrong = robot
    node = processes.omninav("run", "ros2_bridge", "--set", f"ros_router={endpoint}", "--set", "ros_user=robot",
                             "--set", f"ros_password_file={wrong}")
    assert node.wait(120) != 0
    assert "refused the bridge's login (as user robot)" in processes.log_of(node)


@pytest.mark.parametrize("text, key", [
    ('{listen: {endpoints: ["tcp/0.0.0.0:7448"]}}', "listen/endpoints"),
    ('{mode: "peer", listen: {endpoints: {peer: ["tcp/[::]:0"]}}}', "listen/endpoints"),
    ('{scouting: {multicast: {enabled: true}}}', "scouting/multicast/enabled"),
    ('{scouting: {gossip: {enabled: true}}}', "scouting/gossip/enabled"),
    ('{mode: "router"}', "mode"),
    ('{plugins: {rest: {http_port: 8000}}}', "plugins"),
    ('{transport: {link: {tls: {root_ca_certificate: "/nowhere/ca.pem"}}}}', "transport/link/tls/root_ca_certificate"),
])
def test_a_config_that_opens_more_than_loopback_is_refused_naming_the_key(capsys, tmp_path, text, key):
    config = tmp_path / "bad.json5"
    config.write_text(text)
    code, err = bridge(capsys, zenoh_config=str(config), laser=[0.0, 0.0, 0.0])
    assert code == 2 and err.startswith(f"error: --zenoh-config {config}: {key}") and err.count("\n") == 1


def test_tls_passes_through_and_its_router_may_be_off_loopback(tmp_path):
    for name in ("ca.pem", "cert.pem", "key.pem"):
        (tmp_path / name).write_text("not checked here\n")
    config = tmp_path / "tls.json5"
    config.write_text(f'{{connect: {{endpoints: ["tls/robot.local:7447"]}}, transport: {{link: {{tls: {{'
                      f'root_ca_certificate: "{tmp_path / "ca.pem"}", connect_certificate: "{tmp_path / "cert.pem"}", '
                      f'connect_private_key: "{tmp_path / "key.pem"}", enable_mtls: true}}}}}}}}')
    conf = foreign_client_config("tcp/127.0.0.1:7447", checked_login_config(config))
    tls = conf.get_json("transport/link/tls")
    assert all(str(tmp_path / n) in tls for n in ("ca.pem", "cert.pem", "key.pem")) and '"enable_mtls":true' in tls
    assert conf.get_json("connect/endpoints") == '["tls/robot.local:7447"]'
    assert (conf.get_json("mode"), conf.get_json("listen/endpoints")) == ('"client"', "[]")
    assert conf.get_json("scouting/multicast/enabled") == conf.get_json("scouting/gossip/enabled") == "false"
    (tmp_path / "key.pem").unlink()
    with pytest.raises(ValueError, match="connect_private_key"):
        checked_login_config(config)
