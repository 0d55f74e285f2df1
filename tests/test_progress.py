"""Long commands say how far they got (map: frontier goals or laps, mapped share, sim time; navigate:
services starting and up, goals), and --quiet turns that off; progress only reads, so the map is
the same with it or without."""
import json
import re

import numpy as np

from omninav.cli.main import main as cli_main
from omninav.experiments.mapping import MAPPING_ROUTES, build_map, slam_params_for
from omninav.sim.world import load_world, world_path

LINE = re.compile(r"sim (\d+) s: lap 1 of 1, (\d+\.\d) % of the reachable space mapped")


def test_build_map_reports_every_period_of_sim_time_and_maps_the_same_without():
    world = load_world(world_path("room"))
    params = slam_params_for(world, {"particles": 5})
    heard = []
    with_progress = build_map("room", MAPPING_ROUTES["room"], params=params, max_sim_s=4.0,
                              progress=heard.append, progress_every_s=2.0)
    silent = build_map("room", MAPPING_ROUTES["room"], params=params, max_sim_s=4.0)
    matches = [LINE.fullmatch(line) for line in heard]
    assert all(matches), heard
    assert [int(m.group(1)) for m in matches] == [2, 4]
    shares = [float(m.group(2)) for m in matches]
    assert shares == sorted(shares) and shares[-1] > 0
    assert np.array_equal(with_progress.grid.data, silent.grid.data) and with_progress.sim_s == silent.sim_s


def test_map_prints_progress_unless_quiet(tmp_path, capsys):
    base = ["map", "--world", "room", "--route", "--max-time", "3", "--set", "particles=5", "--force"]
    assert cli_main([*base, "-o", str(tmp_path / "loud")]) == 0
    loud = capsys.readouterr().out
    assert re.search(r"^map: sim 3 s: lap 1 of 1, \d+\.\d % of the reachable space mapped$", loud, re.M), loud
    assert cli_main([*base, "-o", str(tmp_path / "quiet"), "--quiet"]) == 0
    quiet = capsys.readouterr().out
    assert "map:" not in quiet and "wrote " in quiet


def test_navigate_quiet_prints_the_summary_only(tmp_path, capsys):
    code = cli_main(["navigate", "--world", "room", "--in-process", "--goal", "3.2", "0.9", "30", "--timeout", "1",
                     "-o", str(tmp_path), "--json", "--quiet"])
    captured = capsys.readouterr()
    assert code == 1 and "navigate:" not in captured.out + captured.err
    assert json.loads(captured.out)["goals_total"] == 1
