"""The global planner's graph written the obvious way, for checking astar.py against scipy's Dijkstra
(tests/test_planner.py and `omninav bench planner`): same passability, step weights and corner rule."""
from __future__ import annotations

import numpy as np
from scipy import sparse

from .astar import SQRT2, passable
from .params import GlobalPlannerParams

STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1))


def graph(costs: np.ndarray, params: GlobalPlannerParams) -> sparse.csr_matrix:
    """The planner's graph as a sparse matrix: edge u → v weighs v's step cost, as in astar.py."""
    height, width = costs.shape
    ok = passable(costs, *np.indices(costs.shape), params)
    weight = params.neutral_cost + params.cost_factor * np.where(costs == 255, params.lethal_cost - 1, costs)
    rows, cols, data = [], [], []
    index = np.arange(costs.size).reshape(costs.shape)
    for dr, dc in STEPS:
        r = slice(max(-dr, 0), height - max(dr, 0))
        c = slice(max(-dc, 0), width - max(dc, 0))
        rn = slice(max(dr, 0), height + min(dr, 0))
        cn = slice(max(dc, 0), width + min(dc, 0))
        edge = ok[rn, cn].copy()
        if dr and dc:   # diagonal: both cells beside the step must be passable
            edge &= ok[r, cn] & ok[rn, c]
        rows.append(index[r, c][edge])
        cols.append(index[rn, cn][edge])
        data.append(weight[rn, cn][edge] * (SQRT2 if dr and dc else 1.0))
    return sparse.csr_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(costs.size, costs.size))
