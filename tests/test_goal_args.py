"""`--goal X Y YAW`: degrees by default, or a unit (90deg, 1.57rad); a bad unit is a usage error naming it."""
import argparse
import math

import pytest

from omninav.cli import demo, navigate
from omninav.cli.goal_args import parse_yaw
from omninav.cli.main import main as cli_main


@pytest.mark.parametrize("text, radians", [
    ("90", math.pi / 2), ("90deg", math.pi / 2), ("-45", -math.pi / 4), ("1.57rad", 1.57), ("-1.57rad", -1.57),
    ("0.5rad", 0.5), ("180 deg", math.pi), (".5rad", 0.5), ("1e1deg", math.radians(10)),
])
def test_a_yaw_is_degrees_unless_it_says_rad(text, radians):
    assert parse_yaw(text) == pytest.approx(radians)


@pytest.mark.parametrize("text", ["90grad", "1.57 radians", "rad", "", "nan", "inf", "90°"])
def test_a_yaw_with_a_bad_unit_names_it(text):
    with pytest.raises(ValueError, match="yaw .* (is not a number with an optional unit deg or rad|is not finite)"):
        parse_yaw(text)


def parsed(module, *argv):
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    return parser.parse_args(list(argv))


def test_navigate_and_demo_take_goals_in_either_unit_even_negative():
    args = parsed(navigate, "--world", "room", "--goal", "3", "-1", "-90", "--goal", "4", "2", "-1.57rad",
                  "--goal", "1", "1", "30deg")
    assert [list(goal) for goal in args.goal] == [[3, -1, pytest.approx(-math.pi / 2)], [4, 2, -1.57],
                                                  [1, 1, pytest.approx(math.pi / 6)]]
    assert parsed(demo, "--goal", "8.3", "3.5", "1.5rad").goal == [(8.3, 3.5, 1.5)]


def test_the_help_says_degrees_are_the_default():
    parser = argparse.ArgumentParser()
    navigate.add_arguments(parser)
    assert "YAW in degrees, or with a unit: 90deg, 1.57rad" in " ".join(parser.format_help().split())


def test_navigate_refuses_a_bad_unit_with_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        cli_main(["navigate", "--world", "room", "--goal", "3", "1", "1.57rd"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "--goal 3 1 1.57rd: yaw '1.57rd' is not a number with an optional unit deg or rad" in err
