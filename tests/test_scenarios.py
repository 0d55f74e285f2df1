"""Generated worlds (experiments/scenarios): one seed always gives the same file; every world of
every kind is fair to the robot, checked here independently of the generator's own check (the
drivable cells form one region holding start and goal, as the shipped worlds are tested); people
walk at human speed and meet the robot on its way; bad requests are one-line errors."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from omninav.cli.main import main as cli_main
from omninav.experiments.scenarios import DYNAMIC_KINDS, EXPLORE_KINDS, KINDS, ScenarioError, generate_world, world_text
from omninav.bench.scenarios import overall, row_line, summary_line
from omninav.experiments.scenarios.route import TIMING
from omninav.services.global_planner.astar import GlobalPlanner
from omninav.services.global_planner.params import GlobalPlannerParams
from omninav.geometry.grid import world_to_cell
from omninav.sim.people.plans import Crowd
from omninav.sim.people.social_force import Obstacles
from omninav.sim.world import load_world, world_from_mapping
from omninav.geometry.polygons import point_segment_distance

SEEDS = range(10)
# walkers (parties with a route) and flows of people per kind
PEOPLE = {"crossing": ((1, 2), 0), "headon": ((1, 1), 0), "overtake": ((1, 1), 0), "crowd": ((4, 6), 0),
          "doorway": ((1, 1), 0), "hall": ((1, 2), 2), "shelves": ((1, 3), 0), "clutter": ((0, 0), 0)}


@pytest.fixture(scope="module")
def worlds(tmp_path_factory):
    """Every kind × seed, written as `omninav scenario generate` writes it and loaded back."""
    folder = tmp_path_factory.mktemp("worlds")
    loaded = {}
    for kind in KINDS:
        for seed in SEEDS:
            path = folder / f"{kind}-{seed}.yaml"
            path.write_text(world_text(generate_world(kind, seed)))
            loaded[kind, seed] = load_world(path)
    return loaded


def test_the_same_seed_gives_the_same_file_and_another_seed_another(tmp_path):
    for kind in KINDS:
        first, again = (tmp_path / f"{kind}-a.yaml", tmp_path / f"{kind}-b.yaml")
        for path in (first, again):
            assert cli_main(["scenario", "generate", "--kind", kind, "--seed", "7", "-o", str(path)]) == 0
        assert first.read_bytes() == again.read_bytes()
        assert world_text(generate_world(kind, 8)) != first.read_text()


def _drivable(world):
    grid = world.rasterize(0.05)
    footprint = world.robot.footprint
    inscribed = point_segment_distance(np.zeros(2), footprint, np.roll(footprint, -1, axis=0)).min()
    clear = ndimage.distance_transform_edt(grid.data == 0) * grid.info.resolution
    return grid, (grid.data == 0) & (clear > inscribed)


@pytest.mark.parametrize("kind", sorted(set(KINDS) - set(EXPLORE_KINDS)))     # a maze has no goal: tests/test_maze.py
def test_every_world_is_solvable(worlds, kind):
    for seed in SEEDS:
        world = worlds[kind, seed]
        ends = np.vstack([world.robot.start, world.goals])
        assert len(world.goals) == 1
        assert world.footprint_clearance(ends).min() > 0.1, (kind, seed)
        assert world.footprint_clearance(ends, world.movers.circles_at(0.0)).min() > 0.1, (kind, seed)
        grid, drivable = _drivable(world)
        labels, _ = ndimage.label(drivable)
        start, goal = (labels[world_to_cell(grid.info, *pose[:2])] for pose in ends)
        assert start != 0 and start == goal, (kind, seed)
        for loop, radius in zip(world.movers.loops, world.movers.radius):     # people walk round furniture
            assert world.distance(loop).min() > radius, (kind, seed)


@pytest.mark.parametrize("kind", sorted(set(KINDS) - set(EXPLORE_KINDS)))
def test_people_walk_at_human_speed_and_their_numbers_fit_the_kind(worlds, kind):
    (low, high), flows = PEOPLE[kind]
    for seed in SEEDS:
        world = worlds[kind, seed]
        people = world.people
        assert len(world.movers) == 0 and low <= len(people.walkers) <= high and len(people.flows) == flows
        for party in [*people.walkers, *people.flows]:
            assert 1.0 <= party.speed[0] <= party.speed[1] <= 1.5 and 0.2 <= party.radius[0] <= party.radius[1] <= 0.25


def _planned_route(world) -> np.ndarray:
    grid, drivable = _drivable(world)
    costs = np.where(drivable, 0, 254).astype(np.uint8)
    plan = GlobalPlanner(GlobalPlannerParams(outline_map=False)).plan(costs, grid.info, world.robot.start, world.goals[0])
    assert plan.ok
    return plan.poses[:, :2]


# the direction (sign of x velocity) a person walks when they meet the robot, where the kind says
MEETING_DIRECTION = {"headon": -1.0, "overtake": 1.0}


def _walked(world, times: np.ndarray) -> np.ndarray:
    """Where the people are (len(times), N, 2) walking without the robot (the social force model
    alone, world's walls and boxes); far away while not in the world."""
    crowd = Crowd(world.people)
    obstacles = Obstacles(world.segments, world.circles)
    out, t, dt = [], 0.0, 0.05
    for when in times:
        while t < when:
            crowd.step(t, dt, obstacles)
            t += dt
        s = crowd.state
        out.append(np.where(s.active[:, None], s.position, 1e6))
    return np.array(out)


@pytest.mark.parametrize("kind", [k for k in DYNAMIC_KINDS if k != "hall"])
def test_a_person_meets_the_robot_on_its_way(worlds, kind):
    """A robot driving its planned way at the expected speed comes within 1 m of a person (its
    centre to the person's body) in most worlds of every dynamic kind — the people are timed to
    meet it — walking towards it in headon and its way in overtake. (hall's flows meet every
    robot that crosses: they fill the hall.)"""
    met = 0
    for seed in SEEDS:
        world = worlds[kind, seed]
        route = _planned_route(world)
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(route, axis=0).T))])
        times = TIMING.start_delay_s + along / TIMING.expected_speed
        where = _walked(world, np.append(times, times[-1] + 0.05))
        radius = Crowd(world.people).state.radius.max()
        gaps = np.hypot(*(where[:-1] - route[:, None]).transpose(2, 0, 1)) - radius     # (route points, people)
        when, who = np.unravel_index(np.argmin(gaps), gaps.shape)
        direction = np.sign(where[when + 1, who, 0] - where[when, who, 0])
        met += gaps[when, who] < 1.0 and direction == MEETING_DIRECTION.get(kind, direction)
    assert met >= 7, f"{kind}: people met the robot in only {met} of {len(SEEDS)} worlds"


