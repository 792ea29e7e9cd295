"""Leaves that follow the couplings: aggregates of aggregates of A's strong graph, by PyAMG's compiled kernels.

A coupling a_ij is strong when |a_ij| >= theta sqrt(|a_ii a_jj|) (smoothed aggregation's symmetric measure,
``pyamg.amg_core.symmetric_strength_of_connection``), theta :data:`THETA` unless the typical row holds no coupling that
strong (:func:`threshold`: wide stencils). Standard aggregation (``amg_core.standard_aggregation``:
a root and its strong neighbours, then the rest joined to a neighbouring aggregate) groups the rows; the
aggregates' own graph, with each pair's couplings summed in magnitude, is aggregated again, ``passes`` times in
all, so a leaf holds 10-40 rows that are strongly coupled to each other. With ``second='pairs'`` the passes after
the first match the aggregates in pairs instead (Notay's pairwise matching, ``amg_core.pairwise_aggregation``, by
each pair's share of both aggregates' outside couplings: :func:`pairs`): leaves of 3-17 rows. The share's threshold
:data:`PAIR_THETA` sits just below a regular aggregate's share with each of its four neighbours, 1/4 (above it no
pairs form): the foreign study's 5-point cases at 64k rows took 33/29/32/28 CG iterations at 0.24 against
34/30/33/30 at 0.2, and the DMDA program at 1024^2 37 against 39, with the same leaves' sizes. Everything is
O(nnz) and compiled (the kernels and scipy's sparse conversions): no Python loop over rows.

Rows are treated by what couples them:

- *decoupled* rows, whose off-diagonal entries are all zero or absent (a DMDA's Dirichlet rows, stored as
  identity rows with explicit zeros), are gathered into leaves of :data:`DECOUPLED_LEAF` rows of their own; the
  leaf solve is exact on them and they get no coarse vector (:class:`~petsc_htp.twolevel.leaflayout.LeafLayout`);
- rows with couplings but no strong one join the aggregate of their largest coupling;
- on several ranks, rows whose couplings to other ranks weigh half their diagonal or more
  (:func:`petsc_htp.ranksplit.cut_rows`) are leaves of one row each: the strong coupling a rank's aggregates
  cannot keep then lies between two coarse columns.

Within a leaf, rows keep the matrix's order, but where its numbering scatters the leaves
(:func:`.leaves.by_degree`).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .amgkernels import kernels
from .csr import drawn, indptr_of, row_entries

THETA = 0.08            # strength threshold (AMGCL's eps_strong and PyAMG's usual value for SA)
PASSES = 2              # aggregation passes: 2 gives leaves of 10-40 rows on 2-D and 3-D Poisson-type graphs
DECOUPLED_LEAF = 64     # rows per leaf of decoupled rows
PAIR_THETA = 0.24       # share of both aggregates' outside couplings that makes a pair (a 1e3 jump: about 0.02)
SECOND = ("standard", "pairs")   # kinds of the passes after the first
SAMPLE_ROWS = 4096      # rows sampled for the shares (:func:`sampled_shares`): the graph's shape, weak shares
THRESHOLD_ROWS = 1024   # ... and for each aggregation's threshold, a median (drawn: :func:`.csr.drawn`)
RELATIVE = 0.5          # ... its lowered threshold: this share of the median row's largest coupling
SQUARE_SAFE = 1e100     # entries whose products of two stay far from overflow and underflow (strength's kernel)


def decoupled_rows(A, start=0) -> np.ndarray:
    """Boolean (n,), read-only: rows of a CSR ``A`` (its diagonal in column ``start`` + row: a rank's rows with global
    columns) with no nonzero off-diagonal entry. Kept on ``A`` for its arrays and ``start``: a set-up reads a rank's
    rows once and asks this of them up to three times (each a pass over every entry)."""
    kept = getattr(A, "_decoupled", None)
    if kept is not None and kept[0] == start and all(a is b for a, b in zip(kept[1], (A.data, A.indices, A.indptr))):
        return kept[2]
    zeros = np.flatnonzero(A.data == 0)                     # explicit zeros: few, counted per row
    stored = np.diff(A.indptr) - np.bincount(np.searchsorted(A.indptr, zeros, side="right") - 1,
                                             minlength=A.shape[0])
    lone = stored - (A.diagonal(k=start) != 0) == 0
    lone.flags.writeable = False
    A._decoupled = (start, (A.data, A.indices, A.indptr), lone)
    return lone


def decoupled_among(A, rows) -> np.ndarray:
    """Boolean, one per row of ``rows`` (indices into the square CSR ``A``): :func:`decoupled_rows` of those rows
    alone, reading only their entries."""
    where, owner = row_entries(A.indptr, rows)
    coupled = (A.data[where] != 0) & (A.indices[where] != rows[owner])
    return np.bincount(owner[coupled], minlength=rows.size) == 0


def strength(A, theta=THETA) -> sp.csr_matrix:
    """The strong couplings of ``A`` (diagonal kept): PyAMG's symmetric strength of connection, which compares
    |a_ij|^2 with theta^2 |a_ii a_jj|: entries beyond :data:`SQUARE_SAFE` either way are first scaled by a power of two
    near the largest (exact; the foreign study's 2-D DMDA matrix of 40 000 rows times 1e200 overflowed there, times
    1e-200 underflowed, and took 31 and 24 CG iterations against 13: ``results/robust-20261128/ab.txt``)."""
    n = A.shape[0]
    data = A.data
    top = max(float(data.max()), -float(data.min())) if data.size else 0.0     # no |data| copy
    if top > SQUARE_SAFE or 0 < top < 1 / SQUARE_SAFE:
        data = np.ldexp(data, -int(np.frexp(top)[1]))
    Sp, Sj, Sx = np.empty_like(A.indptr), np.empty_like(A.indices), np.empty_like(data)
    kernels("smoothed_aggregation").symmetric_strength_of_connection(n, theta, A.indptr, A.indices, data,
                                                                     Sp, Sj, Sx)
    nnz = int(Sp[-1])
    return sp.csr_matrix((Sx[:nnz], Sj[:nnz], Sp), shape=A.shape)


def sampled_shares(A, rows=SAMPLE_ROWS, picked=None) -> tuple:
    """The symmetric shares |a_ij| / sqrt(|a_ii a_jj|) of the nonzero off-diagonal entries of about ``rows`` evenly
    spaced rows of a square CSR ``A`` (or the sorted rows ``picked``; inf over a zero diagonal), each such row's
    largest, and the fraction of those entries that are positive (0.0 where there are none)."""
    picked = np.arange(0, A.shape[0], max(1, A.shape[0] // rows)) if picked is None else picked
    where, owner = row_entries(A.indptr, picked)
    col, signed = A.indices[where], A.data[where]
    val = np.abs(signed)
    off = np.flatnonzero((val != 0) & (col != picked[owner]))
    positive = float(np.mean(signed[off] > 0)) if off.size else 0.0
    root = np.sqrt(np.abs(A.diagonal()))          # scipy's C loop over every row: cheaper than the neighbours' rows
    scale = root[picked[owner[off]]] * root[col[off]]                 # roots first: no overflow at 1e200
    share = np.divide(val[off], scale, out=np.full(scale.size, np.inf), where=scale > 0)
    largest = np.zeros(picked.size)
    if off.size:                                                      # each sampled row's entries lie together
        first = np.flatnonzero(np.concatenate(([True], owner[off][1:] != owner[off][:-1])))
        largest[owner[off][first]] = np.maximum.reduceat(share, first)
    return share, largest[largest > 0], positive


def threshold(largest, theta=THETA) -> float:
    """The strength threshold for a matrix whose sampled rows' largest shares are ``largest``
    (:func:`sampled_shares`): ``theta``, or where the median row holds no coupling that strong, :data:`RELATIVE`
    times that row's largest share. A 27-point Laplacian's couplings are 1/26 of its diagonal: at theta they are all
    weak and every row a leaf of its own (a 64 000-row one then took 860 ms against GAMG's 313, its coarse solve a
    V-cycle on A itself), at 1/52 its aggregates hold 8-27 rows (276 ms, 15 CG iterations). The foreign study's
    matrices keep theta."""
    typical = float(np.median(largest)) if largest.size else np.inf
    return theta if typical >= theta else RELATIVE * typical


def standard(S) -> tuple:
    """(count, aggregate of each row, -1 where a row has no strong neighbour) of PyAMG's standard aggregation."""
    n = S.shape[0]
    agg, roots = np.empty(n, dtype=S.indices.dtype), np.empty(n, dtype=S.indices.dtype)
    count = kernels("smoothed_aggregation").standard_aggregation(n, S.indptr, S.indices, agg, roots)
    return int(count), agg.astype(np.int64)


