"""Leaves: groups of about ``leaf`` rows that a two-level preconditioner treats as blocks.

A :class:`Leaves` is a row permutation plus the offsets of contiguous groups in
it: leaf k is the rows ``perm[offsets[k]:offsets[k + 1]]`` of the caller's matrix.
Contiguous chunks of an ordering (RCM, the given order), Morton chunks cut at quadtree
boundaries, or METIS parts.
"""
from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .aggregation import aggregates
from .csr import compact
from .embedding import grid_coordinates
from ..morton import quantized_morton_codes
from ..ordering import check_coords, check_square, choose_ordering

LAYOUTS = ("auto", "aggregation", "morton", "graph", "metis", "natural", "rcm")
CUT_FACTOR = 2.5    # graph leaves cutting more than this / sqrt(leaf) of A's couplings fall back to METIS
SLACK = 0.25        # a Morton leaf has leaf * (1 +- SLACK) rows
A_ORDER_SPAN = 32768   # median rows spanned by a leaf from which D goes in the leaves' order (leaflayout)
SCATTERED = 0.25       # ... or this share of the rows, from which A's numbering scatters the leaves (part_leaves)


@dataclass(frozen=True, eq=False)
class Leaves:
    """A permutation grouping each leaf's rows contiguously.

    Attributes
    ----------
    perm : numpy.ndarray of int32 (int64 from 2^31 rows), shape (N,)
        ``A[perm][:, perm]`` puts each leaf's rows contiguously.
    offsets : numpy.ndarray of int64, shape (K + 1,)
        Leaf k holds permuted rows ``offsets[k]:offsets[k + 1]``.
    kind : str
        How the leaves were made ('morton', 'metis', ...).
    build_ms : float
        Time to make them (ordering or METIS), in ms.
    """

    perm: np.ndarray
    offsets: np.ndarray
    kind: str
    build_ms: float = 0.0

    def __post_init__(self):
        perm = np.asarray(self.perm, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.int64)
        n = perm.size
        if n == 0 or perm.min() < 0 or perm.max() >= n or np.bincount(perm, minlength=n).max() != 1:
            raise ValueError(f"leaves: perm must be a permutation of 0..N-1 (N >= 1), got size {n}")
        if offsets.ndim != 1 or offsets.size < 2 or offsets[0] != 0 or offsets[-1] != n \
                or np.any(np.diff(offsets) <= 0):
            raise ValueError(f"leaves: offsets must rise strictly from 0 to N={n}")
        object.__setattr__(self, "perm", compact(perm, n))
        object.__setattr__(self, "offsets", offsets)

    @property
    def n(self) -> int:
        """Number of rows N."""
        return int(self.perm.size)

    @property
    def n_leaves(self) -> int:
        """Number of leaves K."""
        return int(self.offsets.size - 1)

    @property
    def sizes(self) -> np.ndarray:
        """Rows per leaf, shape (K,)."""
        return np.diff(self.offsets)

    @property
    def max_size(self) -> int:
        """Largest leaf (the padded leaf size)."""
        return int(self.sizes.max())