def test_unknown_kinds_and_bad_seeds_are_one_line_errors(tmp_path, capsys):
    with pytest.raises(ScenarioError, match="unknown scenario kind .maize.: choose one of building, clutter, crossing"):
        generate_world("maize", 1)
    with pytest.raises(ScenarioError, match="seed must be >= 0"):
        generate_world("crowd", -1)
    assert cli_main(["scenario", "generate", "--kind", "maize", "--seed", "1", "-o", str(tmp_path / "w.yaml")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "unknown scenario kind 'maize'" in err
    assert not (tmp_path / "w.yaml").exists()


def test_bench_figures_over_the_worlds():
    def row(success, robot, mover, approach, time_s, path, plan, status="succeeded", shoved=0):
        return {"world": f"w{len(rows)}", "success": success, "robot_fault_collisions": robot,
                "mover_fault_collisions": mover, "shoved_collisions": shoved,
                "min_mover_clearance_m": approach, "time_s": time_s, "path_length_m": path, "plan_length_m": plan,
                "status": status, "reached": success, "contact_s": 0.25 * (robot + mover),
                "false_successes": int(status == "succeeded" and not success and not robot + mover)}
    rows = []
    for args, kwargs in (((True, 0, 0, 0.4, 20.0, 10.0, 10.0), {}), ((False, 2, 1, 0.0, 60.0, 15.0, 10.0), {}),
                         ((True, 0, 3, 0.0, 30.0, 11.0, 10.0), {"shoved": 1}),
                         ((False, 0, 0, None, 40.0, 1.0, None, "aborted"), {}), ((False, 0, 0, None, 50.0, 5.0, 5.0), {})):
        rows.append(row(*args, **kwargs))
    figures = overall(rows)
    assert figures["success_rate"] == 0.4 and figures["worlds"] == 5
    assert (figures["robot_fault_collisions"], figures["mover_fault_collisions"], figures["worlds_with_robot_fault"]) == (2, 4, 1)
    assert figures["shoved_collisions"] == 1 and figures["contact_s"] == pytest.approx(1.5)
    assert (figures["false_successes"], figures["false_success_worlds"]) == (1, ["w4"])   # said succeeded, not reached
    assert figures["closest_mover_approach_m"] == 0.0 and figures["median_time_s"] == 40.0
    assert figures["median_path_over_plan"] == pytest.approx(1.05)          # of the worlds with a plan
    assert "false successes 1 (w4)" in summary_line(figures) and "FALSE SUCCESS" in row_line(
        {**rows[4], "controller": "dwa", "within_1m_s": None})


def test_bench_scenarios_refuses_an_unknown_kind_or_no_worlds(capsys):
    assert cli_main(["bench", "scenarios", "--kind", "maize"]) == 2
    assert "unknown scenario kind 'maize'" in capsys.readouterr().err
    assert cli_main(["bench", "scenarios", "--kind", "crowd", "--count", "0"]) == 2
    assert "--count and --workers must be >= 1" in capsys.readouterr().err


@pytest.mark.parametrize("kind", EXPLORE_KINDS)
def test_bench_scenarios_refuses_worlds_without_a_goal(kind, tmp_path, capsys):
    # driven, each would end at once and count as a success: every requested goal (none) reached
    assert cli_main(["bench", "scenarios", "--kind", kind, "--count", "1", "-o", str(tmp_path)]) == 2
    assert f"{kind} worlds have no goal to drive to" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_every_kind_to_drive_has_a_goal_and_those_to_explore_none():
    for kind in KINDS:
        goals = world_from_mapping(generate_world(kind, 3), f"<{kind}>").goals
        assert (len(goals) == 0) == (kind in EXPLORE_KINDS), kind
