import re
from dataclasses import dataclass

import pytest

from omninav.services.runtime.params import load_params_file, parse_overrides
from omninav.parameters.declare import Parameters, ParamError, Rule, group, param
from omninav.parameters.from_mapping import load_params


@dataclass(frozen=True)
class Example:
    min_particles: int = 100
    kld_err: float = 0.01
    odom_model_type: str = "diff"
    tf_broadcast: bool = True
    footprint: tuple[tuple[float, float], ...] = ((0.0, 0.0),)


def test_defaults_and_int_to_float():
    p = load_params(Example, {"kld_err": 1})
    assert p.kld_err == 1.0 and isinstance(p.kld_err, float) and p.min_particles == 100


@pytest.mark.parametrize("values,needle", [
    ({"min_particle": 5}, "unknown parameter 'min_particle' (did you mean 'min_particles'?)"),
    ({"min_particles": 5.5}, "'min_particles' must be an integer"),
    ({"min_particles": True}, "'min_particles' must be an integer"),
    ({"tf_broadcast": "yes"}, "'tf_broadcast' must be true or false"),
    ({"kld_err": "x"}, "'kld_err' must be a number"),
    ({"kld_err": float("nan")}, "'kld_err' must be finite"),
    ({"footprint": [[1, 2], [3]]}, "'footprint' must have 2 items"),
])
def test_errors_name_the_parameter_and_source(values, needle):
    with pytest.raises(ParamError) as err:
        load_params(Example, values, "amcl.yaml")
    assert needle in str(err.value) and "amcl.yaml" in str(err.value)


def test_ros1_and_ros2_files_load(tmp_path):
    ros2 = tmp_path / "ros2.yaml"
    ros2.write_text("amcl:\n  ros__parameters:\n    min_particles: 500\n    footprint: [[0.4, 0.3], [-0.4, 0.3]]\n")
    assert load_params_file(Example, ros2, "amcl").min_particles == 500
    assert load_params_file(Example, ros2).footprint == ((0.4, 0.3), (-0.4, 0.3))
    ros1 = tmp_path / "ros1.yaml"
    ros1.write_text("amcl:\n  odom_model_type: omni\n")
    assert load_params_file(Example, ros1, "amcl").odom_model_type == "omni"


def test_missing_and_broken_files(tmp_path):
    with pytest.raises(ParamError, match="no such file"):
        load_params_file(Example, tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1,\n")
    with pytest.raises(ParamError, match="not valid YAML"):
        load_params_file(Example, bad)
    listy = tmp_path / "list.yaml"
    listy.write_text("- 1\n")
    with pytest.raises(ParamError, match="expected a mapping"):
        load_params_file(Example, listy)


def test_overrides():
    assert parse_overrides(["a=1", "b=x", "c=[1, 2]"]) == {"a": 1, "b": "x", "c": [1, 2]}
    with pytest.raises(ParamError):
        parse_overrides(["novalue"])


@dataclass(frozen=True)
class Ranged(Parameters):
    delay_s: float = param(0.0, ge=0)
    rate_hz: float = param(1.0, gt=0)
    samples: int = param(1, ge=1)
    share: float = param(0.5, ge=0, le=1)
    mode: str = param("a", choices=("a", "b"))
    frame: str = param("map", nonempty=True)
    offset: tuple[float, ...] = param((0.0, 0.0), items=2, finite=True)
    outline: tuple[tuple[float, float], ...] = param((), min_items=3, or_empty=True)
    gains: tuple[float, ...] = param((1.0,), ge=0)
    limit: float | None = param(None, gt=0)
    low: float = 0.0

    rules = (Rule("low", lambda p: p.low <= p.rate_hz, "≤ rate_hz ({p.rate_hz})"),)


@dataclass(frozen=True)
class MoreRanged(Ranged):
    high: float = param(2.0, finite=True)

    rules = (Rule("high", lambda p: p.high >= p.low, "≥ low ({p.low})"),)


@pytest.mark.parametrize("values,needle", [
    ({"delay_s": -0.1}, "parameter delay_s must be ≥ 0, got -0.1"),
    ({"rate_hz": 0.0}, "parameter rate_hz must be > 0, got 0.0"),
    ({"samples": 0}, "parameter samples must be ≥ 1, got 0"),
    ({"share": 1.5}, "parameter share must be in [0, 1], got 1.5"),
    ({"mode": "c"}, "parameter mode must be one of 'a', 'b', got 'c'"),
    ({"frame": ""}, "parameter frame must be non-empty, got ''"),
    ({"offset": [1.0]}, "parameter offset must be 2 items, got (1.0,)"),
    ({"outline": [[0, 0], [1, 0]]}, "parameter outline must be empty or at least 3 items"),
    ({"gains": [1.0, -1.0]}, "parameter gains must be a list of numbers each ≥ 0, got (1.0, -1.0)"),
    ({"limit": 0.0}, "parameter limit must be > 0, got 0.0"),
    ({"low": 2.0}, "parameter low must be ≤ rate_hz (1.0), got 2.0"),
    ({"high": -1.0}, "parameter high must be ≥ low (0.0), got -1.0"),
])
def test_each_declared_constraint_is_one_line_naming_the_parameter_the_allowed_and_the_value(values, needle):
    assert load_params(MoreRanged, {}) == MoreRanged()
    with pytest.raises(ParamError, match="^" + re.escape(f"ranged: {needle}")):
        load_params(MoreRanged, values, "ranged")
    with pytest.raises(ParamError, match="^" + re.escape(needle)):     # built in code: the same check
        MoreRanged(**{k: tuple(map(tuple, v)) if k == "outline" else tuple(v) if isinstance(v, list) else v
                      for k, v in values.items()})


def test_what_a_field_allows_passes():
    p = load_params(MoreRanged, {"outline": [[0, 0], [1, 0], [0, 1]], "limit": 3, "share": 1, "mode": "b",
                                 "gains": [], "low": 1.0, "high": 1.0})
    assert p.outline == ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)) and p.limit == 3.0


def test_an_unknown_name_is_refused_naming_it_and_the_known_ones():
    with pytest.raises(ParamError, match=r"^ranged: MoreRanged: unknown parameter 'rate_h' \(did you mean 'rate_hz'\?\); "
                                         r"known: delay_s, frame, gains, high, limit, low, mode, offset, outline, "
                                         r"rate_hz, samples, share$"):
        load_params(MoreRanged, {"rate_h": 2}, "ranged")


def test_a_group_is_built_from_the_larger_class_that_includes_it():
    assert group(MoreRanged(rate_hz=3.0, high=4.0), Ranged) == Ranged(rate_hz=3.0)