def pairs(M, theta=PAIR_THETA) -> tuple:
    """(count, aggregate of every node) of one pairwise matching of the graph ``M`` (nonnegative weights): each node
    joins the unmatched neighbour that holds the largest share of both nodes' outside couplings,
    m_ij / sqrt(e_i e_j) with e_i = sum_(k != i) m_ik, where that share is at least ``theta``, or stays alone (so a
    pair does not straddle a coefficient jump, which a row-wise measure would prefer from the low side)."""
    n = M.shape[0]
    rows = np.repeat(np.arange(n), np.diff(M.indptr))
    off = rows != M.indices
    outside = np.bincount(rows[off], M.data[off], minlength=n)
    root = np.sqrt(outside)                                          # each root first: no overflow at any scale
    share = np.divide(M.data, np.maximum(root[rows] * root[M.indices], np.finfo(float).tiny),
                      out=np.zeros_like(M.data), where=off)           # a lone node's diagonal over 0: no overflow
    strong = off & (share >= theta)
    S = sp.csr_matrix((share[strong], M.indices[strong], indptr_of(rows[strong], n)), shape=M.shape)
    agg, cpts = np.empty(n, dtype=S.indptr.dtype), np.empty(n, dtype=S.indptr.dtype)
    count = kernels("smoothed_aggregation").pairwise_aggregation(n, S.indptr, S.indices, S.data, agg, cpts)
    return int(count), agg.astype(np.int64) - 1                    # the kernel numbers aggregates from 1


