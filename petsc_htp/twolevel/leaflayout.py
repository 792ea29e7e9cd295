"""Where every stored entry of a rank's rows goes in the two-level method: built once per nonzero pattern.

Given a rank's rows of A (scipy CSR, global columns) and its leaves, :func:`layout` returns index maps
that turn a later frame's values (``A.data``, same pattern) into the leaf blocks D, the couplings between leaves O
(A - D, in A's own numbering, other ranks' columns included), and the pieces of every leaf
(:mod:`petsc_htp.twolevel.nullspace`). Explicit zeros are not couplings: they are left out of D and O and do
not join pieces. Pure numpy: no PETSc, no torch.

D's rows come in A's own order where every leaf keeps A's order of its rows (aggregation leaves, and any
contiguous leaves) and A's numbering is local (a leaf's rows within :data:`.leaves.A_ORDER_SPAN` rows of each
other): a block-diagonal matrix fills in only within its blocks, so its factor in A's order holds what the leaves'
order would give, and applies to A's vectors without a gather and a scatter (2 x 3 of the 15 ms of a leaf solve on a
1M-row DMDA matrix: its CG solve 1.51 -> 1.34 s). Otherwise (Morton and METIS leaves reorder the rows within a
leaf; a mesh numbered at random, as the foreign study's P1 meshes, where the leaves' order keeps the solve in
the cache: 116 against 125 ms at 64k rows; there aggregation leaves take their rows by their couplings inside
the leaf, :func:`.leaves.by_degree`, which fills in less) D's rows come in the leaves' order, each leaf contiguous.
``d_in_a_order`` says which.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .csr import compact, indptr_of
from .leaves import A_ORDER_SPAN, Leaves, median_span
from .nullspace import Pieces, find_pieces


@dataclass(frozen=True, eq=False)
class LeafLayout:
    """Per-pattern index maps of one rank's rows (see the module docstring).

    Rows come in two orders: A's (the rank's local rows) and the leaves' (``perm``: leaf-order row p
    is A's local row ``perm[p]``). D lives in A's order or the leaves' (``d_in_a_order``), O in A's.

    Attributes
    ----------
    leaves : Leaves
    start : int
        First global row of the rank.
    perm, iperm : numpy.ndarray (n,)
        Leaf order -> A's local row, and back.
    leaf : numpy.ndarray (n,)
        Leaf of every row in the leaves' order.
    pos : numpy.ndarray (n,)
        Padded position ``k * Lmax + i`` of every row in the leaves' order.
    d_indptr, d_indices : numpy.ndarray
        CSR structure of D (sorted), in A's order or the leaves' (see the module docstring).
    d_src : numpy.ndarray
        The A.data entry of every value of D.
    d_diag : numpy.ndarray (n,)
        Where each row's diagonal sits in D's values (rows in the leaves' order).
    d_in_a_order : bool
        D's rows are A's local rows in A's order (else the leaves' order).
    o_src, o_rows : numpy.ndarray
        The A.data entries of O (nonzero couplings between leaves), in A's row order, and A's local row of each.
    pieces : Pieces
        Pieces of the leaves (rows in the leaves' order).
    isolated : numpy.ndarray of bool (P,)
        Pieces with no nonzero coupling out of their leaf.
    decoupled : numpy.ndarray of bool (P,)
        Pieces that are one row with no nonzero off-diagonal entry at all (a Dirichlet row stored as an identity
        row): the leaf solve is exact on them, so they get no coarse vector.
    """

    leaves: Leaves
    start: int
    perm: np.ndarray
    iperm: np.ndarray
    leaf: np.ndarray
    pos: np.ndarray
    d_indptr: np.ndarray
    d_indices: np.ndarray
    d_src: np.ndarray
    d_diag: np.ndarray
    d_in_a_order: bool
    o_src: np.ndarray
    o_rows: np.ndarray
    pieces: Pieces
    isolated: np.ndarray
    decoupled: np.ndarray

    @property
    def n(self) -> int:
        """Rows of the rank."""
        return int(self.perm.size)

    @property
    def shape(self) -> tuple:
        """Padded leaf layout (K, Lmax)."""
        return self.leaves.n_leaves, self.leaves.max_size

    @property
    def d_leaf_row(self) -> np.ndarray:
        """The row in the leaves' order of each of D's rows."""
        return self.iperm if self.d_in_a_order else np.arange(self.n)


def _a_order_pays(perm, leaf, offsets) -> bool:
    """Whether D goes in A's order: every leaf keeps A's order of its rows, and a leaf's rows lie within
    :data:`.leaves.A_ORDER_SPAN` rows of each other (the median leaf), so a triangular solve in A's order reads them
    from the cache."""
    same = leaf[1:] == leaf[:-1]
    if not np.all(perm[1:][same] > perm[:-1][same]):
        return False
    return median_span(perm, offsets) < A_ORDER_SPAN


def _within_leaves(rows, start, entry_row, leaf_of) -> tuple:
    """(each stored entry's local column, whether it couples two rows of one leaf, whether it is a diagonal entry)
    of a rank's ``rows`` (global columns) with ``leaf_of`` each local row; on one rank with no masks (every column
    is local)."""
    n = rows.shape[0]
    if start == 0 and rows.shape[1] == n:
        col = rows.indices
        return col, leaf_of[entry_row] == leaf_of[col], col == entry_row
    col = rows.indices.astype(np.int64) - start
    local = (col >= 0) & (col < n)
    inside = local.copy()
    inside[local] = leaf_of[entry_row[local]] == leaf_of[col[local]]
    return col, inside, local & (col == entry_row)


def layout(rows: sp.csr_matrix, start: int, leaves: Leaves) -> LeafLayout:
    """Index maps of a rank's rows ``rows`` (CSR, sorted, global columns, local rows ``start`` ...) and leaves."""
    n = rows.shape[0]
    if leaves.n != n:
        raise ValueError(f"leaves cover {leaves.n} rows but the rank has {n}")
    perm = leaves.perm
    iperm = np.empty(n, dtype=perm.dtype)
    iperm[perm] = np.arange(n)
    leaf = compact(np.repeat(np.arange(leaves.n_leaves), leaves.sizes), leaves.n_leaves)
    entry_row = np.repeat(np.arange(n, dtype=iperm.dtype), np.diff(rows.indptr))
    col, inside, diag = _within_leaves(rows, start, entry_row, leaf[iperm])
    nonzero = rows.data != 0
    inside &= nonzero | diag
    d_src = np.flatnonzero(inside)
    in_a_order = _a_order_pays(perm, leaf, leaves.offsets)
    if in_a_order:
        d_rows, d_cols = entry_row[d_src], col[d_src]
    else:                                   # permute the leaf blocks by scipy's C code, then read the sources back
        ids = sp.csr_matrix((d_src + 1.0, (iperm[entry_row[d_src]], iperm[col[d_src]])), shape=(n, n))
        ids.sort_indices()
        d_src = ids.data.astype(np.int64) - 1
        d_rows, d_cols = np.repeat(np.arange(n), np.diff(ids.indptr)), ids.indices.astype(np.int64)
    d_indptr = indptr_of(d_rows, n)
    d_diag = np.flatnonzero(d_rows == d_cols)
    if d_diag.size != n:
        missing = np.setdiff1d(np.arange(n), d_rows[d_rows == d_cols])
        row = missing[0] if in_a_order else perm[missing[0]]
        raise ValueError(f"row {int(row) + start} has no diagonal entry; the two-level "
                         "preconditioner needs every diagonal entry stored")
    if in_a_order:
        d_diag = d_diag[perm]                       # by the rows' order in the leaves
    K, L = leaves.n_leaves, leaves.max_size
    pos = compact(leaf * np.int64(L) + np.arange(n) - leaves.offsets[leaf], K * L)
    pieces = find_pieces(d_indptr, d_cols, leaf, leaves.n_leaves, perm if in_a_order else None)
    o_src = np.flatnonzero(~inside & nonzero & ~diag)
    coupled = np.zeros(pieces.n_pieces, dtype=bool)
    coupled[pieces.label[iperm[entry_row[o_src]]]] = True
    nnz = rows.indptr[-1]
    return LeafLayout(leaves, start, perm, iperm, leaf, pos, compact(d_indptr, nnz), compact(d_cols, n),
                      compact(d_src, nnz), compact(d_diag, n), in_a_order, compact(o_src, nnz), entry_row[o_src],
                      pieces, ~coupled, ~coupled & (pieces.size == 1))
