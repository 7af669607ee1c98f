"""Finding a plant's points in the plot's cloud (the labels of ``cloud.ply``), and the sparse
graphs of point pairs the organ step searches."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from fieldapp.recon.organs import pair_graph, pair_lengths
from fieldapp.recon.result import RowFinder


def test_rows_are_found_bit_for_bit_or_within_a_tenth_of_a_micrometre() -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform(-2.0, 2.0, (5000, 3))
    points[10] = [0.0, 0.0, 0.0]
    picked = rng.permutation(5000)[:700]
    queries = np.concatenate(
        [
            points[picked],
            [[-0.0, 0.0, -0.0]],  # equal to row 10, other bits
            points[20:21] + 3e-8,  # within 0.1 micrometre
            points[30:31] + 1e-5,  # not there
            [[9.0, 9.0, 9.0]],
        ]
    )
    found = RowFinder(points).find(queries)
    np.testing.assert_array_equal(found, [*picked, 10, 20, -1, -1])
    assert RowFinder(points).find(np.zeros((0, 3))).shape == (0,)


def test_pair_graphs_are_searched_as_sorted_ones() -> None:
    """The graph left with its rows' columns unsorted gives the same shortest paths and
    components as the one scipy sorts."""
    points = np.random.default_rng(1).uniform(0.0, 0.1, (800, 3))
    pairs = cKDTree(points).query_pairs(0.012, output_type="ndarray")
    weights = pair_lengths(points, pairs) + 1e-9
    fast = pair_graph(pairs, len(points), weights)
    sorted_ = coo_matrix((weights, (pairs[:, 0], pairs[:, 1])), shape=(800, 800)).tocsr()
    np.testing.assert_array_equal(
        dijkstra(fast, directed=False, indices=[0, 5], min_only=True),
        dijkstra(sorted_, directed=False, indices=[0, 5], min_only=True),
    )
    np.testing.assert_allclose(
        weights - 1e-9, np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    )
    few = pairs[weights < 0.006]
    assert (
        connected_components(pair_graph(few, 800), directed=False)[0]
        == (
            connected_components(
                coo_matrix((np.ones(len(few)), few.T), shape=(800, 800)), directed=False
            )[0]
        )
    )
