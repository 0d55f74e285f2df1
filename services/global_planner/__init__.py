"""The global planner core: cost-aware A* and Dijkstra over a costmap, goal tolerance, path smoothing."""
