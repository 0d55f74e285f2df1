"""experiments/progress.py: a bar with an estimate on a terminal, nothing under --json or in a log;
the printed lines of a bench stay whole beside it."""
import io

from omninav.experiments import progress as progress_module
from omninav.experiments.progress import progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_bar_is_drawn_on_a_terminal_over_the_total(monkeypatch, capsys):
    terminal = Terminal()
    monkeypatch.setattr(progress_module.sys, "stderr", terminal)
    with progress(3, "worlds") as bar:
        for k in range(3):
            with bar.printing():
                print(f"world {k}: success")
            bar.advance()
    drawn = terminal.getvalue()
    assert "0/3 [" in drawn and " worlds/s" in drawn       # the count of the total, and a rate for the estimate
    assert capsys.readouterr().out.splitlines() == ["world 0: success", "world 1: success", "world 2: success"]


def test_no_bar_under_json_or_without_a_terminal(monkeypatch, capsys):
    terminal = Terminal()
    monkeypatch.setattr(progress_module.sys, "stderr", terminal)
    with progress(2, "worlds", quiet=True) as bar:      # --json
        bar.advance(2)
    assert terminal.getvalue() == ""
    log = io.StringIO()                                   # a log file, CI, a pipe
    monkeypatch.setattr(progress_module.sys, "stderr", log)
    with progress(2, "worlds") as bar:
        with bar.printing():
            print("a line")
        bar.advance(2)
    assert log.getvalue() == "" and capsys.readouterr().out == "a line\n"


def test_map_shows_the_share_mapped_as_a_bar_on_a_terminal_and_as_lines_in_a_log(monkeypatch, capsys):
    from omninav.cli.map import MappingReport
    from omninav.experiments.mapping import MappingProgress

    reports = [MappingProgress(30.0, "3 frontier goals sent", None), MappingProgress(60.0, "5 frontier goals sent", 0.42),
               MappingProgress(90.0, "8 frontier goals sent", 0.875)]
    terminal = Terminal()
    monkeypatch.setattr(progress_module.sys, "stderr", terminal)
    with progress(100, "% mapped") as bar:
        report = MappingReport(bar)
        for r in reports:
            report(r)
        assert report.percent == 88
    drawn = terminal.getvalue()
    assert "/100 [" in drawn and "% mapped/s" in drawn
    assert capsys.readouterr().out == ""
    monkeypatch.setattr(progress_module.sys, "stderr", io.StringIO())
    with progress(100, "% mapped") as bar:
        report = MappingReport(bar)
        for r in reports:
            report(r)
    assert capsys.readouterr().out.splitlines() == [
        "map: sim 30 s: 3 frontier goals sent, no map yet",
        "map: sim 60 s: 5 frontier goals sent, 42.0 % of the reachable space mapped",
        "map: sim 90 s: 8 frontier goals sent, 87.5 % of the reachable space mapped"]
