"""Coordinates for the rows of a bare matrix, from breadth-first distances in its graph.

A matrix handed over without coordinates still usually comes from a grid. On a 2-D grid graph the
distance from a corner p is |x - x_p| + |y - y_p|, so differences of distances from two pairs of far
apart nodes (opposite corners, and the other two corners, found where a first guess from the two ends of the
first pair's midpoint set is extreme, farthest from that midpoint set) are the grid's diagonal coordinates; rotated by 45 degrees they
are its x and y. Eight breadth-first searches give them, in a few milliseconds where a METIS partition
takes hundreds; Morton leaves on them
(:func:`petsc_htp.twolevel.leaves.choose_leaves`) are the grid's square blocks whatever the row order. On a
graph that is not 2-D-like (level sizes around a corner growing faster than linearly, as in 3-D) or
not connected, :func:`grid_coordinates` returns None and the caller partitions otherwise.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

MAX_SLOPE = 1.25    # log-log growth of BFS level sizes from a corner above which the graph is not 2-D-like


def bfs_levels(G, sources) -> np.ndarray:
    """Distance of every node from the nearest of ``sources`` along the rows of the CSR pattern G (-1: unreachable).

    One breadth-first search from a virtual node joined to every source; depths come from the search
    order, whose nodes' parents appear in order too, by cutting it where the parents cross into a new level.
    """
    n = G.shape[0]
    src = np.unique(np.atleast_1d(np.asarray(sources, dtype=G.indices.dtype)))
    H = sp.csr_matrix((np.ones(G.nnz + src.size, dtype=np.int8), np.concatenate([G.indices, src]),
                       np.concatenate([G.indptr, [G.nnz + src.size]])), shape=(n + 1, n + 1))
    H.has_canonical_format = G.has_canonical_format         # spare the search a sorted copy
    from scipy.sparse.csgraph import breadth_first_order      # not at import: it loads scipy.sparse.linalg

    order, pred = breadth_first_order(H, n, directed=True, return_predecessors=True)
    where = np.empty(n + 1, dtype=np.int64)
    where[order] = np.arange(order.size)
    parent = where[np.maximum(pred[order], 0)]
    parent[0] = -1
    cuts = [0, 1]
    while cuts[-1] < order.size:
        cuts.append(int(np.searchsorted(parent, cuts[-1], "left")))
    depth = np.full(n + 1, 0, dtype=np.int64)
    depth[order] = np.repeat(np.arange(len(cuts) - 1), np.diff(cuts))
    out = depth[:n] - 1
    reached = np.zeros(n + 1, dtype=bool)
    reached[order] = True
    out[~reached[:n]] = -1
    return out


def _growth(levels) -> float:
    """Log-log slope of the level sizes around a corner over the first third of the levels (2-D: 1, 3-D: 2)."""
    sizes = np.bincount(levels)
    r = np.arange(2, max(3, sizes.size // 3))
    r = r[r < sizes.size]
    if r.size < 3:
        return 1.0
    return float(np.polyfit(np.log(r), np.log(np.maximum(sizes[r], 1)), 1)[0])


def grid_coordinates(G) -> np.ndarray | None:
    """(n, 2) coordinates from eight breadth-first searches, or None if the graph is not 2-D-like or not connected.

    Parameters
    ----------
    G : scipy.sparse.csr_matrix
        A structurally symmetric matrix; only its pattern is read (self loops do no harm).
    """
    n = G.shape[0]
    G = sp.csr_matrix((np.ones(G.nnz, dtype=np.int8), G.indices.copy(), G.indptr.copy()), shape=G.shape)
    G.sum_duplicates()                                      # sorted once (a copy: the caller's A stays as it is)
    d0 = bfs_levels(G, 0) if n >= 4 else None
    if d0 is None or d0.min() < 0:
        return None
    p1 = int(np.argmax(d0))
    d1 = bfs_levels(G, p1)
    if _growth(d1) > MAX_SLOPE:
        return None
    d2 = bfs_levels(G, int(np.argmax(d1)))
    mid = np.flatnonzero(np.abs(d1 - d2) <= 1)
    dq = bfs_levels(G, int(mid[0]))
    p3 = int(mid[np.argmax(dq[mid])])
    d3 = bfs_levels(G, p3)
    b = d3 - bfs_levels(G, int(mid[np.argmax(d3[mid])]))
    a = d1 - d2
    ends = [int(np.flatnonzero(b == v)[np.argmax(np.abs(a[b == v]))]) for v in (b.max(), b.min())]
    b = bfs_levels(G, ends[0]) - bfs_levels(G, ends[1])                           # the other two corners
    return np.column_stack([a + b, a - b]).astype(np.float64)
