"""`omninav bench report [--check]`: docs/measurements.md and the README's headline table, from the results files.

Every figure in either comes from a file in docs/results/ (bench/results.py): a run saved with
`omninav bench NAME --save-results`, or a figure transcribed from the record kept as text before.
The output depends only on those files (sorted, no date of its own), so `--check` can tell a hand
edit, or a results file added without running the report, from the written record.
"""
from __future__ import annotations

import argparse
import difflib
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..services.runtime.errors import UserError, exits_2_on_user_error
from .results import RESULTS_DIR, load_results

# relative to the directory the report runs in (the repository)
MEASUREMENTS = Path("docs") / "measurements.md"
README = Path("README.md")
TABLE_BEGIN = "<!-- headline table: written by `omninav bench report` from docs/results/; do not edit by hand -->"
TABLE_END = "<!-- end of the headline table -->"

# what a measured run's figures say in one line: (figure, reference, aim met or None)
Summary = Callable[[dict], tuple[str, str | None, bool | None]]


def _transport(figures: dict) -> tuple[str, str | None, bool | None]:
    if "without_acl" in figures:        # --acl both: the headline is the run without the ACL
        figures = figures["without_acl"]
    rtt = figures["rtt_median_ms"] / figures["rtt_raw_median_ms"]
    share = figures["msgs_per_s"] / figures["msgs_raw_per_s"]
    figure = (f"round trip {figures['rtt_median_ms']:.3f} ms, {rtt:.2f} × raw; "
              f"small messages {figures['msgs_per_s']:,} msgs/s, {share:.0%} of raw")
    reference = f"raw bytes {figures['rtt_raw_median_ms']:.3f} ms, {figures['msgs_raw_per_s']:,} msgs/s"
    return figure, reference, rtt <= 1.1 and share >= 0.5


def _shove(figures: dict) -> tuple[str, str | None, bool | None]:
    def span(values) -> str:
        low, high = f"{min(values):.2f}", f"{max(values):.2f}"
        return low if low == high else f"{low}–{high}"
    fused = [r for r in figures["runs"] if r["odometry"] == "fused"]
    chassis = [r for r in figures["runs"] if r["odometry"] == "chassis"]
    doubts = [r["doubt_after_s"] for r in fused if r["doubt_after_s"] is not None]
    figure = (f"the {figures['profile']} carried {span([r['shoved_m'] for r in fused])} m: fused odometry "
              f"{span([100 * r['error_after_1s_m'] for r in fused])} cm off 1 s after the shove, "
              f"{span([100 * r['error_at_end_m'] for r in fused])} cm at its end; doubtful "
              + (f"{span(doubts)} s after it began" if len(doubts) == len(fused) else "not in every run"))
    reference = f"the chassis's odometry {span([r['error_after_1s_m'] for r in chassis])} m off" if chassis else None
    return figure, reference, figures["aim_met"]


@dataclass(frozen=True)
class Headline:
    """One row of the README's table: the newest results file that is this measurement."""
    key: str                    # a transcribed file names it in "headline"
    title: str
    bench: str                  # a measured run of this bench whose command has every one of
    command_has: tuple[str, ...] = ()       # these and none of command_lacks is one too
    command_lacks: tuple[str, ...] = ()
    aim: str | None = None      # the aim a measured run is held to (a transcribed file carries its own)

    def matches(self, record: dict) -> bool:
        if record.get("headline") == self.key:
            return True
        command = record.get("command") or ""
        return (record.get("source") == "measured" and record["bench"] == self.bench
                and all(part in command for part in self.command_has)
                and not any(part in command for part in self.command_lacks))


