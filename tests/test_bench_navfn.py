"""`omninav bench planner --navfn DIR`: the navfn reference is built from the sources a user points
at and run on the bench's own costmap and pairs. navfn itself is not in the repository, so these
tests build the driver against a stand-in with navfn's interface that records what it was given."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from omninav.bench.navfn_reference import build, plan_times
from omninav.services.runtime.errors import UserError

pytestmark = pytest.mark.skipif(shutil.which("c++") is None and shutil.which("g++") is None,
                                reason="no C++ compiler to build the navfn reference")

HEADER = """#pragma once
namespace navfn {
class NavFn {
 public:
  NavFn(int nx, int ny) : nx_(nx), ny_(ny) {}
  void setCostmap(const unsigned char* costs, bool, bool) { costs_ = costs; }
  void setStart(int* s) { start_[0] = s[0]; start_[1] = s[1]; }
  void setGoal(int* g) { goal_[0] = g[0]; goal_[1] = g[1]; }
  bool calcNavFnAstar() { return free(start_) && free(goal_); }
  bool calcNavFnDijkstra(bool) { return calcNavFnAstar(); }
 private:
  bool free(const int* c) const { return c[0] < nx_ && c[1] < ny_ && costs_[c[1] * nx_ + c[0]] < 253; }
  int nx_, ny_, start_[2] = {0, 0}, goal_[2] = {0, 0};
  const unsigned char* costs_ = nullptr;
};
}
"""
SOURCE = "#include <navfn/navfn.h>\n#include <ros/console.h>\n"


def stand_in(folder, source=SOURCE):
    (folder / "include" / "navfn").mkdir(parents=True)
    (folder / "include" / "navfn" / "navfn.h").write_text(HEADER)
    (folder / "src").mkdir()
    (folder / "src" / "navfn.cpp").write_text(source)
    return folder


def test_the_reference_is_built_once_and_answers_every_pair_on_the_benchs_costmap(tmp_path):
    sources = stand_in(tmp_path / "navfn")
    binary = build(sources, tmp_path / "out")
    assert build(sources, tmp_path / "out") == binary                   # the same sources: not built again
    costs = np.zeros((4, 6), np.uint8)
    costs[2, 5] = 254                                                   # row 2 (y), column 5 (x): lethal
    times = plan_times(binary, costs, [((0, 0), (3, 4)), ((0, 0), (2, 5))], runs=2)
    assert [t.ok for t in times] == [True, False]                       # cells reach navfn as (x, y) = (column, row)
    assert all(t.astar_ms >= t.astar_search_ms >= 0 and t.dijkstra_ms >= 0 for t in times)


def test_a_bad_navfn_folder_is_named(tmp_path):
    with pytest.raises(UserError, match="no such folder"):
        build(tmp_path / "nowhere")
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "navfn.cpp").write_text(SOURCE)
    with pytest.raises(UserError, match="navfn/navfn.h not found"):
        build(tmp_path / "half")
    with pytest.raises(UserError, match="did not compile"):
        build(stand_in(tmp_path / "broken", SOURCE + "this is not C++;\n"), tmp_path / "out")
