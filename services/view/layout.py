"""The Foxglove layout shipped in docs/foxglove/omninav_layout.json, built with foxglove-sdk's layout types
from the view's own topic names, so the file and the channels cannot drift apart (a test compares them).

    python -m omninav.services.view.layout docs/foxglove/omninav_layout.json     # after changing the view

A 3D panel in the map frame with the grids, scan, robot, movers, tracks, plans, goals and the localizer, whose
"Publish pose" tool sends goals on the view's goal channel; beside it the transform tree and one tab
per service's Diagnostic.
"""
from __future__ import annotations

import json
import sys

import foxglove.layouts as fl

from .convert import DIAGNOSTICS_TOPIC, MAP_FRAME
from .node import GOAL_TOPIC

DIAGNOSED_SERVICES = ("navigator", "localizer", "costmap", "global_planner", "local_planner", "sim", "view")


def _poses(color_from: str, color_to: str, kind: str = "line") -> fl.BaseRendererPosesTopicSettings:
    return fl.BaseRendererPosesTopicSettings(visible=True, type=kind, line_width=0.05, gradient=(color_from, color_to))


def three_d_panel() -> fl.ThreeDeePanel:
    topics = {
        "/map": fl.BaseRendererGridTopicSettings(visible=True, color_mode="gradient", color_field="occupancy",
                                                 gradient=("#ffffffff", "#000000ff"), min_value=0, max_value=100,
                                                 draw_behind=True),
        "/costmap/global": fl.BaseRendererGridTopicSettings(visible=True, color_mode="colormap", color_field="cost",
                                                            color_map="turbo", explicit_alpha=0.35, min_value=0,
                                                            max_value=254),
        "/costmap/local": fl.BaseRendererGridTopicSettings(visible=True, color_mode="colormap", color_field="cost",
                                                           color_map="turbo", explicit_alpha=0.5, min_value=0,
                                                           max_value=254),
        "/scan": fl.BaseRendererLaserScanTopicSettings(visible=True, point_size=4, point_shape="circle",
                                                       cube_outline=False, color_mode="flat", flat_color="#ff2020ff"),
        "/truth/robot": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
        "/truth/movers": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
        "/tracks": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
        "/plan": _poses("#2060ffff", "#20c0ffff"),
        "/local_plan": _poses("#ff9000ff", "#ffd000ff"),
        "/goal": _poses("#c000c0ff", "#c000c0ff", kind="arrow"),
        "/localizer/pose": fl.BaseRendererPoseTopicSettings(visible=True, type="arrow", color="#00a0a0ff"),
        "/localizer/particles": _poses("#80808080", "#80808080", kind="arrow"),
    }
    return fl.ThreeDeePanel(title="omninav", config=fl.ThreeDeeConfig(
        topics=topics, fixed_frame=MAP_FRAME, follow_tf=MAP_FRAME, follow_mode="follow-none",
        publish=fl.ThreeDeePublishSettings(type="pose", pose_topic=GOAL_TOPIC)))


def layout() -> fl.Layout:
    diagnostics = fl.TabContainer(selected_tab_index=0, tabs=[
        fl.TabItem(title=service, content=fl.RawMessagesPanel(config=fl.RawMessagesConfig(
            topic_path=f"{DIAGNOSTICS_TOPIC}/{service}", expansion="all")))
        for service in DIAGNOSED_SERVICES])
    side = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=1, content=fl.TransformTreePanel()),
        fl.SplitItem(proportion=2, content=diagnostics)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=three_d_panel()),
        fl.SplitItem(proportion=1, content=side)]))


def layout_json() -> str:
    """Indented, so a change to the layout reads well in a diff."""
    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


if __name__ == "__main__":
    with open(sys.argv[1], "w") as out:
        out.write(layout_json())