HEADLINES = (
    Headline("barn", "BARN worlds 0–149, Jackal, no map", "barn", ("--range 0-149",), ("--odometry",),
             "100 %, 0 collisions, ≥ 0.45 lockstep, ≥ 0.42 real time"),
    Headline("dynabarn", "DynaBARN-style worlds, reporting seeds", "dynabarn", ("--seed 100100", "--count 100"),
             ("--controller",),
             "≥ 90 % each"),
    Headline("scenarios-people", "people kinds, reporting seeds", "scenarios", ("--seed 100000", "--count 100"),
             ("--controller",), "≥ 95 % each"),
    Headline("scenarios-teb", "TEB beside DWA on the people kinds", "scenarios", ("--controller dwa teb",), (),
             "success ≥ DWA's, mean time lower"),
    Headline("buildings", "buildings, every robot, reporting seeds", "buildings", ("--seed 1001", "--count 100"), (),
             "100 %, ≤ 1.5 × the shortest way's time, no contact"),
    Headline("missions", "navigation missions, 6 worlds × 3 drives", "missions", (), (), "100 %"),
    Headline("paper", "the mecanum paper's experiment, 20 seeds", "paper", (), (), "20/20 within 5 cm and 2°"),
    Headline("explore", "frontier exploration of mazes", "explore", ("--seed 100000",), (),
             "≥ 95 % in ≥ 95 % of mazes"),
    Headline("shove", "a shove the wheels miss (odometry fusion)", "shove", (), (), "within 10 cm in 1 s"),
    Headline("slam-eval", "SLAM on the MIT CSAIL log", "slam-eval", (), (), "≥ 20 × real time"),
    Headline("localize-eval", "AMCL tracking from a rough start", "localize-eval", (), (), "p95 ≤ 5 cm, ≤ 2°"),
    Headline("planner", "A* on Willow, 20 far pairs", "planner", (), (), "ours / navfn ≤ 0.5"),
    Headline("local", "local planner cycle (DWA)", "local", (), ("--controller",), "≤ 3 ms, p99 ≤ 5 ms"),
    Headline("local-teb", "TEB cycle, a person crossing", "local", ("--controller teb",), (), "p95 ≤ 25 ms"),
    Headline("footprint", "footprint of a live mission at 1× real time", "footprint", (), (),
             "one container ≤ 3 s, ≤ 0.25 cores, ≤ 400 MB; separate ≤ 5 s, ≤ 0.5, ≤ 800 MB"),
    Headline("kills", "a crash of each service during a room mission", "kills", (), (), "36/36"),
    Headline("transport", "messages between processes", "transport", (), ("--acl on",),
             "≤ 1.1 × raw; ≥ 50 % of raw"),
)

# the benches' sections in docs/measurements.md, in this order; any other bench after them by name
SECTION_TITLES = {
    "barn": "BARN (`omninav bench barn`)",
    "dynabarn": "DynaBARN-style worlds (`omninav bench dynabarn`)",
    "scenarios": "generated worlds with people and clutter (`omninav bench scenarios`)",
    "buildings": "buildings (`omninav bench buildings`)",
    "regress": "tuning missions (`omninav bench regress`)",
    "missions": "navigation missions (`omninav bench missions`)",
    "paper": "the mecanum paper's experiment (`omninav bench paper`)",
    "explore": "maze exploration (`omninav bench explore`)",
    "map": "mapping the shipped worlds (`omninav map --world`)",
    "shove": "odometry fusion (`omninav bench shove`)",
    "slam-eval": "SLAM on real logs (`omninav slam-eval`)",
    "localize-eval": "AMCL in the simulator and on a real bag (`omninav localize-eval`)",
    "amcl": "AMCL update (`omninav bench amcl`)",
    "planner": "global planner (`omninav bench planner`)",
    "local": "local planner cycle (`omninav bench local`)",
    "footprint": "footprint of a live mission (`omninav bench footprint`)",
    "cpu": "CPU per service (`omninav bench cpu`)",
    "kills": "crashes during a mission (`omninav bench kills`)",
    "fuzz": "random payloads (`omninav bench fuzz`)",
    "transport": "the bus between processes (`omninav bench transport`)",
    "recorder": "recorder (`omninav bench recorder`)",
    "sim": "simulator (`omninav bench sim`)",
    "codec-timeit": "the codec in one process (`timeit`)",
    "throwaway-script": "throwaway measuring scripts",
    "fresh-clone": "a fresh clone (`make test`, `make demo`)",
    "several": "several benches at once",
}


def newest_first_key(item: tuple[Path, dict]) -> tuple[str, str]:
    """When a run was made, as its file says: its date, else the newest commit its text names."""
    path, record = item
    when = max([record.get("date_utc") or "", *(record.get("commit_dates") or {}).values()])
    return when, path.name


def anchor(path: Path) -> str:
    return path.stem


def _aim_verdict(met: bool | None) -> str:
    return {True: "met", False: "**missed**", None: "not judged"}[met]


def headline_row(spec: Headline, path: Path, record: dict) -> tuple[str, str, str, str]:
    """(figure, reference, aim, verdict) of a headline file."""
    if record.get("source") == "measured":
        figure, reference, met = summarize(record["figures"], record["bench"])
        aim = spec.aim
    else:
        figure = record.get("headline_figure") or record["figure"]
        reference = record.get("headline_reference")
        aim = record.get("headline_aim")
        met = record.get("aim_met")
    return figure, reference or "—", aim or "—", "—" if aim is None else _aim_verdict(met)


