"""Visiting order of the sample poses, and the robot's motion time.

Motion time between two poses is that of a synchronised joint move at the vendor's velocity
limits (every joint arrives together; acceleration neglected): ``max_j |Δq_j| / v_j``, scaled by
the speed override a lab runs at. Orders compared: the naive raster (grid index order), the
serpentine (boustrophedon over the grid), and nearest-neighbour followed by 2-opt on the motion
time metric, starting from the pose the robot is in.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import ArrayLike

from brachycal.se3 import FloatArray


def move_times(Q: ArrayLike, velocity_limit: ArrayLike, speed_scale: float = 1.0) -> FloatArray:
    """``(N, N)`` seconds between configurations ``(N, nq)`` at ``speed_scale`` × the limits."""
    Q = np.asarray(Q, dtype=float)
    return np.max(np.abs(Q[:, None, :] - Q[None, :, :]) / (np.asarray(velocity_limit) * speed_scale), axis=2)


def path_time(order: ArrayLike, times: FloatArray, start: int | None = None) -> float:
    """Total seconds visiting ``order``; from node ``start`` first if given."""
    nodes: list[int] = np.asarray(order).tolist()
    if start is not None:
        nodes = [start, *nodes]
    return float(sum(times[a, b] for a, b in itertools.pairwise(nodes)))


def raster(index: ArrayLike) -> np.ndarray:
    """Grid index order: i fastest, then j, then k, each row from the same end."""
    index = np.asarray(index)
    return np.lexsort((index[:, 0], index[:, 1], index[:, 2]))


def serpentine(index: ArrayLike) -> np.ndarray:
    """Boustrophedon: i alternates direction along each row, rows alternate within a layer."""
    index = np.asarray(index)
    n = index.max(axis=0) + 1
    key_j = np.where(index[:, 2] % 2 == 0, index[:, 1], n[1] - 1 - index[:, 1])
    row = index[:, 2] * n[1] + key_j
    key_i = np.where(row % 2 == 0, index[:, 0], n[0] - 1 - index[:, 0])
    return np.lexsort((key_i, key_j, index[:, 2]))


def nearest_neighbour_two_opt(times: FloatArray, start: int) -> np.ndarray:
    """An open path over all nodes but ``start`` (the current pose), beginning next to it.

    Nearest neighbour builds a path, then 2-opt reverses segments while that shortens it.
    ``times`` must be symmetric (it is: joint moves are reversible).
    """
    n = len(times)
    left = set(range(n)) - {start}
    path = [start]
    while left:
        nxt = min(left, key=lambda j: times[path[-1], j])
        path.append(nxt)
        left.remove(nxt)
    improved = True
    while improved:
        improved = False
        for i in range(1, n - 1):
            for j in range(i + 1, n):
                a, b = path[i - 1], path[i]
                c = path[j]
                d = path[j + 1] if j + 1 < n else None
                before = times[a, b] + (times[c, d] if d is not None else 0.0)
                after = times[a, c] + (times[b, d] if d is not None else 0.0)
                if after < before - 1e-12:
                    path[i : j + 1] = path[i : j + 1][::-1]
                    improved = True
    return np.array(path[1:])
