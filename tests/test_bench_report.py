"""Results files and `omninav bench report`: the record and the README's table are written, not typed."""
from __future__ import annotations

import argparse
import json
import shutil

import pytest

from conftest import REPO
from omninav.bench import measurements, results


def report_args(**paths) -> argparse.Namespace:
    return argparse.Namespace(check=paths.pop("check", False), **paths)


def test_the_record_and_the_readme_table_are_what_the_results_files_say(monkeypatch):
    monkeypatch.chdir(REPO)
    args = report_args(check=True, results=results.RESULTS_DIR, measurements=measurements.MEASUREMENTS,
                       readme=measurements.README)
    assert measurements.main(args) == 0, "docs/measurements.md or README.md differs: run `omninav bench report`"


def test_every_results_file_says_where_it_comes_from():
    for path, record in results.load_results(REPO / "docs" / "results"):
        source = record.get("source", "")
        assert source == "measured" or source.startswith("transcribed from "), path
        if source == "measured":
            assert record["commit"] and record["date_utc"] and "figures" in record, path
        else:       # nothing of a run's provenance invented for a figure copied from text
            assert record["commit"] is None and record["machine"] is None, path
            assert record["figure"], path


def test_a_saved_run_keeps_the_json_the_bench_printed_with_its_provenance(tmp_path, capsys):
    def bench() -> int:
        print("warming up")
        print(json.dumps({"median_ms": 1.5, "runs": [1, 2]}), flush=True)
        return 0

    assert results.run_recorded("transport", ["--json"], bench, results_dir=tmp_path) == 0
    assert '{"median_ms": 1.5' in capsys.readouterr().out     # still printed as --json prints it
    [saved] = tmp_path.glob("*-transport.json")
    record = json.loads(saved.read_text())
    assert record["figures"] == {"median_ms": 1.5, "runs": [1, 2]}
    assert record["source"] == "measured" and record["command"] == "omninav bench transport --json"
    assert len(record["commit"]) == 40 and isinstance(record["dirty"], bool)
    assert record["machine"]["cores"] >= 1 and len(record["machine"]["load_start"]) == 3
    assert record["date_utc"].endswith("Z") and record["duration_s"] >= 0


def test_a_broken_silent_or_interrupted_bench_writes_no_results_file(tmp_path):
    assert results.run_recorded("sim", [], lambda: 3, results_dir=tmp_path) == 3
    assert results.run_recorded("sim", [], lambda: print("no json") or 0, results_dir=tmp_path) == 1
    assert results.run_recorded("barn", [], lambda: print('{"interrupted": true}') or 130, results_dir=tmp_path) == 130
    assert not list(tmp_path.iterdir())


def test_a_bench_that_missed_its_aim_is_recorded_with_its_exit_code(tmp_path):
    """`bench scenarios` exits 1 when a mission failed; its figures are the record all the same."""
    assert results.run_recorded("scenarios", ["--kind", "crossing"], lambda: print('{"success_rate": 0.8}') or 1,
                                results_dir=tmp_path) == 1
    (path,) = tmp_path.iterdir()
    record = json.loads(path.read_text())
    assert record["exit_code"] == 1 and record["figures"] == {"success_rate": 0.8}


def test_an_indented_json_object_is_found_too():
    text = 'progress\n{\n  "a": 1,\n  "b": {"c": 2}\n}\n'
    assert results.last_json_object(text) == {"a": 1, "b": {"c": 2}}


