// omninav's timing driver for ROS navfn, the reference of `omninav bench planner --navfn DIR`.
// navfn itself is not part of omninav: the bench compiles this file against the navfn sources the
// user points it at. Reads <dir>/costs.bin (int32 width, height, then uint8 costmap_2d costs, row
// after row) and <dir>/pairs.txt (start row, column, goal row, column per line); plans each pair as
// navfn_ros's makePlan does (setCostmap every plan, unknown allowed, the wave from the goal) with A*
// and with Dijkstra, `runs` times each, and prints per pair: ok, then the fastest ms of each planner
// with setCostmap and of its search alone, in CPU time of this thread (as the bench times its own).
#include <navfn/navfn.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <time.h>

static double now_ms() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

int main(int argc, char** argv) {
  if (argc < 2) { std::fprintf(stderr, "usage: driver DIR [RUNS]\n"); return 2; }
  const std::string dir = argv[1];
  const int runs = argc > 2 ? std::atoi(argv[2]) : 3;
  FILE* f = std::fopen((dir + "/costs.bin").c_str(), "rb");
  int size[2];
  if (!f || std::fread(size, sizeof(int), 2, f) != 2) { std::fprintf(stderr, "cannot read costs.bin\n"); return 2; }
  std::vector<unsigned char> costs(static_cast<size_t>(size[0]) * size[1]);
  if (std::fread(costs.data(), 1, costs.size(), f) != costs.size()) { std::fprintf(stderr, "short costs.bin\n"); return 2; }
  std::fclose(f);
  f = std::fopen((dir + "/pairs.txt").c_str(), "r");
  if (!f) { std::fprintf(stderr, "cannot read pairs.txt\n"); return 2; }
  std::vector<std::array<int, 4>> pairs;
  std::array<int, 4> p;
  while (std::fscanf(f, "%d %d %d %d", &p[0], &p[1], &p[2], &p[3]) == 4) pairs.push_back(p);
  std::fclose(f);

  navfn::NavFn planner(size[0], size[1]);
  for (const auto& pair : pairs) {
    int start[2] = {pair[1], pair[0]}, goal[2] = {pair[3], pair[2]};   // navfn takes (x, y)
    bool ok = true;
    double best[2][2] = {{1e300, 1e300}, {1e300, 1e300}};              // [astar, dijkstra][whole, search]
    for (int mode = 0; mode < 2; ++mode) {
      for (int r = 0; r < runs; ++r) {
        const double t0 = now_ms();
        planner.setCostmap(costs.data(), true, true);
        const double t1 = now_ms();
        planner.setStart(goal);                    // navfn_ros propagates from the goal
        planner.setGoal(start);
        ok = (mode == 0 ? planner.calcNavFnAstar() : planner.calcNavFnDijkstra(true)) && ok;
        const double t2 = now_ms();
        best[mode][0] = std::min(best[mode][0], t2 - t0);
        best[mode][1] = std::min(best[mode][1], t2 - t1);
      }
    }
    std::printf("%d %.4f %.4f %.4f %.4f\n", ok ? 1 : 0, best[0][0], best[0][1], best[1][0], best[1][1]);
  }
  return 0;
}