def _positive_int(value, name):
    """Return ``value`` as a positive int, or raise ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value <= 0:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def contiguous_leaves(n, leaf=128, perm=None, kind="natural", build_ms=0.0) -> Leaves:
    """Cut an ordering into ceil(n / leaf) contiguous leaves of near-equal size.

    The first ``n % K`` leaves have one row more, as PETSc's ``PCBJACOBI`` splits its blocks, so
    contiguous leaves of the given order are exactly ``-pc_bjacobi_local_blocks K``'s blocks.

    Parameters
    ----------
    n : int
        Number of rows.
    leaf : int
        Target leaf size.
    perm : array_like of int, optional
        The ordering (identity when None).
    kind : str
        Name recorded in the result.
    """
    n, leaf = _positive_int(n, "n"), _positive_int(leaf, "leaf")
    perm = np.arange(n, dtype=np.int64) if perm is None else perm
    k = math.ceil(n / leaf)
    sizes = n // k + (np.arange(k) < n % k)
    return Leaves(perm, np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64), kind, build_ms)


def morton_leaves(codes, leaf=128, perm=None, kind="morton", build_ms=0.0, slack=SLACK) -> Leaves:
    """Cut a Morton order into leaves at its coarsest quadtree boundaries.

    Each cut lies within ``slack * leaf`` rows of ``leaf`` rows after the previous one, where
    consecutive codes differ in the highest bit (nearest the target among ties). On a full
    power-of-two grid these are the ``leaf``-cell quadtree blocks, as plain chunks would be;
    with holes (an obstacle) plain chunks straddle two blocks and often fall apart, cut leaves do not.

    Parameters
    ----------
    codes : array_like of int, shape (N,)
        Morton codes of the rows in the order ``perm`` (non-decreasing).
    leaf : int
        Target leaf size.
    perm, kind, build_ms
        As in :func:`contiguous_leaves`.
    slack : float
        Largest relative deviation of a leaf's size from ``leaf``.
    """
    codes = np.asarray(codes, dtype=np.int64)
    n, leaf = _positive_int(codes.size, "n"), _positive_int(leaf, "leaf")
    if np.any(np.diff(codes) < 0):
        raise ValueError("morton_leaves: codes must be non-decreasing (rows in Morton order)")
    level = np.zeros(n, dtype=np.int64)
    level[1:] = np.frexp((codes[1:] ^ codes[:-1]).astype(np.float64))[1]      # highest differing bit + 1
    width = int(slack * leaf)
    cuts = _block_cuts(level, leaf, width)
    if cuts is None:
        cuts, level = [0], level.tolist()
        while n - cuts[-1] > leaf + width:
            target = cuts[-1] + leaf
            lo, hi = target - width, min(target + width, n - 1)
            top = max(level[lo:hi + 1])
            cuts.append(min((i for i in range(lo, hi + 1) if level[i] == top), key=lambda i: abs(i - target)))
    perm = np.arange(n, dtype=np.int64) if perm is None else perm
    return Leaves(perm, np.array(cuts + [n], dtype=np.int64), kind, build_ms)


def _block_cuts(level, leaf, width):
    """The cuts of :func:`morton_leaves` without its loop where they are every ``leaf`` rows (a power of two):
    the boundaries of the ``leaf``-cell quadtree blocks, found at once; None where the blocks are uneven."""
    if leaf & (leaf - 1):
        return None
    bounds = np.flatnonzero(level >= leaf.bit_length())
    n = level.size
    bounds = bounds[bounds <= max(n - leaf - width - 1, 0) + leaf]      # the loop stops leaf + width before n
    if bounds.size and (bounds[0] != leaf or np.any(np.diff(bounds) != leaf)):
        return None
    cuts = [0] + bounds.tolist()
    return cuts if n - cuts[-1] <= leaf + width else None


RECURSIVE_PARTS = 64       # METIS by recursive bisection above this many parts (see metis_leaves)


def _metis_graph(A):
    """xadj, adjncy of the symmetric graph of ``A`` without self loops."""
    C = sp.csr_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
    S = (C + C.T).tocoo()
    off = S.row != S.col
    G = sp.csr_matrix((S.data[off], (S.row[off], S.col[off])), shape=A.shape)
    return G.indptr, G.indices


def _within_parts_rcm(A, parts):
    """Each row's position in the reverse Cuthill-McKee order of the graph of A without its cut edges."""
    C = A.tocoo()
    keep = parts[C.row] == parts[C.col]
    G = sp.csr_matrix((np.ones(int(keep.sum())), (C.row[keep], C.col[keep])), shape=A.shape)
    from scipy.sparse.csgraph import reverse_cuthill_mckee     # not at import: it loads scipy.sparse.linalg

    order = reverse_cuthill_mckee(G, symmetric_mode=False)
    position = np.empty(A.shape[0], dtype=np.int64)
    position[order] = np.arange(A.shape[0])
    return position


