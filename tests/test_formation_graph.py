"""Communication graph: Laplacian, H, Assumption 1 (design §1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bioform_mj.core.errors import GraphError
from bioform_mj.formation import graph


def test_paper_default_topology_matrices():
    g = graph.from_edges(3, [(1, 2), (1, 3)], [1])
    L = g.laplacian()
    np.testing.assert_array_equal(L, [[2, -1, -1], [-1, 1, 0], [-1, 0, 1]])
    H = g.H()
    np.testing.assert_array_equal(H, L + np.diag([1, 0, 0]))
    assert np.linalg.eigvalsh(H).min() > 0.1


@pytest.mark.parametrize(
    "builder,n,m", [(graph.chain, 5, 4), (graph.ring, 5, 5), (graph.star, 5, 4), (graph.complete, 5, 10)]
)
def test_builders_edge_counts_and_degrees(builder, n, m):
    g = builder(n)
    assert len(g.edges) == m
    assert g.degree.sum() == 2 * m
    assert np.allclose(g.laplacian().sum(axis=1), 0.0)
    assert np.linalg.eigvalsh(g.H()).min() > 0


def test_disconnected_graph_names_cut_off_followers():
    with pytest.raises(GraphError, match=r"follower\(s\) 4, 5 cannot reach the leader"):
        graph.from_edges(5, [(1, 2), (2, 3), (4, 5)], [1])


def test_no_leader_access_refused():
    with pytest.raises(GraphError, match="no follower has leader access"):
        graph.from_edges(3, [(1, 2), (2, 3)], [])


@pytest.mark.parametrize(
    "edges,match", [([(1, 1)], "self-loop"), ([(1, 2), (2, 1)], "more than once"), ([(1, 4)], "outside 1..3")]
)
def test_malformed_edges(edges, match):
    with pytest.raises(GraphError, match=match):
        graph.from_edges(3, edges, [1])


@settings(max_examples=150, deadline=None)
@given(
    st.integers(1, 9).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.sets(st.tuples(st.integers(1, n), st.integers(1, n)).filter(lambda e: e[0] < e[1]), max_size=n * 2),
            st.sets(st.integers(1, n), max_size=n),
        )
    )
)
def test_H_positive_definite_exactly_when_assumption_holds(case):
    n, edges, access = case
    g = graph.Graph(
        n,
        np.array(sorted(edges), dtype=int).reshape(-1, 2) - 1 if edges else np.zeros((0, 2), int),
        np.isin(np.arange(1, n + 1), list(access)).astype(float),
    )
    pd = np.linalg.eigvalsh(g.H()).min() > 1e-9
    try:
        g.check()
        ok = True
    except GraphError:
        ok = False
    assert ok == pd
