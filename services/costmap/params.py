"""Costmap parameters with ROS costmap_2d's names and defaults, and a loader for ROS parameter files.

Names and defaults are those of ROS 1 noetic costmap_2d (Costmap2DROS, StaticLayer, ObstacleLayer,
InflationLayer). ROS parameter files load unchanged:

- ROS 1 move_base layout: a common file (flat, loaded into both costmaps) plus files that nest
  the costmap's own values under `global_costmap:` / `local_costmap:`.
- Hydro and later `plugins: [{name: ..., type: costmap_2d::...}]` with one section per plugin
  name, or the pre-Hydro layout without `plugins` (static layer when `static_map: true`, then the
  obstacle and inflation layers, fed from the costmap-level values), exactly as Costmap2DROS
  decides.
- ROS 2 wrapping (`global_costmap: global_costmap: ros__parameters:`) and Nav2's plugin list of
  names whose section gives the type as `plugin:`.

ROS 1 quirks kept on purpose, so a file means here what it meant on a ROS robot: a value given at
the costmap level is copied into every plugin of the matching type and wins over that plugin's own
(Costmap2DROS::copyParentParameters); an observation source's obstacle_range and raytrace_range are
searched upwards (source, layer, costmap, then 2.5 / 3.0 m).

Names ROS or Nav2 accept that mean nothing for a 2-D laser costmap (voxel settings, obstacle heights,
topic wiring handled by the node) are listed in IGNORED and accepted without effect, with a warning
naming them; so is a plugin's section that the plugin list does not name (Nav2 never reads it);
anything else unknown is an error naming the key and the file, with the closest known name.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import yaml

from ..runtime.params import read_yaml, sample_or_given
from ...parameters.declare import Parameters, ParamError, Rule, param
from ...parameters.from_mapping import load_params, unknown_names

_log = logging.getLogger("omninav.params")

COSTMAP_NAMES = ("global_costmap", "local_costmap")
DEFAULT_OBSTACLE_RANGE = 2.5   # m, ObstacleLayer's fallback when no level sets obstacle_range
DEFAULT_RAYTRACE_RANGE = 3.0   # m

# Accepted for compatibility, no effect here (why, in docs/costmap_and_planner.md).
IGNORED = {
    "costmap": {"map_type", "publish_voxel_map", "origin_z", "z_resolution", "z_voxels",
                "unknown_threshold", "mark_threshold", "footprint_topic", "published_footprint_topic",
                "use_sim_time", "max_obstacle_height", "map_vis_z"},
    "obstacle": {"max_obstacle_height", "publish_voxel_map", "origin_z", "z_resolution", "z_voxels",
                 "unknown_threshold", "mark_threshold", "transform_tolerance", "footprint_scale"},
    # Nav2's min ranges: a laser's readings below range_min are dropped already
    "source": {"min_obstacle_height", "max_obstacle_height", "expected_update_rate", "obstacle_min_range",
               "raytrace_min_range"},
    "layer": {"use_sim_time", "map_subscribe_transient_local"},
}
# Nav2 spells two observation-source ranges differently.
SOURCE_ALIASES = {"obstacle_max_range": "obstacle_range", "raytrace_max_range": "raytrace_range"}


def _unique_names(items) -> bool:
    names = [item.name for item in items]
    return len(set(names)) == len(names)


@dataclass(frozen=True)
class ObservationSource(Parameters):
    """One sensor of an obstacle layer (ROS: the section named in observation_sources)."""
    name: str
    topic: str = ""                                             # ROS default: the source's name
    sensor_frame: str = ""                                      # "" = the frame the scan's header names
    data_type: str = param("LaserScan", choices=("LaserScan",))  # only laser scans reach this costmap (ROS default PointCloud)
    marking: bool = True
    clearing: bool = False
    obstacle_range: float = param(DEFAULT_OBSTACLE_RANGE, ge=0)  # m, mark hits nearer than this
    raytrace_range: float = param(DEFAULT_RAYTRACE_RANGE, ge=0)  # m, clear free space out to this
    inf_is_valid: bool = False                                  # +inf readings clear out to range_max
    observation_persistence: float = param(0.0, ge=0)           # s; 0 keeps only the latest scan

    def __post_init__(self):
        if not self.topic:
            object.__setattr__(self, "topic", self.name)
        super().__post_init__()


@dataclass(frozen=True)
class StaticLayerParams(Parameters):
    name: str = "static_layer"
    enabled: bool = True
    map_topic: str = "map"
    first_map_only: bool = False
    subscribe_to_updates: bool = False
    track_unknown_space: bool = True                       # map's unknown cells stay NO_INFORMATION
    use_maximum: bool = False                              # combine by max instead of overwriting
    lethal_cost_threshold: int = param(100, ge=0, le=100)  # map values at or above are lethal
    unknown_cost_value: int = -1                           # the map value meaning unknown
    trinary_costmap: bool = True                           # everything below lethal is free (else scaled)


@dataclass(frozen=True)
class ObstacleLayerParams(Parameters):
    name: str = "obstacle_layer"
    enabled: bool = True
    track_unknown_space: bool | None = None             # None: the costmap's track_unknown_space
    footprint_clearing_enabled: bool = True
    combination_method: int = param(1, choices=(0, 1))  # 0 overwrite, 1 maximum
    observation_sources: tuple[ObservationSource, ...] = ()
    # ours, no ROS names: hits on the tracker's moving obstacles are not marked (the local planner
    # meets those where they will be); the costmap then takes the tracks. Slower tracks stay marked
    # (the local planner leaves them to the costmap: its dynamic_min_speed)
    skip_tracked: bool = False
    skip_tracked_min_speed: float = param(0.1, ge=0)    # m/s

    rules = (Rule("observation_sources", lambda p: _unique_names(p.observation_sources), "of different names",
                  shown=lambda p: [s.name for s in p.observation_sources]),)


@dataclass(frozen=True)
class InflationLayerParams(Parameters):
    name: str = "inflation_layer"
    enabled: bool = True
    inflation_radius: float = param(0.55, ge=0)     # m
    cost_scaling_factor: float = param(10.0, ge=0)  # 1/m, exponential decay beyond the inscribed radius
    inflate_unknown: bool = False                   # let inflation overwrite unknown cells below inscribed cost


@dataclass(frozen=True)
class KeepoutLayerParams(Parameters):
    """Keepout zones and speed limits from mask images (map_server YAML files, in the map frame),
    after Nav2's keepout and speed filters. Keepout cells (mask value ≥ 100) are lethal; a speed
    mask value v in 1..100 limits the speed to speed_limit_base + speed_limit_multiplier·v
    (percent of the maximum speed, or m/s when speed_limit_percentage is false); 0 and unknown
    cells have no limit."""
    name: str = "keepout_layer"
    enabled: bool = True
    mask: str = ""              # map YAML of the keepout mask ("" = none)
    speed_limit_mask: str = ""  # map YAML of the speed mask ("" = none)
    speed_limit_base: float = param(0.0, finite=True)
    speed_limit_multiplier: float = param(1.0, finite=True)
    speed_limit_percentage: bool = True


@dataclass(frozen=True)
class MoverLayerParams(Parameters):
    """The tracker's moving obstacles, stamped where they will walk (mover_layer.py); no ROS
    counterpart (social_navigation_layers' passing layer is the nearest)."""
    name: str = "mover_layer"
    enabled: bool = True
    prediction_time: float = param(5.0, gt=0)          # s of each track's way ahead that is stamped
    sweep_cost: int = param(200, ge=1, le=252)         # of every cell of that way (below 253: dear, not closed)
    margin: float = param(0.1, ge=0)                   # m beyond the track's radius plus the robot's inscribed radius
    behind_time: float = param(2.0, ge=0)              # s of the way just walked that is stamped too (people turn round)
    min_speed: float = param(0.1, ge=0)                # m/s: slower tracks are left to the obstacle layer


LayerParams = Union[StaticLayerParams, ObstacleLayerParams, InflationLayerParams, KeepoutLayerParams, MoverLayerParams]

LAYER_TYPES: dict[str, type] = {
    "costmap_2d::StaticLayer": StaticLayerParams,
    "costmap_2d::ObstacleLayer": ObstacleLayerParams,
    "costmap_2d::VoxelLayer": ObstacleLayerParams,   # a 2-D laser fills every voxel column alike
    "costmap_2d::InflationLayer": InflationLayerParams,
    "nav2_costmap_2d::StaticLayer": StaticLayerParams,
    "nav2_costmap_2d::ObstacleLayer": ObstacleLayerParams,
    "nav2_costmap_2d::VoxelLayer": ObstacleLayerParams,
    "nav2_costmap_2d::InflationLayer": InflationLayerParams,
    "omninav::KeepoutLayer": KeepoutLayerParams,
    "omninav::MoverLayer": MoverLayerParams,
}


@dataclass(frozen=True)
class CostmapParams(Parameters):
    """One costmap (Costmap2DROS). width/height are metres (ROS declares them int but files often
    write 6.0); they size a rolling window, or a costmap without a static map."""
    global_frame: str = "map"
    robot_base_frame: str = "base_link"
    transform_tolerance: float = param(0.3, ge=0)               # s
    update_frequency: float = param(5.0, ge=0)                  # Hz, sim time
    publish_frequency: float = param(0.0, ge=0)                 # Hz, sim time; 0 = never
    rolling_window: bool = False
    track_unknown_space: bool = False
    always_send_full_costmap: bool = False
    width: float = param(10.0, gt=0)                            # m
    height: float = param(10.0, gt=0)                           # m
    resolution: float = param(0.05, gt=0)                       # m/cell
    origin_x: float = 0.0                                       # m
    origin_y: float = 0.0                                       # m
    footprint: tuple[tuple[float, float], ...] = param((), min_items=3, or_empty=True)  # polygon in the robot frame; () = robot_radius
    robot_radius: float = param(0.46, ge=0)                     # m
    footprint_padding: float = param(0.01, ge=0)                # m
    # pre-Hydro default plugin set (no static map unless static_map: true)
    layers: tuple[LayerParams, ...] = field(default_factory=lambda: (ObstacleLayerParams(), InflationLayerParams()))

    rules = (Rule("layers", lambda p: _unique_names(p.layers), "of different names",
                  shown=lambda p: [layer.name for layer in p.layers]),
             Rule("layers", lambda p: sum(isinstance(layer, InflationLayerParams) and layer.enabled
                                          for layer in p.layers) <= 1, "at most one inflation layer",
                  shown=lambda p: [layer.name for layer in p.layers]))

    def layer(self, kind: type) -> Any:
        """The first enabled layer of a params type, or None."""
        return next((l for l in self.layers if isinstance(l, kind) and l.enabled), None)


# ---------------------------------------------------------------- loading ROS files

def _merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def _unwrap_ros2(section: Any, name: str) -> Any:
    if isinstance(section, dict) and isinstance(section.get(name), dict) and len(section) == 1:
        section = section[name]                      # global_costmap: global_costmap: ros__parameters:
    if isinstance(section, dict) and "ros__parameters" in section:
        section = section["ros__parameters"] or {}
    return section


def costmap_section(doc: dict, name: str, source: str) -> dict:
    """What a parameter file says about costmap `name`: its `name:` section when the file has
    costmap sections, else (a common file) the whole mapping."""
    doc = _unwrap_ros2(doc, name)
    if any(key in doc for key in (*COSTMAP_NAMES, name)):
        section = _unwrap_ros2(doc.get(name) or {}, name)
    else:
        section = doc
    if not isinstance(section, dict):
        raise ParamError(f"{source}: {name}: expected a mapping of parameters, got {section!r}")
    return section


def load_costmap_params(paths, name: str = "global_costmap") -> CostmapParams:
    """Load costmap `name` from ROS parameter files, later files overriding earlier ones, as
    move_base's `rosparam load` lines do (common file first)."""
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    merged: dict = {}
    for path in paths:
        doc = read_yaml(sample_or_given(path))
        if not isinstance(doc, dict):
            raise ParamError(f"{path}: expected a mapping of parameter names to values")
        merged = _merge(merged, costmap_section(doc, name, str(path)))
    return costmap_params_from_mapping(merged, ", ".join(map(str, paths)) + f": {name}")


def _footprint(value: Any, source: str) -> Any:
    """ROS 1 also accepts the footprint as a string '[[x, y], ...]'."""
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError:
            raise ParamError(f"{source}: parameter 'footprint' is not a list of [x, y] points: {value!r}") from None
    return value if value else ()


def _plugins(value: Any, mapping: dict, source: str) -> list[tuple[str, str]]:
    if not isinstance(value, list):
        raise ParamError(f"{source}: 'plugins' must be a list, got {value!r}")
    out = []
    for item in value:
        if isinstance(item, dict) and {"name", "type"} <= set(item):      # ROS 1
            out.append((str(item["name"]), str(item["type"])))
        elif isinstance(item, str) and isinstance(mapping.get(item), dict) and "plugin" in mapping[item]:
            out.append((item, str(mapping[item]["plugin"])))               # Nav2
        else:
            raise ParamError(f"{source}: plugin entry {item!r} is neither {{name, type}} nor a name "
                             "whose section gives `plugin:`")
    return out


def _source_names(value: Any, source: str) -> list[str]:
    if isinstance(value, list):
        return [str(v) for v in value]
    if isinstance(value, str):
        return value.split()
    raise ParamError(f"{source}: 'observation_sources' must be a space-separated string, got {value!r}")


def _without(values: dict, ignored: set[str], source: str) -> dict:
    """values less the names accepted without effect, which a warning lists."""
    dropped = sorted(set(values) & ignored)
    if dropped:
        _log.warning("%s: parameters accepted without effect (nothing to do for a 2-D laser costmap): %s",
                     source, ", ".join(dropped))
    return {k: v for k, v in values.items() if k not in ignored}


def _obstacle_layer(name: str, section: dict, parent: dict, source: str) -> ObstacleLayerParams:
    where = f"{source}/{name}"
    names = _source_names(section.get("observation_sources", ""), where)
    sources = []
    for src in names:
        raw = section.get(src)
        if not isinstance(raw, dict):
            raise ParamError(f"{where}: observation source {src!r} has no section of parameters")
        values = {SOURCE_ALIASES.get(k, k): v for k, v in raw.items()}
        for key in ("obstacle_range", "raytrace_range"):   # ROS searchParam: source, layer, costmap
            for level in (section, parent):
                if key not in values and key in level:
                    values[key] = level[key]
        sources.append(load_params(ObservationSource, {**_without(values, IGNORED["source"], f"{where}/{src}"),
                                                       "name": src}, f"{where}/{src}"))
    own = {k: v for k, v in section.items()
           if k not in names and k not in ("observation_sources", "obstacle_range", "raytrace_range", "plugin")}
    own = _without(own, IGNORED["obstacle"] | IGNORED["layer"], where)
    return load_params(ObstacleLayerParams, {**own, "name": name, "observation_sources": tuple(sources)}, where)


# costmap-level names Costmap2DROS copies into plugins of each type (copyParentParameters)
_PARENT_COPIES = {
    StaticLayerParams: ("map_topic", "unknown_cost_value", "lethal_cost_threshold", "track_unknown_space"),
    ObstacleLayerParams: ("raytrace_range", "obstacle_range", "track_unknown_space", "skip_tracked",
                          "skip_tracked_min_speed"),
    InflationLayerParams: ("cost_scaling_factor", "inflation_radius"),
    KeepoutLayerParams: (),
    MoverLayerParams: (),
}
_PARENT_COPIES_ALL = {key for keys in _PARENT_COPIES.values() for key in keys}


def _layer(name: str, kind: type, section: dict, parent: dict, source: str) -> LayerParams:
    section = dict(section)
    for key in _PARENT_COPIES[kind]:
        if key in parent:
            section[key] = parent[key]
    if kind is ObstacleLayerParams:
        return _obstacle_layer(name, section, parent, source)
    values = _without({k: v for k, v in section.items() if k != "plugin"}, IGNORED["layer"], f"{source}/{name}")
    return load_params(kind, {**values, "name": name}, f"{source}/{name}")


def costmap_params_from_mapping(mapping: dict, source: str = "costmap") -> CostmapParams:
    """CostmapParams from one costmap's merged parameter mapping (ROS 1, Hydro+ or pre-Hydro, or
    Nav2 plugin layout)."""
    mapping = dict(mapping or {})
    top_names = {f for f in CostmapParams.__dataclass_fields__ if f != "layers"}
    if "plugins" in mapping:
        specs = _plugins(mapping["plugins"], mapping, source)
        section_names = {n for n, _ in specs}
        layers = []
        for layer_name, type_name in specs:
            kind = LAYER_TYPES.get(type_name)
            if kind is None:
                raise ParamError(f"{source}: plugin {layer_name!r}: type {type_name!r} is not supported; "
                                 f"known: {sorted(LAYER_TYPES)}")
            section = mapping.get(layer_name) or {}
            if not isinstance(section, dict):
                raise ParamError(f"{source}: plugin {layer_name!r}: expected a section of parameters")
            layers.append(_layer(layer_name, kind, section, mapping, source))
        # a common file's pre-Hydro observation sources: ROS reads sources only inside the
        # obstacle layer's own section, so with plugins these are ignored, as there
        consumed = section_names | {"plugins", "static_map", "observation_sources"} | _PARENT_COPIES_ALL
        sources_here = set(_source_names(mapping.get("observation_sources", ""), source))
    else:
        # pre-Hydro: Costmap2DROS::loadOldParameters builds the plugin list from top-level values
        layers = []
        if mapping.get("static_map") is True:
            layers.append(_layer("static_layer", StaticLayerParams, {}, mapping, source))
        sources_here = set(_source_names(mapping.get("observation_sources", ""), source))
        obstacle_section = {k: mapping[k] for k in ("observation_sources", *sources_here) if k in mapping}
        layers.append(_layer("obstacle_layer", ObstacleLayerParams, obstacle_section, mapping, source))
        layers.append(_layer("inflation_layer", InflationLayerParams, {}, mapping, source))
        consumed = {"static_map", "observation_sources"} | _PARENT_COPIES_ALL
    # a layer's section the plugin list does not name: Nav2 and ROS never read it
    unused_sections = {k for k, v in mapping.items() if isinstance(v, dict) and "plugins" in mapping} - consumed
    rest = _without({k: v for k, v in mapping.items() if k not in consumed | sources_here},
                    IGNORED["costmap"] | unused_sections, source)
    problem = unknown_names(rest, top_names | consumed, "parameter")
    if problem:
        raise ParamError(f"{source}: {problem} (and the plugins' and the sources' sections)")
    values = {k: v for k, v in mapping.items() if k in top_names}
    if "footprint" in values:
        values["footprint"] = _footprint(values["footprint"], source)
    return load_params(CostmapParams, {**values, "layers": tuple(layers)}, source)