def metis_leaves(A, leaf=128, seed=0) -> Leaves:
    """METIS parts of A's graph, ceil(n / leaf) of them, as leaves.

    Over :data:`RECURSIVE_PARTS` parts by recursive bisection, whose time grows with log(parts) where k-way's
    grows with the parts (a bare 3-D 32^3 matrix into 512 leaves: 169 against 389 ms, 35 against 33 CG
    iterations); fewer parts k-way, whose leaves are better (2-D FEM, 20 parts: 35 against 39). The
    partition is deterministic for a given ``seed``; empty parts are dropped and the rows of a part are in the reverse Cuthill-McKee order of the part's own graph, so
    that position within a leaf is a smooth coordinate whatever the given row order.
    """
    import pymetis

    A = check_square(A)
    leaf = _positive_int(leaf, "leaf")
    n = _positive_int(A.shape[0], "the size of A")
    t0 = time.perf_counter()
    nparts = math.ceil(n / leaf)
    if nparts == 1:
        parts = np.zeros(n, dtype=np.int64)
    else:
        _, parts = pymetis.part_graph(nparts, pymetis.CSRAdjacency(*_metis_graph(A)),
                                      options=pymetis.Options(seed=int(seed)),
                                      recursive=nparts > RECURSIVE_PARTS)
        parts = np.asarray(parts, dtype=np.int64)
    return part_leaves(A, parts, "metis", t0)


def part_leaves(A, parts, kind, t0, smooth=True) -> Leaves:
    """Leaves from the part of every row (empty parts dropped); ``t0`` is when making them started (perf_counter).

    With ``smooth``, each part's rows are in the reverse Cuthill-McKee order of its own graph, else in the given
    order: small aggregates (10-40 rows) take the same iterations either way (the eig space's one inverse-iteration
    step smooths its seed), without RCM's 15-20 ms at N = 65536. Where A's numbering scatters the parts (a mesh
    numbered at random: a part's rows span :data:`A_ORDER_SPAN` rows, or :data:`SCATTERED` of them, in the median,
    :func:`median_span`), A's order within a part is a random one, whose leaf factor fills in: the rows then go by
    :func:`by_degree`."""
    sizes = np.bincount(parts)
    offsets = np.concatenate(([0], np.cumsum(sizes[sizes > 0])))
    if smooth:
        perm = np.lexsort((_within_parts_rcm(A, parts), parts))
    else:
        perm = np.argsort(parts, kind="stable")
        if median_span(perm, offsets) >= min(A_ORDER_SPAN, SCATTERED * parts.size):
            perm = by_degree(A, parts, perm)
    return Leaves(perm, offsets, kind, (time.perf_counter() - t0) * 1e3)


def median_span(perm, offsets) -> float:
    """The median over leaves (rows ``perm[offsets[k]:offsets[k + 1]]``) of the rows of A a leaf spans (0: none)."""
    if len(offsets) < 2:
        return 0.0
    return float(np.median(np.maximum.reduceat(perm, offsets[:-1]) - np.minimum.reduceat(perm, offsets[:-1])))


def by_degree(A, parts, perm) -> np.ndarray:
    """``perm`` (rows grouped by part) with each part's rows by how many nonzero couplings they hold inside their part,
    fewest first (ties in the given order): a minimum-degree-like order that the leaf factor's natural ordering
    keeps. On the foreign study's matrices at about 64k rows numbered at random, the leaf factor then holds
    178 000 against 268 000 values (the free surface), 275 000 against 422 000 (P1 triangles), 559 000 against
    1 011 000 (P1 tets), and a leaf solve takes 0.65 against 0.82, 0.79 against 1.03 and 1.10 against 1.59 ms
    (``results/numbering-20261126/fill.py``)."""
    counts = np.diff(A.indptr)
    inside = (parts[A.indices] == np.repeat(parts, counts)) & (A.data != 0)      # the diagonal too: one more each
    degree = np.where(counts > 0, np.add.reduceat(inside, np.minimum(A.indptr[:-1], inside.size - 1),
                                                   dtype=np.int32), 0) if inside.size else counts
    return perm[np.lexsort((degree[perm], parts[perm]))]


