"""Formation shapes for any N and matching communication graphs.

Every shape points along +x (the first leg of the paper's route), puts UAV 0 (the leader) at the
origin and keeps every pair of slots at least ``spacing`` apart. Offsets are z^d rows
``(x, y, z, vx, vy, vz)`` [m, m/s] (the velocity part is 0: the formation moves as one).

- ``"v"``: the paper's V (eq. 22 for N = 5 with ``back = spacing``, ``side = 2 spacing``);
- ``"line_abreast"``: side by side across the track; ``"column"``: one behind the other;
- ``"wedge"``: a filled triangle, row r holding r + 1 UAVs; ``"grid"``: a square-ish block;
- ``"circle"``: a ring with neighbouring slots ``spacing`` apart.

:func:`k_nearest_adjacency` gives each UAV the k nearest slots as neighbours (both ways), joined by
a minimum spanning tree, so the graph always has the spanning tree the scenario requires, and a
UAV talks to a bounded number of others whatever N is.
"""

from __future__ import annotations

import math

import numpy as np

SHAPES = ("v", "line_abreast", "column", "wedge", "grid", "circle")

__all__ = ["SHAPES", "formation_offsets", "k_nearest_adjacency"]


def _alternating(count: int) -> np.ndarray:
    """0, +1, -1, +2, -2, ...: the side index of slot i in symmetric shapes."""
    i = np.arange(count)
    return np.where(i % 2 == 1, (i + 1) // 2, -(i // 2)).astype(float)


def formation_offsets(shape: str, n_uav: int, spacing: float = 20.0) -> np.ndarray:
    """(N, 6) formation offsets z^d of a named shape (see the module docstring) [m, m/s].

    Args:
        shape: one of :data:`SHAPES`.
        n_uav: N >= 1.
        spacing: the smallest distance between two slots [m], > 0.

    Raises:
        ValueError: for an unknown shape, N < 1 or spacing <= 0, naming the argument.
    """
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {SHAPES}, got {shape!r}")
    if isinstance(n_uav, bool) or not isinstance(n_uav, int | np.integer) or n_uav < 1:
        raise ValueError(f"n_uav must be an integer >= 1, got {n_uav!r}")
    if not (isinstance(spacing, int | float) and math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a finite number > 0 [m], got {spacing!r}")
    i = np.arange(n_uav)
    xy = np.zeros((n_uav, 2))
    if shape == "v":
        k = (i + 1) // 2  # pair index: slot i is in the k-th pair behind the apex
        xy[:, 0] = -spacing * k
        xy[:, 1] = 2 * spacing * k * np.where(i % 2 == 1, 1.0, -1.0)
    elif shape == "line_abreast":
        xy[:, 1] = spacing * _alternating(n_uav)
    elif shape == "column":
        xy[:, 0] = -spacing * i
    elif shape == "wedge":
        row = np.floor((np.sqrt(8 * i + 1) - 1) / 2)  # row r holds slots r(r+1)/2 .. r(r+3)/2
        col = i - row * (row + 1) / 2
        xy[:, 0] = -spacing * row
        xy[:, 1] = spacing * (col - row / 2)
    elif shape == "grid":
        cols = math.ceil(math.sqrt(n_uav))
        row, col = np.divmod(i, cols)
        xy[:, 0] = -spacing * row
        xy[:, 1] = spacing * _alternating(cols)[col]
    else:  # circle: the leader in front, the ring behind it
        radius = spacing / (2 * math.sin(math.pi / n_uav)) if n_uav > 1 else 0.0
        angle = 2 * math.pi * i / n_uav
        xy[:, 0] = radius * (np.cos(angle) - 1.0)
        xy[:, 1] = radius * np.sin(angle)
    offsets = np.zeros((n_uav, 6))
    offsets[:, :2] = xy
    return offsets


def _minimum_spanning_edges(distance: np.ndarray) -> np.ndarray:
    """(N - 1, 2) edges of a minimum spanning tree of a complete graph (Prim, O(N²) in numpy)."""
    n = len(distance)
    inside = np.zeros(n, dtype=bool)
    inside[0] = True
    best = distance[0].copy()  # cheapest link of every node to the tree
    parent = np.zeros(n, dtype=np.int64)
    edges = np.zeros((max(n - 1, 0), 2), dtype=np.int64)
    for k in range(n - 1):  # one node joins per round: N rounds of O(N) array work
        node = int(np.argmin(np.where(inside, np.inf, best)))
        edges[k] = parent[node], node
        inside[node] = True
        closer = distance[node] < best
        best = np.where(closer, distance[node], best)
        parent = np.where(closer, node, parent)
    return edges


def k_nearest_adjacency(offsets: np.ndarray, k: int = 4) -> np.ndarray:
    """(N, N) 0/1 communication graph: UAV i receives from its k nearest slots and from every
    slot that has i among its k nearest (a symmetric graph), plus the edges of a minimum spanning
    tree of the slots, so that every UAV is reachable.

    Args:
        offsets: (N, 6) or (N, 3) formation offsets [m].
        k: neighbours per UAV, >= 1 (fewer when N - 1 < k).
    """
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise ValueError(f"k must be an integer >= 1, got {k!r}")
    p = np.asarray(offsets, dtype=float)[:, :3]
    n = len(p)
    adjacency = np.zeros((n, n), dtype=np.int64)
    if n < 2:
        return adjacency
    # np.linalg.norm(p[:, None] - p[None], axis=-1) axis by axis: the same sums in the same
    # order, without the (N, N, 3) temporaries (a third of swarm_scenario(1000)'s build)
    distance, gap = np.zeros((n, n)), np.empty((n, n))
    for axis in range(p.shape[1]):
        np.subtract(p[:, axis, None], p[None, :, axis], out=gap)
        gap *= gap
        distance += gap
    np.sqrt(distance, out=distance)
    np.fill_diagonal(distance, np.inf)
    kk = min(int(k), n - 1)
    nearest = np.argpartition(distance, kk - 1, axis=1)[:, :kk]  # (N, k), ties broken by index
    adjacency[np.repeat(np.arange(n), kk), nearest.ravel()] = 1
    tree = _minimum_spanning_edges(distance)
    adjacency[tree[:, 0], tree[:, 1]] = 1
    adjacency = adjacency | adjacency.T
    np.fill_diagonal(adjacency, 0)
    return adjacency