def _largest_neighbour(A, rows) -> np.ndarray:
    """For each of ``rows`` (each with a nonzero off-diagonal entry) the column of its largest |a_ij|, j != i."""
    sub = A[rows]
    r = np.repeat(np.arange(rows.size), np.diff(sub.indptr))
    weight = np.where(sub.indices != rows[r], np.abs(sub.data), -1.0)
    order = np.lexsort((-weight, r))                                    # each row's largest first
    first = np.concatenate(([0], np.cumsum(np.diff(sub.indptr))[:-1]))
    return sub.indices[order[first]].astype(np.int64)


def _pass(M, theta) -> tuple:
    """One aggregation pass over the graph ``M``: (count, aggregate of every node, every node placed)."""
    count, agg = standard(strength(M, theta))
    lone = np.flatnonzero(agg < 0)
    if lone.size:
        coupled = lone[~decoupled_among(M, lone)]
        if coupled.size:                                                # weak couplings only: the largest one
            host = agg[_largest_neighbour(M, coupled)]
            agg[coupled[host >= 0]] = host[host >= 0]
        lone = np.flatnonzero(agg < 0)
        agg[lone] = count + np.arange(lone.size)                        # whatever is left stands alone
        count += lone.size
    return count, agg


def _renumbered(agg, count) -> tuple:
    """(how many, ``agg`` numbered 0, 1, ... in the order of its numbers below ``count``) of the aggregates that
    ``agg`` holds."""
    used = np.zeros(count, dtype=bool)
    used[agg] = True
    return int(used.sum()), (np.cumsum(used) - 1)[agg]


