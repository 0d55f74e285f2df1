"""Compose files load into the expected structure; every kind of mistake is one error naming it."""
import textwrap

import pytest

from omninav.services.runtime.compose import ComposeError, ServiceSpec, load_compose

from conftest import REPO


def write(tmp_path, text, name="compose.yaml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_a_valid_file_parses_into_services_in_order(tmp_path):
    (tmp_path / "params").mkdir()
    write(tmp_path, """\
        listener:
          ros__parameters:
            gain: 2.0
            summary_period_s: 0.5
        """, "params/listener.yaml")
    path = write(tmp_path, """\
        router: tcp/127.0.0.1:7500
        robot: r2
        services:
          - service: talker
            params: {rate: 4}
            restart: no
          - name: listener
            service: listener
            params_file: params/listener.yaml
            params: {gain: 3}
            robot: r3
            restart: always
            max_restarts: 4
          - name: mine
            module: omninav.services.demo.talker:Talker
        """)
    compose = load_compose(path)
    assert compose.path == path and compose.router == "tcp/127.0.0.1:7500" and compose.robot == "r2"
    assert compose.services == (
        ServiceSpec("talker", "talker", None, {"rate": 4}, "r2", "no", None, "talker"),
        # the file's values, overridden by the inline ones; the file's path is relative to the compose file
        ServiceSpec("listener", "listener", None, {"gain": 3, "summary_period_s": 0.5}, "r3", "always", 4,
                        "listener"),
        ServiceSpec("mine", None, "omninav.services.demo.talker:Talker", {}, "r2", "on-failure", None, "mine"),
    )


def test_defaults(tmp_path):
    compose = load_compose(write(tmp_path, "services: [{service: listener}]\n"))
    assert compose.router is None and compose.robot == "r1"
    assert compose.services == (ServiceSpec("listener", "listener", None, {}, "r1", "on-failure", None, "listener"),)


@pytest.mark.parametrize("services,needles", [
    ("- service: nosuch", ["services[0] (nosuch)", "unknown service 'nosuch'"]),
    ("- {name: x, module: omninav_nosuch.mod:Node}", ["services[0] (x)", "cannot import omninav_nosuch.mod"]),
    ("- {name: x, module: 'omninav.services.demo.talker:Nope'}", ["services[0] (x)", "has no Nope"]),
    ("- {name: x, module: 'omninav.services.demo.talker:TalkerParams'}", ["services[0] (x).module", "not a Node class"]),
    ("- {name: x, module: omninav.services.demo.talker}", ["services[0].module", "not 'package.module:Class'"]),
    ("- {module: 'omninav.services.demo.talker:Talker'}", ["services[0]", "needs a 'name'"]),
    ("- {service: talker, module: 'omninav.services.demo.talker:Talker'}", ["services[0]", "exactly one of"]),
    ("- {name: x}", ["services[0]", "exactly one of"]),
    ("- {service: listener, params_file: missing.yaml}",
     ["services[0] (listener).params_file", "missing.yaml: no such file"]),
    ("- {service: listener, params_file: broken.yaml}", ["services[0] (listener).params_file", "not valid YAML"]),
    ("- {service: listener, params_file: typo.yaml}",
     ["services[0] (listener).params_file", "typo.yaml", "unknown parameter 'gian' (did you mean 'gain'?)"]),
    ("- {service: listener, params: {gian: 2}}", ["services[0] (listener).params", "unknown parameter 'gian' (did you mean 'gain'?)"]),
    ("- {service: listener, params: {gain: fast}}", ["services[0] (listener).params", "'gain' must be a number"]),
    ("- {service: talker, params: {rate: -1}}", ["services[0] (talker).params", "parameter rate must be > 0, got -1.0"]),
    ("- {service: listener, params: [gain]}", ["services[0] (listener).params", "must be a mapping"]),
    ("- service: talker\n- service: listener\n- service: talker", ["services[2]", "duplicate name 'talker'"]),
    ("- {service: talker, parmas: {rate: 2}}", ["services[0]", "unknown key 'parmas' (did you mean 'params'?)"]),
    ("- {service: talker, restart: sometimes}", ["services[0] (talker).restart", "'sometimes'"]),
    ("- {service: talker, max_restarts: -1}", ["services[0] (talker).max_restarts", "-1"]),
    ("- {service: talker, max_restarts: 1.5}", ["services[0] (talker).max_restarts", "1.5"]),
    ("- {service: talker, robot: 'r 1'}", ["services[0] (talker).robot", "'r 1'"]),
    ("- {service: talker, name: 'a/b'}", ["services[0].name", "'a/b'"]),
    ("- talker", ["services[0]", "expected a mapping"]),
    ("[]", ["services must be a non-empty list"]),
])
def test_service_errors_name_the_file_and_the_key(tmp_path, services, needles):
    write(tmp_path, "not: [valid", "broken.yaml")
    write(tmp_path, "listener:\n  ros__parameters:\n    gian: 2\n", "typo.yaml")
    path = write(tmp_path, "services:\n" + textwrap.indent(services, "  ") + "\n")
    with pytest.raises(ComposeError) as err:
        load_compose(path)
    message = str(err.value)
    assert message.startswith(str(path)), message
    for needle in needles:
        assert needle in message, message


@pytest.mark.parametrize("text,needle", [
    ("servces: [{service: talker}]\n", "unknown key 'servces' (did you mean 'services'?)"),
    ("router: tcp/0.0.0.0:7447\nservices: [{service: talker}]\n", "router: endpoint 'tcp/0.0.0.0:7447'"),
    ("router: 7447\nservices: [{service: talker}]\n", "router must be an endpoint string"),
    ("robot: 'a b'\nservices: [{service: talker}]\n", "robot: robot namespace 'a b'"),
    ("- talker\n", "expected a mapping with a 'services' list"),
    ("services: [talker\n", "not valid YAML"),
])
def test_file_errors_name_the_file_and_the_key(tmp_path, text, needle):
    path = write(tmp_path, text)
    with pytest.raises(ComposeError) as err:
        load_compose(path)
    assert str(path) in str(err.value) and needle in str(err.value), str(err.value)


def test_missing_compose_file(tmp_path):
    with pytest.raises(ComposeError, match="nope.yaml: no such file"):
        load_compose(tmp_path / "nope.yaml")


def test_a_module_that_fails_to_import_is_an_error_not_a_traceback(tmp_path, monkeypatch):
    (tmp_path / "omninav_broken_mod.py").write_text("x = (\n")
    monkeypatch.syspath_prepend(tmp_path)
    path = write(tmp_path, "services: [{name: x, module: 'omninav_broken_mod:Node'}]\n")
    with pytest.raises(ComposeError, match=r"services\[0\] \(x\): importing omninav_broken_mod:Node failed: SyntaxError"):
        load_compose(path)


def test_the_demo_compose_file_is_valid():
    pytest.importorskip("omninav.services.recorder.node", reason="the recorder service is not written yet")
    compose = load_compose(REPO / "compose" / "demo.yaml")
    assert [s.name for s in compose.services] == ["recorder", "talker", "listener"]  # recorder stops last


def test_a_misspelt_compose_key_names_the_closest_known_one(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("services:\n  - {service: chassis, param: {drive: diff}}\n")
    with pytest.raises(ComposeError, match=r"unknown key 'param' \(did you mean 'params'\?\)"):
        load_compose(path)
    path.write_text("services:\n  - {service: chassis, params: {drvie: diff}}\n")
    with pytest.raises(ComposeError, match=r"unknown parameter 'drvie' \(did you mean 'drive'\?\)"):
        load_compose(path)


def test_up_imports_each_node_class_once_while_loading_the_file(tmp_path, monkeypatch):
    """The loaded file carries each service's Node class; what `up` does next builds from it."""
    from omninav.services.demo.talker import Talker
    from omninav.services.runtime import launcher, run

    compose = load_compose(write(tmp_path, "services: [{service: talker}, {name: mine, module: "
                                           "'omninav.services.demo.talker:Talker'}]\n"))
    assert [s.node_type for s in compose.services] == [Talker, Talker]

    def no_second_import(*args):
        raise AssertionError(f"node class resolved again: {args}")
    monkeypatch.setattr(run, "node_class", no_second_import)
    assert launcher.lockstep_participants(compose) == ["talker", "mine"]
    assert all(isinstance(node, Talker) for node in launcher.build_nodes(compose).values())
