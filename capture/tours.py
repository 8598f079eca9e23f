"""Short open tours through a matrix of move costs: nearest neighbour and index order, 2-opt.

:func:`open_tour` is how :mod:`capture.plan_order` orders a camera's lights and the cameras:
from node 0 (where the rig stands) through every other node of a cost matrix (the motion-time
model's move seconds, :mod:`rig.motion_time`), the better of a nearest-neighbour tour and the
given order (or its reverse), each improved by 2-opt.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["open_tour"]

#: 2-opt stops after this many passes over a tour (it usually converges in a handful).
_MAX_PASSES = 50

FloatArray = NDArray[np.float64]


def _tour_cost(cost: FloatArray, path: Sequence[int]) -> float:
    return float(sum(cost[a, b] for a, b in itertools.pairwise(path)))


def _two_opt(cost: FloatArray, path: list[int]) -> list[int]:
    """Improve an open path whose first node stays put by reversing segments (2-opt)."""
    p = np.array(path)
    n = len(p)
    for _ in range(_MAX_PASSES):
        improved = False
        for i in range(1, n - 1):
            j = np.arange(i + 1, n)
            last = j == n - 1
            after = p[np.minimum(j + 1, n - 1)]
            a, b, c = p[i - 1], p[i], p[j]
            delta = cost[a, c] - cost[a, b] + np.where(last, 0.0, cost[b, after] - cost[c, after])
            best = int(np.argmin(delta))
            if delta[best] < -1e-9:
                p[i : j[best] + 1] = p[i : j[best] + 1][::-1].copy()
                improved = True
        if not improved:
            break
    return [int(v) for v in p]


def _nearest_neighbour(cost: FloatArray) -> list[int]:
    n = cost.shape[0]
    path = [0]
    free = np.ones(n, dtype=bool)
    free[0] = False
    for _ in range(n - 1):
        row = np.where(free, cost[path[-1]], np.inf)
        nxt = int(np.argmin(row))
        path.append(nxt)
        free[nxt] = False
    return path


def open_tour(cost: FloatArray) -> list[int]:
    """A short open path from node 0 through every node of ``cost``; the nodes after 0.

    The better of nearest neighbour and the given order (1, 2, ...; or reversed), each improved
    by 2-opt.
    """
    n = cost.shape[0]
    if n <= 2:
        return list(range(1, n))
    candidates = [
        _nearest_neighbour(cost),
        list(range(n)),
        [0, *range(n - 1, 0, -1)],
    ]
    tours = [_two_opt(cost, c) for c in candidates]
    best = min(tours, key=lambda t: _tour_cost(cost, t))
    return best[1:]