def _outcomes(block: dict) -> str:
    """A bench's block of runs (barn's 'all', dynabarn's difficulty) in one phrase."""
    runs = block["runs"]
    return (f"{round(block['success_rate'] * runs)}/{runs}, {block['collisions']} collisions, "
            f"{block['timeouts']} timeouts, {block.get('false_successes', 0)} false successes, "
            f"mean score {block['mean_score']:.4f}")


def _barn(figures: dict) -> tuple[str, str | None, bool | None]:
    return (f"{figures.get('odometry', 'chassis')} odometry, worlds {figures['range']}: {_outcomes(figures['all'])}",
            None, None)


def _dynabarn(figures: dict) -> tuple[str, str | None, bool | None]:
    per = "; ".join(f"{name} {_outcomes(block)}" for name, block in figures["difficulties"].items())
    return f"{figures.get('odometry', 'auto')} odometry, {figures.get('controller', 'dwa')}: {per}", None, None


# what a measured run of a bench says in one line (its reference and its aim's verdict where it judges them)
SUMMARIES: dict[str, Summary] = {"transport": _transport, "shove": _shove, "barn": _barn, "dynabarn": _dynabarn}


def summarize(figures: dict, bench: str, most: int = 6) -> tuple[str, str | None, bool | None]:
    """A measured run's (figure, reference, aim met): its bench's summary, else its first few
    top-level numbers, judged by nobody."""
    if bench in SUMMARIES:
        return SUMMARIES[bench](figures)
    items = [f"{k} {v}" for k, v in figures.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]
    return "; ".join(items[:most]) or "figures in the results file", None, None


def headline_table(results: list[tuple[Path, dict]], link_prefix: str) -> str:
    lines = ["| what | latest | reference | aim | |", "|---|---|---|---|---|"]
    for spec in HEADLINES:
        matching = [item for item in results if spec.matches(item[1])]
        if not matching:
            continue
        path, record = max(matching, key=newest_first_key)
        figure, reference, aim, verdict = headline_row(spec, path, record)
        cells = [f"[{spec.title}]({link_prefix}#{anchor(path)})", figure, reference, aim, verdict]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _when(record: dict) -> str:
    parts = []
    if record.get("date_utc"):
        parts.append(record["date_utc"])
    commit = record.get("commit")
    if commit:
        dirty = " (dirty tree)" if record.get("dirty") else ""
        parts.append(f"commit {commit[:7]}{dirty}")
    named = [h for h in record.get("commits_mentioned") or [] if h != commit]
    if named:
        dates = record.get("commit_dates") or {}
        parts.append("commits named: " + ", ".join(f"{h} ({dates[h][:10]})" if h in dates else h for h in named))
    return "; ".join(parts) or "not given"


def _machine(record: dict) -> str | None:
    machine = record.get("machine")
    if not machine:
        return None
    load = " → ".join(f"{m[0]:.2f}" for m in (machine.get("load_start"), machine.get("load_end")) if m)
    duration = f", {record['duration_s']:g} wall s" if record.get("duration_s") is not None else ""
    return f"{machine.get('cores')} cores, load average (1 min) {load or 'unknown'}{duration}"


def record_entry(path: Path, record: dict) -> str:
    measured = record.get("source") == "measured"
    title = record.get("what") or record.get("command") or path.stem
    lines = [f'<a id="{anchor(path)}"></a>', f"### {title}" if not measured else f"### `{record['command']}`", ""]
    fields: list[tuple[str, str | None]] = [
        ("when", _when(record)),
        ("command", None if measured else record.get("command")),
        ("machine", _machine(record)),
        ("exit code", f"{record['exit_code']} (a run or an aim failed; the figures say which)"
         if record.get("exit_code") else None),
    ]
    if measured:
        figure, reference, met = summarize(record["figures"], record["bench"])
        spec = next((s for s in HEADLINES if s.matches(record)), None)
        judged = spec is not None and met is not None
        fields += [("figure", figure), ("reference", reference),
                   ("aim", f"{spec.aim} — {_aim_verdict(met)}" if judged else None)]
    else:
        fields += [("figure", record.get("figure")), ("reference", record.get("reference")),
                   ("seeds", record.get("seeds"))]
        if record.get("aim") or record.get("aim_met") is not None:
            verdict = _aim_verdict(record.get("aim_met"))
            why = f" ({record['aim_met_note']})" if record.get("aim_met_note") else ""
            fields.append(("aim", f"{record.get('aim') or 'as the texts say'} — {verdict}{why}"))
    if not measured:    # the README's texts link docs/X.md; this page is in docs/
        fields = [(name, value.replace("](docs/", "](") if isinstance(value, str) else value) for name, value in fields]
    notes = [record[k] for k in sorted(record) if k.startswith("note")]
    fields += [("note", note) for note in notes]
    fields.append(("source", f"{record['source']}; [{path.name}](results/{path.name})"))
    lines += [f"- **{name}**: {value}" for name, value in fields if value]
    return "\n".join(lines) + "\n"