def _graph(M, agg, count) -> sp.csr_matrix:
    """The aggregates' graph: each pair's couplings summed in magnitude (self couplings on the diagonal), as
    P^T |M| P with P the aggregation matrix (scipy's compiled sparse products)."""
    n = M.shape[0]
    P = sp.csr_matrix((np.ones(n), agg, np.arange(n + 1)), shape=(n, count))
    G = (P.T.tocsr() @ abs(M) @ P).tocsr()
    G.sort_indices()
    return G


def nodes(n, bs, offset=0) -> np.ndarray:
    """The node of each of ``n`` rows in nodes of ``bs`` rows, the first row ``offset`` rows into its node (a rank's
    rows that start inside a node: its first and last node may be partial)."""
    return (np.arange(n) + offset) // bs


def node_graph(A, node) -> sp.csr_matrix:
    """The graph of ``A``'s nodes (``node``: each row's, :func:`nodes`): the Frobenius norm of every node block
    (PyAMG's amalgamation for block matrices: :func:`_graph` of A's squared entries, then the root)."""
    G = _graph(sp.csr_matrix((np.square(A.data), A.indices, A.indptr), shape=A.shape), node,
               int(node[-1]) + 1 if node.size else 0)
    G.data = np.sqrt(G.data)
    return G


def aggregates(A, theta=None, passes=PASSES, bs=1, second="standard", offset=0, alone=None, lone=None,
               scale=1.0) -> np.ndarray:
    """The leaf of every row of a square CSR ``A``: ``passes`` aggregation passes over its strong couplings at ``theta``
    (None: :func:`threshold`'s for A times ``scale``; the standard passes after the first take the same on the
    aggregates' graph: each its own graph's lowered the rotated anisotropy's and took it from 61 to 128 CG iterations),
    those after the first of the kind ``second`` (one of :data:`SECOND`), decoupled rows in leaves of their own (see the
    module docstring), and the rows ``alone`` (boolean, optional: :func:`..ranksplit.cut_rows`) in leaves of one row
    each. With a block size ``bs`` > 1 the nodes' graph (:func:`node_graph`; the first row ``offset`` rows into its
    node) is aggregated, so a leaf holds whole nodes (``alone`` is not used). ``lone``: A's decoupled rows where already
    found (:func:`decoupled_rows`; not with ``bs`` > 1)."""
    if second not in SECOND:
        raise ValueError(f"unknown aggregation pass {second!r}; expected one of {', '.join(SECOND)}")
    n = A.shape[0]
    if bs > 1 and n:
        node = nodes(n, bs, offset)
        return aggregates(node_graph(A, node), theta, passes, second=second, scale=scale)[node]
    lone = decoupled_rows(A) if lone is None else lone
    alone = np.zeros(n, dtype=bool) if alone is None else alone & ~lone
    keep = np.flatnonzero(~lone & ~alone)
    part = np.full(n, -1, dtype=np.int64)
    count = 0
    if keep.size:
        whole = keep.size == n or not alone.any()        # decoupled rows stand alone in A's strong graph: no
        M = A if whole else A[keep][:, keep].tocsr()     # submatrix (8 ms of the DMDA's 262 144 rows), their
        agg = np.arange(M.shape[0])                      # aggregates dropped below
        if theta is None:
            theta = scale * threshold(sampled_shares(M, picked=drawn(M.shape[0], THRESHOLD_ROWS))[1])
        for step in range(passes):
            if step and second == "pairs":
                count, node = pairs(M)
            else:
                count, node = _pass(M, theta)
            agg = node[agg]
            if step + 1 < passes:
                M = _graph(M, node, count)
        if agg.size > keep.size:
            count, agg = _renumbered(agg[keep], count)
        part[keep] = agg
    if alone.any():                                                     # rows strongly coupled to other ranks
        part[alone] = count + np.arange(np.count_nonzero(alone))
        count += np.count_nonzero(alone)
    if lone.any():                                                      # decoupled rows: leaves of their own
        idle = np.flatnonzero(lone)
        part[idle] = count + np.arange(idle.size) // DECOUPLED_LEAF
    return part
