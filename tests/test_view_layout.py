"""The shipped Foxglove layout is the one services/view/layout.py builds, and shows the view's topics."""
import json
from pathlib import Path

from omninav.services.view.layout import DIAGNOSED_SERVICES, layout_json
from omninav.services.view.node import GOAL_TOPIC

from view_fixtures import VIEW_CHANNELS

SHIPPED = Path(__file__).resolve().parents[1] / "docs" / "foxglove" / "omninav_layout.json"


def panels(content: dict):
    if content["type"] == "panel":
        yield content
    for item in content.get("items", []) + content.get("tabs", []):
        yield from panels(item["content"])


def test_the_shipped_layout_is_the_built_one_and_opens_the_view_topics():
    assert SHIPPED.read_text() == layout_json(), "run: python -m omninav.services.view.layout " + str(SHIPPED)
    found = list(panels(json.loads(SHIPPED.read_text())["content"]))
    (three_d,) = [p for p in found if p["panelType"] == "ThreeDee"]
    assert set(three_d["config"]["topics"]) == set(VIEW_CHANNELS) - {"/tf", "/diagnostics/costmap"}
    assert three_d["config"]["publish"] == {"type": "pose", "poseTopic": GOAL_TOPIC}
    raw = {p["config"]["topicPath"] for p in found if p["panelType"] == "RawMessages"}
    assert raw == {f"/diagnostics/{service}" for service in DIAGNOSED_SERVICES}
