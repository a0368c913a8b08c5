"""Formation shapes for any N and k-nearest communication graphs."""

from __future__ import annotations

import numpy as np
import pytest

from uav_formation_env.config import PAPER_OFFSETS, FormationConfig, has_directed_spanning_tree
from uav_formation_env.formations import SHAPES, formation_offsets, k_nearest_adjacency


def min_pair_distance(offsets: np.ndarray) -> float:
    d = np.linalg.norm(offsets[:, None, :3] - offsets[None, :, :3], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(d.min())


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("n_uav", [2, 3, 5, 8, 20, 100])
def test_shapes_keep_the_spacing_and_put_the_leader_at_the_origin(shape: str, n_uav: int):
    offsets = formation_offsets(shape, n_uav, spacing=15.0)
    assert offsets.shape == (n_uav, 6)
    np.testing.assert_allclose(offsets[0], 0.0, atol=1e-12)
    assert (offsets[:, 2:] == 0).all()  # planar, and moving as one
    assert min_pair_distance(offsets) >= 15.0 - 1e-9
    assert (offsets[:, 0] <= 1e-9).all()  # every slot at or behind the leader (pointing +x)
    graph = k_nearest_adjacency(offsets, k=4)
    FormationConfig(tuple(map(tuple, offsets)), tuple(map(tuple, graph)))  # a valid formation


def test_the_v_of_spacing_10_is_the_papers():
    np.testing.assert_array_equal(formation_offsets("v", 5, spacing=10.0), np.array(PAPER_OFFSETS))


def test_exact_layouts():
    np.testing.assert_allclose(formation_offsets("column", 3, 20.0)[:, 0], [0, -20, -40])
    np.testing.assert_allclose(formation_offsets("line_abreast", 3, 20.0)[:, 1], [0, 20, -20])
    wedge = formation_offsets("wedge", 6, 10.0)[:, :2]
    np.testing.assert_allclose(
        wedge, [[0, 0], [-10, -5], [-10, 5], [-20, -10], [-20, 0], [-20, 10]]
    )
    ring = formation_offsets("circle", 6, 10.0)[:, :2]  # a hexagon of side 10: radius 10
    np.testing.assert_allclose(np.linalg.norm(ring - [-10.0, 0.0], axis=1), 10.0)
    grid = formation_offsets("grid", 9, 10.0)[:, :2]
    assert sorted(map(tuple, np.round(grid))) == sorted(
        (x, y) for x in (0.0, -10.0, -20.0) for y in (-10.0, 0.0, 10.0)
    )


def test_k_nearest_graph_on_a_grid():
    offsets = formation_offsets("grid", 25, 10.0)
    graph = k_nearest_adjacency(offsets, k=4)
    assert (graph == graph.T).all() and (np.diag(graph) == 0).all()
    assert has_directed_spanning_tree(graph)
    centre = int(np.argmin(np.linalg.norm(offsets[:, :2] - [-20.0, 0.0], axis=1)))
    neighbours = offsets[np.flatnonzero(graph[centre]), :2] - offsets[centre, :2]
    # an interior slot hears exactly its 4 lattice neighbours, 10 m away
    np.testing.assert_allclose(np.linalg.norm(neighbours, axis=1), 10.0)
    assert graph[centre].sum() == 4


def test_the_spanning_tree_joins_separate_clusters():
    # two far-apart pairs: k = 1 alone would give two components
    offsets = np.zeros((4, 6))
    offsets[:, 0] = [0.0, -10.0, -1000.0, -1010.0]
    graph = k_nearest_adjacency(offsets, k=1)
    assert has_directed_spanning_tree(graph)
    assert graph[1, 2] == 1 and graph.sum() == 6  # 2 k-nearest edges + 1 bridge, both ways


def test_degree_is_bounded_whatever_n():
    for n in (10, 100, 400):
        graph = k_nearest_adjacency(formation_offsets("wedge", n, 10.0), k=4)
        assert graph.sum(axis=1).max() <= 12  # k out, plus those choosing it, plus tree edges


@pytest.mark.parametrize(
    ("call", "pattern"),
    [
        (lambda: formation_offsets("star", 5), "shape must be one of"),
        (lambda: formation_offsets("v", 0), "n_uav must be an integer >= 1"),
        (lambda: formation_offsets("v", 5, spacing=-1.0), "spacing must be a finite number > 0"),
        (lambda: k_nearest_adjacency(np.zeros((3, 6)), k=0), "k must be an integer >= 1"),
    ],
)
def test_bad_arguments_are_named(call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call()


def _norm_graph(offsets: np.ndarray, k: int) -> np.ndarray:
    """k_nearest_adjacency with the distances of np.linalg.norm (the formula it computes axis by
    axis), as a reference."""
    p = offsets[:, :3]
    n = len(p)
    distance = np.linalg.norm(p[:, None] - p[None], axis=-1)
    np.fill_diagonal(distance, np.inf)
    adjacency = np.zeros((n, n), dtype=np.int64)
    nearest = np.argpartition(distance, k - 1, axis=1)[:, :k]
    adjacency[np.repeat(np.arange(n), k), nearest.ravel()] = 1
    from uav_formation_env.formations import _minimum_spanning_edges

    tree = _minimum_spanning_edges(distance)
    adjacency[tree[:, 0], tree[:, 1]] = 1
    adjacency = adjacency | adjacency.T
    np.fill_diagonal(adjacency, 0)
    return adjacency


@pytest.mark.parametrize("shape", SHAPES)
def test_k_nearest_distances_are_the_norms(shape: str) -> None:
    rng = np.random.default_rng(1)
    offsets = formation_offsets(shape, 37, 10.0)
    offsets[:, :3] += rng.normal(scale=0.7, size=(37, 3))  # no ties
    np.testing.assert_array_equal(k_nearest_adjacency(offsets, 3), _norm_graph(offsets, 3))


@pytest.mark.parametrize(
    "value, valid", [(1, True), (True, True), (1.0, True), (2, False), (-1, False), (0.5, False)]
)
def test_adjacency_entries_are_checked_whatever_their_type(value, valid: bool) -> None:
    rows = ((0, value), (1, 0))
    offsets = PAPER_OFFSETS[:2]
    if valid:
        FormationConfig(offsets, rows)
    else:
        with pytest.raises(ValueError, match="entries must be 0 or 1"):
            FormationConfig(offsets, rows)
