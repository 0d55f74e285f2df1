"""The README teaches what runs: every shell block in it is run as written, and it stays short.

Each fenced block is preceded by `<!-- readme-test: MODE … -->`, which this test reads:
  run               run the block with bash -e; it must exit 0
  until-stopped N   a server: it must still be running after N s, then stop cleanly at Ctrl-C
  dry-run           `make -n` of the block's make targets (the block is this suite itself)
  not-run: WHY      skipped, saying why (a block that needs hardware the machine does not have)
A block with no annotation fails: nothing is skipped silently. The blocks run in order in one
temporary folder (the repository's compose/ and sim/ linked in, README.md and docs/ copied), with
the venv on the PATH and a router port of their own, and every process they start is stopped
whatever ends the test.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO, free_port

README = REPO / "README.md"
MOST_WORDS = 1600       # issue 37: "at most ~1,500 words"; HTML comments (the annotations) not counted
BLOCK = re.compile(r"<!-- readme-test: (?P<mode>[^>]*?) -->\s*\n```(?P<lang>\w*)\n(?P<body>.*?)```", re.S)
ANY_BLOCK = re.compile(r"^```(\w*)\n", re.M)
RUN_TIMEOUT_S = 300


def visible_words(markdown: str) -> int:
    return len(re.sub(r"<!--.*?-->", "", markdown, flags=re.S).split())


def readme_blocks() -> list[tuple[str, str]]:
    text = README.read_text()
    return [(m["mode"].strip(), m["body"]) for m in BLOCK.finditer(text)]


def test_the_readme_is_short():
    words = visible_words(README.read_text())
    assert words <= MOST_WORDS, f"README.md has {words} words; at most {MOST_WORDS}: move detail to docs/"


def test_every_block_is_annotated_and_a_shell_block():
    text = README.read_text()
    opened = [m.start() for m in ANY_BLOCK.finditer(text)]
    annotated = [m.start("lang") - 3 for m in BLOCK.finditer(text)]
    # every opening fence (``` with a language or none) is one that BLOCK found; closing fences aside
    openings = [start for i, start in enumerate(opened) if text.count("```", 0, start) % 2 == 0]
    assert sorted(openings) == sorted(annotated), "a fenced block in README.md without <!-- readme-test: … -->"
    assert all(m["lang"] == "sh" for m in BLOCK.finditer(text)), "README blocks are ```sh"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """Where the blocks run, one after another: what they read linked or copied, what they write here."""
    work = tmp_path_factory.mktemp("readme")
    for name in ("compose", "sim", "Makefile", "pyproject.toml", ".venv"):
        (work / name).symlink_to(REPO / name)
    shutil.copy(README, work / "README.md")
    (work / "docs").mkdir()
    shutil.copy(REPO / "docs" / "measurements.md", work / "docs" / "measurements.md")
    shutil.copytree(REPO / "docs" / "results", work / "docs" / "results")
    return work


def block_env() -> dict[str, str]:
    venv_bin = str(Path(sys.executable).parent)
    env = {k: v for k, v in os.environ.items() if k not in ("OMNINAV_CREDENTIALS", "OMNINAV_LOCKSTEP")}
    env.update(PATH=f"{venv_bin}{os.pathsep}{env.get('PATH', '')}",
               OMNINAV_ROUTER=f"tcp/127.0.0.1:{free_port()}")
    return env


def stop_group(proc: subprocess.Popen) -> None:
    """Whatever the block started is in its process group: end it all."""
    for sig, wait_s in ((signal.SIGINT, 30), (signal.SIGKILL, 5)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(wait_s)
        except subprocess.TimeoutExpired:
            continue


def start(body: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(["bash", "-e", "-c", body], cwd=cwd, env=block_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)


BLOCKS = readme_blocks()


@pytest.mark.parametrize("mode, body", BLOCKS, ids=[f"block{i}-{mode.split()[0]}" for i, (mode, _) in enumerate(BLOCKS)])
def test_readme_block(mode, body, workdir):
    kind, _, rest = mode.partition(" ")
    kind = kind.rstrip(":")
    if kind == "not-run":
        reason = rest.strip(" :")
        assert reason, "a not-run block says why"
        pytest.skip(f"README block not run, as its annotation says: {reason}")
    if kind == "dry-run":
        targets = [line.split("#")[0].split()[1:] for line in body.splitlines() if line.strip()]
        assert all(line.split()[0] == "make" for line in body.splitlines() if line.strip()), "dry-run is for make"
        done = subprocess.run(["make", "-n", *sum(targets, [])], cwd=workdir, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        return
    proc = start(body, workdir)
    try:
        if kind == "run":
            out, _ = proc.communicate(timeout=RUN_TIMEOUT_S)
            assert proc.returncode == 0, f"README block exited {proc.returncode}:\n{body}\n--- output:\n{out[-4000:]}"
        elif kind == "until-stopped":
            seconds = float(rest.split(":")[0])
            time.sleep(seconds)
            assert proc.poll() is None, f"README block ended before it was stopped:\n{proc.communicate()[0][-4000:]}"
            os.killpg(proc.pid, signal.SIGINT)
            out, _ = proc.communicate(timeout=30)
            assert proc.returncode in (0, 130), f"README block stopped with {proc.returncode}:\n{out[-4000:]}"
        else:
            pytest.fail(f"unknown readme-test mode {mode!r}")
    finally:
        stop_group(proc)


def test_the_bench_block_recorded_a_run_and_the_report_took_it(workdir):
    """After the blocks: the transport run is a results file and the headline table's transport row."""
    if not any("bench transport --save-results" in body for _, body in BLOCKS):
        pytest.skip("the README no longer runs a bench")
    measured = sorted(p for p in (workdir / "docs" / "results").glob("*-transport.json")
                      if json.loads(p.read_text())["source"] == "measured")
    assert measured, "omninav bench transport --save-results wrote no results file"
    readme = (workdir / "README.md").read_text()
    assert f"docs/measurements.md#{measured[-1].stem}" in readme
