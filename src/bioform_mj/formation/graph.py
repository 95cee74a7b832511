"""Communication graph of the followers (paper Sec. II-A).

Followers are numbered ``0 … n-1`` inside the library and ``1 … n`` in files,
CLI flags and messages. The graph is undirected with unit weights ``a_ij``; the
leader-access vector ``a_ir`` says which followers read the virtual leader.

Everything the control step needs is kept as edge lists (``O(edges)``); the dense
Laplacian ``L`` and ``H = L + diag(a)`` (eq. 2) are built only on request, for
analysis and tests.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from bioform_mj.core.errors import GraphError

__all__ = [
    "Graph",
    "from_edges",
    "chain",
    "ring",
    "star",
    "complete",
]


@dataclass(frozen=True)
class Graph:
    """Undirected follower graph with leader access.

    Attributes
    ----------
    n : int
        Number of followers.
    edges : ndarray, shape (m, 2), int
        Undirected edges ``(i, j)``, ``i < j``, 0-based, unique.
    leader_access : ndarray, shape (n,), float
        ``a_ir`` in {0, 1}.
    """

    n: int
    edges: np.ndarray
    leader_access: np.ndarray
    src: np.ndarray = field(init=False, repr=False)
    dst: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        e = np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)
        object.__setattr__(self, "edges", e)
        object.__setattr__(self, "leader_access", np.asarray(self.leader_access, dtype=float).reshape(-1))
        # Both directions: row k says "follower src[k] reads follower dst[k]".
        object.__setattr__(self, "src", np.concatenate([e[:, 0], e[:, 1]]))
        object.__setattr__(self, "dst", np.concatenate([e[:, 1], e[:, 0]]))

    @property
    def degree(self) -> np.ndarray:
        """Number of neighbours of each follower, shape (n,)."""
        return np.bincount(self.src, minlength=self.n)

    def neighbours(self, i: int) -> np.ndarray:
        """0-based ids of the followers that follower ``i`` reads."""
        return np.sort(self.dst[self.src == i])

    def laplacian(self) -> np.ndarray:
        """Dense graph Laplacian ``L`` (n, n). For analysis only (O(n²) memory)."""
        L = np.zeros((self.n, self.n))
        np.add.at(L, (self.src, self.dst), -1.0)
        L[np.diag_indices(self.n)] = self.degree
        return L

    def H(self) -> np.ndarray:
        """Dense ``H = L + diag(a)`` (eq. 2), positive definite under Assumption 1."""
        return self.laplacian() + np.diag(self.leader_access)

    def unreachable(self) -> np.ndarray:
        """0-based ids of followers with no path to a leader-connected follower.

        O(n + edges) breadth-first search from every follower with ``a_ir = 1``.
        """
        reached = self.leader_access > 0
        frontier = np.flatnonzero(reached)
        order = np.argsort(self.src, kind="stable")
        starts = np.searchsorted(self.src[order], np.arange(self.n + 1))
        dst_sorted = self.dst[order]
        while frontier.size:
            nb = (
                np.concatenate([dst_sorted[starts[i] : starts[i + 1]] for i in frontier]) if frontier.size else frontier
            )
            nb = np.unique(nb)
            nb = nb[~reached[nb]]
            reached[nb] = True
            frontier = nb
        return np.flatnonzero(~reached)

    def check(self) -> None:
        """Raise :class:`GraphError` unless every follower can reach the leader.

        This is exactly the condition under which ``H`` is positive definite
        (Lemma 1). The paper's Assumption 1 (connected follower graph and at least
        one ``a_ir = 1``) implies it; a disconnected graph whose every component
        has a leader-connected follower also satisfies it and is accepted.
        """
        if not np.any(self.leader_access > 0):
            raise GraphError("no follower has leader access (Assumption 1 needs some a_ir = 1)")
        cut = self.unreachable()
        if cut.size:
            ids = ", ".join(str(i + 1) for i in cut[:20]) + (" …" if cut.size > 20 else "")
            raise GraphError(
                f"follower(s) {ids} cannot reach the leader: no path to a follower with leader access (Assumption 1)"
            )


def from_edges(n: int, edges: Iterable[Sequence[int]], leader_access: Iterable[int]) -> Graph:
    """Build and check a graph from 1-based edges and 1-based leader-access ids.

    Raises :class:`GraphError` on self-loops, duplicate edges, out-of-range ids,
    or a graph that violates Assumption 1.
    """
    if n < 1:
        raise GraphError(f"need at least one follower, got n = {n}")
    e = [tuple(int(v) for v in edge) for edge in edges]
    for edge in e:
        if len(edge) != 2:
            raise GraphError(f"edge {list(edge)} must have two follower ids")
        i, j = edge
        if not (1 <= i <= n and 1 <= j <= n):
            raise GraphError(f"edge ({i}, {j}) names a follower outside 1..{n}")
        if i == j:
            raise GraphError(f"edge ({i}, {j}) is a self-loop")
    arr = np.array([(min(i, j) - 1, max(i, j) - 1) for i, j in e], dtype=np.int64).reshape(-1, 2)
    if arr.size:
        uniq, counts = np.unique(arr, axis=0, return_counts=True)
        if np.any(counts > 1):
            i, j = uniq[np.argmax(counts > 1)] + 1
            raise GraphError(f"edge ({i}, {j}) is listed more than once")
    access = np.zeros(n)
    for k in leader_access:
        k = int(k)
        if not 1 <= k <= n:
            raise GraphError(f"leader access names follower {k}, outside 1..{n}")
        if access[k - 1]:
            raise GraphError(f"leader access lists follower {k} more than once")
        access[k - 1] = 1.0
    g = Graph(n, arr, access)
    g.check()
    return g


def chain(n: int, leader_access: Iterable[int] = (1,)) -> Graph:
    """Path 1–2–…–n."""
    return from_edges(n, [(i, i + 1) for i in range(1, n)], leader_access)


def ring(n: int, leader_access: Iterable[int] = (1,)) -> Graph:
    """Cycle 1–2–…–n–1 (a chain for n ≤ 2)."""
    edges = [(i, i + 1) for i in range(1, n)]
    if n > 2:
        edges.append((n, 1))
    return from_edges(n, edges, leader_access)


def star(n: int, center: int = 1, leader_access: Iterable[int] = (1,)) -> Graph:
    """Every follower linked to ``center`` (1-based)."""
    if not 1 <= center <= n:
        raise GraphError(f"star centre {center} is outside 1..{n}")
    return from_edges(n, [(center, j) for j in range(1, n + 1) if j != center], leader_access)


def complete(n: int, leader_access: Iterable[int] = (1,)) -> Graph:
    """All pairs linked (O(n²) edges: small teams only)."""
    return from_edges(n, [(i, j) for i in range(1, n + 1) for j in range(i + 1, n + 1)], leader_access)
