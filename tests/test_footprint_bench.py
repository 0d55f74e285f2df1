"""`omninav bench footprint`: the /proc readers of a process tree's CPU time and proportional memory,
and the sim time of a recording at given wall times."""
import os
import subprocess
import sys

import pytest

from omninav.bench.process_footprint import FootprintError, cpu_seconds, pss_mb, sim_time_at, tree_pids
from omninav.schemas.codec import encode
from omninav.schemas.messages import Clock, Header
from omninav.services.recorder.mcap_io import RecordingWriter

TICKS = os.sysconf("SC_CLK_TCK")


def fake_process(proc, pid: int, ppid: int, utime: int = 0, stime: int = 0, pss_kb: int | None = None) -> None:
    folder = proc / str(pid)
    folder.mkdir()
    # a command name with a space and a parenthesis: fields are counted after the last ')'
    fields = ["S", str(ppid), *["0"] * 9, str(utime), str(stime), *["0"] * 5]
    (folder / "stat").write_text(f"{pid} (py (x) y) {' '.join(fields)}\n")
    if pss_kb is not None:
        (folder / "smaps_rollup").write_text(f"00400000-7fff [rollup]\nRss:  {2 * pss_kb} kB\nPss:  {pss_kb} kB\n"
                                             f"Pss_Anon:  1 kB\n")


def test_the_tree_its_cpu_time_and_its_pss_are_read_from_proc(tmp_path):
    fake_process(tmp_path, 10, 1, utime=3 * TICKS, stime=TICKS, pss_kb=1024)
    fake_process(tmp_path, 11, 10, utime=TICKS, pss_kb=2048)
    fake_process(tmp_path, 12, 11, stime=2 * TICKS)          # gone before its memory was read
    fake_process(tmp_path, 13, 1, utime=100 * TICKS, pss_kb=99999)    # not in the tree
    (tmp_path / "self").mkdir()
    pids = tree_pids(10, tmp_path)
    assert sorted(pids) == [10, 11, 12]
    assert cpu_seconds(pids, tmp_path) == pytest.approx(7.0)
    assert pss_mb(pids, tmp_path) == pytest.approx(3.0)
    assert cpu_seconds([99], tmp_path) == 0.0                 # a process that ended counts nothing


def test_the_real_proc_sees_a_child_and_its_memory():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert child.pid in tree_pids(os.getpid())
        assert pss_mb([os.getpid()]) > 1.0
        assert cpu_seconds([os.getpid()]) > 0.0
    finally:
        child.kill()
        child.wait()


def test_sim_time_at_wall_times_comes_from_the_recorded_clock(tmp_path):
    path = tmp_path / "run.mcap"
    with RecordingWriter(path) as writer:
        for k in range(1, 6):       # sim k s received at wall 100 + 2k s
            writer.write("omninav/sim/clock", "Clock", encode(Clock(header=Header(stamp_ns=k * 10**9), rate=1.0)),
                         k, k * 10**9, (100 + 2 * k) * 10**9)
    assert sim_time_at(path, [103 * 10**9, 106 * 10**9, 200 * 10**9, 0]) == [1.0, 3.0, 5.0, 1.0]
    empty = tmp_path / "empty.mcap"
    with RecordingWriter(empty):
        pass
    with pytest.raises(FootprintError, match="no clock messages"):
        sim_time_at(empty, [0])