def _morton(A, coords, leaf, given_ok, kind, t0) -> Leaves:
    """Morton leaves from coordinates (kept in the given order when it already is Morton's and ``given_ok``)."""
    codes = quantized_morton_codes(np.asarray(coords, dtype=np.float64)).astype(np.int64)
    if given_ok and np.all(codes[1:] >= codes[:-1]):
        return morton_leaves(codes, leaf, None, kind + " (given)", (time.perf_counter() - t0) * 1e3)
    perm = np.argsort(codes, kind="stable").astype(np.int64)
    return morton_leaves(codes[perm], leaf, perm, kind, (time.perf_counter() - t0) * 1e3)


def _cut_fraction(A, leaves) -> float:
    """Share of A's stored off-diagonal entries that couple two leaves."""
    leaf = np.empty(leaves.n, dtype=np.int64)
    leaf[leaves.perm] = np.repeat(np.arange(leaves.n_leaves), leaves.sizes)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    off = rows != A.indices
    return float(np.count_nonzero(leaf[rows[off]] != leaf[A.indices[off]]) / max(np.count_nonzero(off), 1))


def choose_leaves(A, coords=None, layout="auto", leaf=128, bs=1, second="standard", theta=None, offset=0,
                  alone=None) -> Leaves:
    """Leaves for ``A`` by layout.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, N)
    coords : array_like, shape (N, 2), optional
        Row coordinates (needed for 'morton').
    layout : {'auto', 'aggregation', 'morton', 'graph', 'metis', 'natural', 'rcm'}
        'auto': Morton leaves (:func:`morton_leaves`) of ``coords`` when given (keeping an order that
        already is Morton), else 'aggregation'. 'aggregation': aggregates of aggregates of A's strong
        couplings (:mod:`petsc_htp.twolevel.aggregation`; their size follows the graph, ``leaf`` is not used).
        'graph': Morton leaves of coordinates found in A's graph
        (:func:`petsc_htp.twolevel.embedding.grid_coordinates`), falling back to 'metis' when the graph is not
        2-D-like or the leaves cut more than ``CUT_FACTOR / sqrt(leaf)`` of A's couplings. 'metis': METIS
        parts of A's graph.
    leaf : int
        Target leaf size.
    bs : int
        Block size: aggregation leaves hold whole nodes of ``bs`` rows (A's first row ``offset`` rows into its node).
    second : {'standard', 'pairs'}
        Aggregation leaves: the kind of the passes after the first (:func:`~.aggregation.aggregates`).
    theta : float, optional
        Aggregation leaves: the first pass's strength threshold (None: :func:`~.aggregation.threshold`'s).
    alone : numpy.ndarray of bool, optional
        Aggregation leaves: rows that are leaves of their own (:func:`petsc_htp.ranksplit.cut_rows`).
    """
    if layout not in LAYOUTS:
        raise ValueError(f"unknown leaf layout {layout!r}; expected one of {', '.join(LAYOUTS)}")
    A = check_square(A)
    t0 = time.perf_counter()
    if layout == "aggregation" or (layout == "auto" and coords is None):
        part = aggregates(A, theta, bs=bs, second=second, offset=offset, alone=alone)
        return part_leaves(A, part, "aggregation", t0, smooth=False)
    if layout == "graph":
        xy = grid_coordinates(A)
        if xy is not None:
            leaves = _morton(A, xy, _positive_int(leaf, "leaf"), False, "graph", t0)
            if _cut_fraction(A, leaves) <= CUT_FACTOR / math.sqrt(leaf):
                return leaves
        return metis_leaves(A, leaf)
    if layout == "metis":
        return metis_leaves(A, leaf)
    if layout in ("auto", "morton"):
        if coords is None:
            raise ValueError("leaf layout 'morton' needs coordinates (coords=None given)")
        return _morton(A, check_coords(coords, A.shape[0]), _positive_int(leaf, "leaf"), layout == "auto", "morton",
                       t0)
    perm, name = choose_ordering(A, coords, layout)
    return contiguous_leaves(A.shape[0], leaf, perm, name, (time.perf_counter() - t0) * 1e3)