def test_a_new_run_becomes_the_headline_and_a_missed_aim_says_so(tmp_path, monkeypatch):
    """A measured transport run newer than the transcribed figure takes its row; 1.3 × raw misses ≤ 1.1 ×."""
    shutil.copytree(REPO / "docs" / "results", tmp_path / "results")
    shutil.copy(REPO / "README.md", tmp_path / "README.md")
    run = {"format": 1, "bench": "transport", "source": "measured", "command": "omninav bench transport --json",
           "commit": "0" * 40, "dirty": False, "date_utc": "2031-01-01T00:00:00Z",
           "machine": {"cores": 2, "load_start": [1.0, 1.0, 1.0], "load_end": [1.5, 1.0, 1.0]}, "duration_s": 9.0,
           "figures": {"rtt_median_ms": 0.39, "rtt_raw_median_ms": 0.3, "msgs_per_s": 300000,
                       "msgs_raw_per_s": 900000}}
    (tmp_path / "results" / "2031-01-01T000000Z-transport.json").write_text(json.dumps(run))
    args = report_args(results=tmp_path / "results", measurements=tmp_path / "measurements.md",
                       readme=tmp_path / "README.md")
    assert measurements.main(args) == 0
    row = next(line for line in (tmp_path / "README.md").read_text().splitlines() if "2031-01-01T000000Z-transport" in line)
    assert "1.30 × raw" in row and "33% of raw" in row and "**missed**" in row
    assert "0000000" not in row, "no commit in the README's table"
    assert measurements.main(argparse.Namespace(**(vars(args) | {"check": True}))) == 0
    (tmp_path / "README.md").write_text((tmp_path / "README.md").read_text().replace("1.30 × raw", "1.0 × raw"))
    assert measurements.main(argparse.Namespace(**(vars(args) | {"check": True}))) == 1


def test_a_readme_without_the_markers_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="markers"):
        measurements.readme_with_table("# no table here\n", "| a |")


def test_barn_and_dynabarn_runs_say_their_outcomes_in_one_line():
    block = {"runs": 20, "success_rate": 0.75, "collisions": 5, "timeouts": 0, "false_successes": 1, "mean_score": 0.37339}
    assert measurements.summarize({"odometry": "fused", "controller": "dwa", "difficulties": {"easy": block}},
                                  "dynabarn")[0] \
        == "fused odometry, dwa: easy 15/20, 5 collisions, 0 timeouts, 1 false successes, mean score 0.3734"
    assert measurements.summarize({"range": "0-149", "all": dict(block, runs=150, success_rate=1.0)}, "barn")[0] \
        == "chassis odometry, worlds 0-149: 150/150, 5 collisions, 0 timeouts, 1 false successes, mean score 0.3734"


def test_a_shove_run_says_how_far_the_fused_odometry_was_off_against_the_chassis():
    def run(odometry, shoved, end, after, doubt):
        return {"odometry": odometry, "shoved_m": shoved, "error_at_end_m": end, "error_after_1s_m": after,
                "doubt_after_s": doubt}
    figures = {"profile": "jackal", "aim_met": True,
               "runs": [run("chassis", 0.56, 0.55, 0.55, None), run("fused", 0.56, 0.028, 0.012, 0.0),
                        run("chassis", 2.06, 2.05, 2.05, None), run("fused", 2.06, 0.067, 0.028, 0.0)]}
    assert measurements._shove(figures) == (
        "the jackal carried 0.56–2.06 m: fused odometry 1.20–2.80 cm off 1 s after the shove, 2.80–6.70 cm at "
        "its end; doubtful 0.00 s after it began", "the chassis's odometry 0.55–2.05 m off", True)


def test_report_outside_the_repository_or_on_a_broken_results_file_says_so_in_one_line(tmp_path, capsys):
    def report(*argv):
        parser = argparse.ArgumentParser()
        measurements.add_arguments(parser)
        return measurements.main(parser.parse_args(list(argv)))

    assert report("--results", str(tmp_path / "nowhere"), "--readme", str(REPO / "README.md")) == 2
    assert "nowhere: no such file or folder (the results folder)" in capsys.readouterr().err
    results_dir = tmp_path / "results"
    results_dir.mkdir()
    (results_dir / "broken.json").write_text("{not json")
    assert report("--results", str(results_dir), "--readme", str(REPO / "README.md"), "--check") == 2
    assert "broken.json: not JSON" in capsys.readouterr().err
    (results_dir / "broken.json").write_text('{"figures": {}}')
    assert report("--results", str(results_dir), "--readme", str(REPO / "README.md"), "--check") == 2
    assert "broken.json: not a results file" in capsys.readouterr().err
