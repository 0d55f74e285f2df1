"""Global planner parameters with ROS global_planner's names and defaults (plus the smoother's).

ROS files load unchanged: names global_planner reads that have no meaning for this planner
(the potential-field interpolation and publishing settings) are in IGNORED and accepted without
effect; anything else unknown is an error naming the key. Nav2's planner_server files load too (NAV2:
the one plugin of planner_plugins, NavFn, flattened; `tolerance` is default_tolerance, `use_astar`
the opposite of use_dijkstra).
"""
from __future__ import annotations

from dataclasses import dataclass

from ..runtime.params import ForeignNames
from ...parameters.from_mapping import load_params
from ...parameters.declare import Parameters, param

ORIENTATION_MODES = {0: "none", 1: "forward", 2: "interpolate", 3: "forward_then_interpolate",
                     4: "backward", 5: "leftward", 6: "rightward"}

# ROS global_planner settings of its potential field and its topics: no effect on a graph search.
IGNORED = frozenset({"old_navfn_behavior", "use_quadratic", "planner_window_x", "planner_window_y",
                     "publish_scale", "publish_potential", "planner_costmap_publish_frequency", "use_sim_time"})

NAV2 = ForeignNames(
    stack="Nav2", node="planner_server", plugin_list="planner_plugins",
    plugin_types=frozenset({"nav2_navfn_planner/NavfnPlanner", "nav2_navfn_planner::NavfnPlanner"}),
    renames={"tolerance": "default_tolerance", "use_astar": "use_dijkstra"},
    convert={"use_astar": lambda use_astar: not use_astar if isinstance(use_astar, bool) else use_astar},
    # the server's rate (replanning is the navigator's planner_frequency here), the plan's last pose
    # orientation (orientation_mode says it), sim time (always)
    ignored=frozenset({"expected_planner_frequency", "use_final_approach_orientation", "use_sim_time"}))


@dataclass(frozen=True)
class GlobalPlannerParams(Parameters):
    use_dijkstra: bool = True                                   # Dijkstra; false: A* (same optimal cost, fewer cells expanded)
    use_grid_path: bool = False                                 # true: the raw 8-connected cell path, unsmoothed
    allow_unknown: bool = True                                  # plan through NO_INFORMATION cells
    default_tolerance: float = param(0.0, ge=0)                 # m: a goal in an obstacle (or unreachable) may move this far
    neutral_cost: int = param(50, ge=1, le=255)                 # cost of a free step (per cell length)
    cost_factor: float = param(3.0, ge=0)                       # each costmap cost adds cost_factor × cost per cell length
    lethal_cost: int = param(253, ge=1, le=255)                 # cells at or above this cost are impassable (unknown aside)
    orientation_mode: int = param(1, choices=tuple(ORIENTATION_MODES))  # ROS OrientationFilter: 0 none … 6 rightward (ORIENTATION_MODES)
    orientation_window_size: int = param(1, ge=1)               # cells either side used for the path direction
    outline_map: bool = True                                    # the costmap's border cells are impassable
    visualize_potential: bool = False                           # return the search's cost-to-come grid with each plan
    # the smoother (not in ROS): gradient smoothing that never moves a point to a costlier cell
    smooth_weight_data: float = param(0.2, ge=0)                # pull towards the original point
    smooth_weight_smooth: float = param(0.3, ge=0)              # pull towards the neighbours' midpoint
    smooth_max_iterations: int = param(100, ge=0)
    smooth_tolerance: float = param(1e-3, ge=0)                 # cells: stop when no point moves more than this

    @classmethod
    def from_mapping(cls, values: dict | None, source: str = "global_planner") -> GlobalPlannerParams:
        """From a ROS parameter mapping, dropping the names in IGNORED, or a Nav2 one (NAV2)."""
        values = NAV2.translate(dict(values or {}), source)
        return load_params(cls, {k: v for k, v in values.items() if k not in IGNORED}, source, NAV2.names)