def measurements_md(results: list[tuple[Path, dict]]) -> str:
    by_bench: dict[str, list[tuple[Path, dict]]] = {}
    for item in results:
        by_bench.setdefault(item[1]["bench"], []).append(item)
    order = [b for b in SECTION_TITLES if b in by_bench] + sorted(b for b in by_bench if b not in SECTION_TITLES)
    out = [
        "# Measured: the full record",
        "",
        "<!-- written by `omninav bench report` from docs/results/*.json; do not edit by hand -->",
        "",
        "Every run each benchmark's figures come from, newest first, grouped by bench: the command, the",
        "commit, the machine's load, the figure beside the reference measured in the same run, and the aim",
        "(**missed** where it was not met). A run saved with `omninav bench NAME --save-results` carries",
        "its own provenance; the runs before that were transcribed from the record kept as text",
        "(README's *Measured* table, this page, docs/honest-world.md), each figure as the text gave it and",
        "`null` where the text gave nothing (docs/results/README.md). Which seeds are tuning and which",
        "reporting: [seeds.md](seeds.md).",
        "",
        "## The headline figures",
        "",
        headline_table(results, ""),
        "",
        "## Benches",
        "",
    ]
    out += [f"- [{SECTION_TITLES.get(b, b)}](#bench-{b}) ({len(by_bench[b])})" for b in order]
    out.append("")
    for bench in order:
        out += [f'<a id="bench-{bench}"></a>', f"## {SECTION_TITLES.get(bench, bench)}", ""]
        for item in sorted(by_bench[bench], key=newest_first_key, reverse=True):
            out.append(record_entry(*item))
    return "\n".join(out).rstrip("\n") + "\n"


def readme_with_table(readme: str, table: str) -> str:
    try:
        head, rest = readme.split(TABLE_BEGIN, 1)
        _, tail = rest.split(TABLE_END, 1)
    except ValueError:
        raise SystemExit(f"omninav bench report: README.md lacks the markers {TABLE_BEGIN!r} … {TABLE_END!r}")
    return f"{head}{TABLE_BEGIN}\n{table}\n{TABLE_END}{tail}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if docs/measurements.md or README.md differs from what it would write")
    parser.add_argument("--results", type=Path, default=RESULTS_DIR, metavar="DIR",
                        help=f"the results files (default {RESULTS_DIR})")
    parser.add_argument("--measurements", type=Path, default=MEASUREMENTS, metavar="FILE",
                        help=f"the full record to write (default {MEASUREMENTS})")
    parser.add_argument("--readme", type=Path, default=README, metavar="FILE",
                        help=f"the README whose headline table to write (default {README})")


@exits_2_on_user_error("bench report")
def main(args: argparse.Namespace) -> int:
    for path, what in ((args.results, "the results folder"), (args.readme, "the README")):
        if not path.exists():
            raise UserError(f"{path}: no such file or folder ({what}); run it in the repository, or give "
                            f"--results and --readme")
    try:
        results = load_results(args.results)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    wanted = {
        args.measurements: measurements_md(results),
        args.readme: readme_with_table(args.readme.read_text(), headline_table(results, "docs/measurements.md")),
    }
    stale = [path for path, text in wanted.items() if not path.exists() or path.read_text() != text]
    if args.check:
        for path in stale:
            old = path.read_text().splitlines() if path.exists() else []
            diff = difflib.unified_diff(old, wanted[path].splitlines(), str(path), "omninav bench report", lineterm="", n=0)
            print("\n".join(list(diff)[:40]), file=sys.stderr)
            print(f"{path}: differs from the results files; run `omninav bench report`", file=sys.stderr)
        return 1 if stale else 0
    for path in stale:
        path.write_text(wanted[path])
        print(f"wrote {path}")
    print(f"{len(results)} results files; {len(stale)} file(s) changed")
    return 0
