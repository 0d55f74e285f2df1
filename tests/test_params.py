from dataclasses import dataclass

import pytest

from omninav.services.runtime.params import (ParamError, load_params, load_params_file, parse_overrides, require_at_least,
                                             require_nonnegative, require_positive)


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
class Ranged:
    delay_s: float = 0.0
    rate_hz: float = 1.0
    samples: int = 1

    def __post_init__(self):
        require_nonnegative(self, "delay_s")
        require_positive(self, "rate_hz")
        require_at_least(self, 1, "samples")


@pytest.mark.parametrize("values,needle", [
    ({"delay_s": -0.1}, "delay_s must be zero or positive, got -0.1"),
    ({"rate_hz": 0}, "rate_hz must be positive, got 0.0"),
    ({"samples": 0}, "samples must be ≥ 1, got 0"),
])
def test_range_checks_name_the_parameter_and_its_value(values, needle):
    assert load_params(Ranged, {}) == Ranged()
    with pytest.raises(ParamError, match=f"^ranged: {needle}$"):
        load_params(Ranged, values, "ranged")
