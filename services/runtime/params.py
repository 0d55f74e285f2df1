"""Parameter files: YAML read with errors that name the file, and the parameter classes
(omninav.parameters: declared and checked there) loaded from them.

ROS parameter files load unchanged: a ROS 2 file ({node: {ros__parameters: {...}}}) or a ROS 1
file (flat, or under the node's name) both give the flat mapping. A service that also reads Nav2's
names describes them with ForeignNames (which section, renames, names without effect here).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import yaml

from ...parameters.declare import ParamError
from ...parameters.from_mapping import load_params


# the checkout's own folder: the sample parameter files (compose/params) that services name by
# default, relative, so that a recording's parameters read the same in any checkout
CHECKOUT = Path(__file__).resolve().parents[2]


def sample_or_given(path: str | Path) -> Path:
    """A relative path not found from the working directory is looked up in the checkout too, as
    ROS finds a package's own files: a service's default parameter files work from any folder."""
    path = Path(path)
    if path.is_absolute() or path.is_file() or not (CHECKOUT / path).is_file():
        return path
    return CHECKOUT / path


def read_yaml(path: str | Path) -> Any:
    path = Path(path)
    if not path.is_file():
        raise ParamError(f"{path}: no such file")
    try:
        return yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ParamError(f"{path}: not valid YAML: {exc}") from None


def unwrap_ros(mapping: dict, node_name: str = "") -> dict:
    """Strip the ROS 2 `node: ros__parameters:` or ROS 1 `node:` wrapping, if present; from a ROS 2
    file of several nodes (a whole nav2_params.yaml), take the named node's section."""
    own = mapping.get(node_name) if node_name else None
    if isinstance(own, dict) and "ros__parameters" in own:
        return own["ros__parameters"] or {}
    if len(mapping) == 1:
        (only_key, inner), = mapping.items()
        if isinstance(inner, dict) and "ros__parameters" in inner:
            return inner["ros__parameters"] or {}
        if only_key == node_name and isinstance(inner, dict):
            return inner
    if "ros__parameters" in mapping:
        return mapping["ros__parameters"] or {}
    return mapping


def load_node_params(params_type: type, values: dict | None, source: str = "parameters") -> Any:
    """A node's Params from a mapping: through its from_mapping when it has one (it reads ROS or Nav2
    names that need more than load_params), else load_params."""
    from_mapping = getattr(params_type, "from_mapping", None)
    return from_mapping(values, source) if from_mapping else load_params(params_type, values, source)


def read_params_mapping(path: str | Path, node_name: str = "") -> dict:
    """The flat parameter mapping of a ROS 1 or ROS 2 style YAML file."""
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ParamError(f"{path}: expected a mapping of parameter names to values")
    return unwrap_ros(data, node_name)


def load_params_file(cls: type, path: str | Path, node_name: str = "") -> Any:
    return load_params(cls, read_params_mapping(path, node_name), str(path))


def parse_overrides(pairs: list[str]) -> dict:
    """`name=value` strings (values parsed as YAML scalars) into a mapping."""
    out = {}
    for pair in pairs:
        name, sep, raw = pair.partition("=")
        if not sep or not name:
            raise ParamError(f"override {pair!r} is not name=value")
        out[name] = yaml.safe_load(raw)
    return out


# ---------------------------------------------------------------- another stack's parameter files (Nav2)

_log = logging.getLogger("omninav.params")


@dataclass(frozen=True)
class ForeignNames:
    """How a service reads another stack's parameter file unchanged (Nav2's): the node section it
    takes from a whole-stack file (`amcl: ros__parameters:` among the others), the plugin section it
    flattens (`GridBased:` named by `planner_plugins`), the names that mean one of ours (renames; a
    value converter where the meaning differs), and the names it knows but does not implement
    (accepted without effect, listed in a warning). Any other name goes on to load_params, which
    refuses an unknown one naming it."""
    stack: str                                          # "Nav2", for messages
    node: str                                           # the node's section in a whole-stack file
    renames: Mapping[str, str] = field(default_factory=dict)
    convert: Mapping[str, Callable[[Any], Any]] = field(default_factory=dict)   # by the foreign name
    ignored: frozenset[str] = frozenset()
    plugin_list: str = ""                               # e.g. "planner_plugins": its one entry is flattened
    plugin_types: frozenset[str] = frozenset()          # the plugin types this service implements
    # names whose value names sections this service does not implement (goal_checker_plugins: their
    # sections are ignored too)
    naming_ignored_sections: frozenset[str] = frozenset()

    @property
    def names(self) -> set[str]:
        """Every foreign name this knows (for did-you-mean)."""
        return set(self.renames) | set(self.ignored) | set(self.naming_ignored_sections)

    def node_section(self, values: dict) -> dict:
        """The node's own mapping when `values` is a whole-stack file, else `values`."""
        section = values.get(self.node)
        if isinstance(section, dict) and "ros__parameters" in section:
            return dict(section["ros__parameters"] or {})
        return values

    def translate(self, values: dict, source: str) -> dict:
        """Our names for a mapping that may use the foreign stack's; warns listing the ignored ones."""
        values = self.node_section(dict(values))
        if self.plugin_list and self.plugin_list in values:
            values = self._flatten_plugin(values, source)
        out: dict = {}
        ignored = []
        ignored_sections = {str(section) for name in self.naming_ignored_sections
                            for section in _as_list(values.get(name))}
        for name, value in values.items():
            if name in self.ignored or name in self.naming_ignored_sections or name in ignored_sections:
                ignored.append(name)
                continue
            ours = self.renames.get(name, name)
            if name in self.convert:
                try:
                    value = self.convert[name](value)
                except (ValueError, TypeError) as exc:
                    raise ParamError(f"{source}: parameter {name!r}: {exc}") from None
            if ours in out and out[ours] != value:
                raise ParamError(f"{source}: {ours} is given twice ({name}: {value!r}, and {out[ours]!r})")
            out[ours] = value
        if ignored:
            _log.warning("%s: %s parameters accepted without effect (omninav does not implement them): %s",
                         source, self.stack, ", ".join(sorted(ignored)))
        return out

    def _flatten_plugin(self, values: dict, source: str) -> dict:
        plugins = values.pop(self.plugin_list)
        if not (isinstance(plugins, list) and len(plugins) == 1 and isinstance(plugins[0], str)):
            raise ParamError(f"{source}: {self.plugin_list} must name one plugin (omninav runs one), got {plugins!r}")
        section = values.pop(plugins[0], None)
        if not isinstance(section, dict):
            raise ParamError(f"{source}: plugin {plugins[0]!r} has no section of parameters")
        section = dict(section)
        kind = section.pop("plugin", "")
        if kind not in self.plugin_types:
            raise ParamError(f"{source}: plugin {plugins[0]!r}: type {kind!r} is not implemented here; "
                             f"known: {', '.join(sorted(self.plugin_types))}")
        for name, value in section.items():
            if name in values and values[name] != value:
                raise ParamError(f"{source}: {name} is given twice ({plugins[0]}.{name}: {value!r}, "
                                 f"and {values[name]!r})")
            values[name] = value
        return values


def _as_list(value: Any) -> list:
    """A list parameter that ROS also accepts as one string."""
    if value is None:
        return []
    return list(value) if isinstance(value, (list, tuple)) else [value]
