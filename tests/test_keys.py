import pytest

from omninav.schemas import KeyLayout, type_for_key
from omninav.schemas.keys import ROBOT_TOPICS, SIM_TOPICS
from omninav.schemas.messages import Clock, Diagnostic, LaserScan, Odometry
from omninav.services.runtime.selector import join_selector, split_selector


def test_layout_and_namespaces():
    r1, r2 = KeyLayout(), KeyLayout("r2")
    assert r1.robot("scan") == "omninav/r1/scan" and r2.robot("scan") == "omninav/r2/scan"
    assert r1.sim("clock") == r2.sim("clock") == "omninav/sim/clock"
    assert r2.resolve("sim/truth") == "omninav/sim/r2/truth"
    assert r1.diagnostics("slam") == "omninav/r1/diagnostics/slam"


def test_types_by_key():
    assert type_for_key("omninav/r7/scan") is LaserScan
    assert type_for_key("omninav/sim/clock") is Clock
    assert type_for_key("omninav/sim/r7/truth") is Odometry
    assert type_for_key("omninav/r1/diagnostics/amcl") is Diagnostic
    assert type_for_key("omninav/r1/nope") is None and type_for_key("other/r1/scan") is None
    for topic in ROBOT_TOPICS:
        assert type_for_key(KeyLayout().robot(topic)) is ROBOT_TOPICS[topic]
    for topic in SIM_TOPICS:
        assert type_for_key(KeyLayout.sim(topic)) is SIM_TOPICS[topic]


def test_bad_names():
    with pytest.raises(ValueError):
        KeyLayout("r/1")
    with pytest.raises(KeyError, match="unknown robot topic"):
        KeyLayout().robot("scna")


def test_selectors():
    assert split_selector("omninav/r1/plan;start=0,0;goal=1,2") == ("omninav/r1/plan", {"start": "0,0", "goal": "1,2"})
    assert split_selector("omninav/r1/plan?start=0,0") == ("omninav/r1/plan", {"start": "0,0"})
    assert split_selector("omninav/r1/map") == ("omninav/r1/map", {})
    assert join_selector("k", {"a": "1", "b": "2"}) == "k?a=1;b=2"
