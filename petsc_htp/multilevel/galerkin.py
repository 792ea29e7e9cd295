"""A level's smoothed coarse space W and Galerkin operator W^T A W from each rank's own rows, by scipy's sparse
products on the rank (no PETSc MPIAIJ product, which keeps its symbolic data and whose symbolic phase did not
shrink with ranks: the finest MatPtAP of the 1024^2 DMDA took 147 ms on one rank and 146 on two).

Each rank multiplies its rows of A (columns numbered: its own rows, then its ghosts, :class:`Halo`) by its rows of W
and the ghosts' rows of W (one MatCreateSubMatrices), then by its rows of W transposed; the rows of the product
that belong to another rank's coarse columns go there (one all-to-all) and are added to its own.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..aijarrays import aij, split
from ..petscmat import ghost_values, read_csr

NULL_SHARE = 1e-13      # a Galerkin row whose entries all lie within this share of its scale is null (rounding: 1e-16);
# a leaf constant on an island of conductivity K in a medium of e keeps about e / K of its scale: above 1e12 contrast
# such an island's coarse row is taken for null too (its coarse correction then lost, the V-cycle still SPD)


class Halo:
    """The numbering of this rank's rows' columns of A (scipy CSR ``rows``, global columns; the pattern alone): its
    own rows, then its ghosts (:attr:`ghosts`, the other ranks' rows its rows couple to, ascending)."""

    def __init__(self, rows, start):
        self.n, cols = rows.shape[0], rows.indices
        outside = (cols < start) | (cols >= start + self.n)
        self.ghosts, self.local = np.zeros(0, dtype=np.int64), None
        if outside.any():
            theirs = cols[outside]
            self.ghosts = np.unique(theirs)
            self.local = (cols - start).astype(PETSc.IntType, copy=False)      # numbers below n + ghosts: no overflow
            self.local[outside] = self.n + np.searchsorted(self.ghosts, theirs)

    def matrix(self, rows, start) -> sp.csr_matrix:
        """``rows`` (the operator's values now, this pattern) with their columns so numbered."""
        cols = self.local if self.local is not None else (rows.indices - start if start else rows.indices)
        return sp.csr_matrix((rows.data, cols, rows.indptr), shape=(self.n, self.n + self.ghosts.size))


def coarse_columns(mat, halo, column):
    """Each column of :meth:`Halo.matrix`: the coarse column (global) of its row, or -1 (this rank's rows by
    ``column``; the ghosts' from their ranks: collective on more than one rank, whether this one has ghosts or not)."""
    if mat.getComm().getSize() == 1:
        return column
    theirs = ghost_values(mat, column.astype(np.float64), halo.ghosts)
    return np.concatenate([column, np.rint(theirs).astype(column.dtype)])


def tentative(columns, n_coarse, weights=None) -> sp.csr_matrix:
    """W0, the leaf constants: one entry of each covered row (own rows, then ghosts: ``columns``,
    :func:`coarse_columns`) in its leaf's coarse column, 1 or the row's of ``weights`` (same rows); scipy CSR."""
    covered = columns >= 0
    values = np.ones(int(covered.sum())) if weights is None else weights[covered]
    return sp.csr_matrix((values, columns[covered], np.concatenate(([0], np.cumsum(covered)))),
                         shape=(columns.size, n_coarse))


def diagonal_entries(A) -> np.ndarray:
    """Where each row's diagonal is stored in ``A`` (:meth:`Halo.matrix`); None where some row has none."""
    row = np.repeat(np.arange(A.shape[0], dtype=A.indices.dtype), np.diff(A.indptr))
    at = np.flatnonzero(row == A.indices)
    return at if at.size == A.shape[0] else None


def smoothed_rows(A, d, W0, at, omega):
    """This rank's rows of W = (I - omega D^-1 A) W0 (``d``: A's diagonal; ``W0``: :func:`tentative`; a row whose
    diagonal is zero or absent is scaled by 1 in D's place), scipy CSR with global coarse columns, sorted: one sparse
    product of the smoother, whose diagonal lies at A's (``at``, :func:`diagonal_entries`; None: added apart), with W0
    (entries that cancel are dropped). ``A``: this rank's rows, :meth:`Halo.matrix`."""
    n = A.shape[0]
    scale = -omega / np.where(d != 0, d, 1.0)
    S = sp.csr_matrix((A.data * np.repeat(scale, np.diff(A.indptr)), A.indices, A.indptr), shape=A.shape)
    if at is not None:
        S.data[at] += 1.0
    else:
        S = (S + sp.eye(n, A.shape[1], format="csr")).tocsr()
    W = S @ W0
    W.sort_indices()
    return W


def galerkin(mat, A, ghosts, W_rows, W, first, k, scale):
    """W^T A W, the next level's operator, from this rank's rows ``A`` of ``mat`` (:meth:`Halo.matrix`, ``ghosts``
    its ghosts), ``W_rows`` (:func:`smoothed_rows`) and ``W`` (their PETSc Mat, whose ghost rows it reads); its rows
    ``first:first+k`` on this rank, those null against their ``scale`` made unit rows (:func:`_unit_null_rows`)."""
    K = W_rows.shape[1]
    if mat.getComm().getSize() > 1:
        AW = A @ sp.vstack([W_rows, _rows_of(W, ghosts)], format="csr")
    else:
        AW = A @ W_rows
    C = W_rows.T.tocsr() @ AW
    C.sort_indices()
    C = _unit_null_rows(_summed(C, first, k, mat.getComm()), first, scale)
    return aij(mat.getComm(), ((k, K), (k, K)), *split(C, first, first + k))


def leaf_scales(column, diag, k, weights=None) -> np.ndarray:
    """Each of this rank's ``k`` coarse rows' scale: the sum of w_i^2 |a_ii| over its leaf's rows (``column``: each
    row's coarse column on this rank, -1 for none; ``diag``: their diagonal; ``weights``: W0's entries w, else 1), of
    the order of its Galerkin diagonal."""
    scale = np.abs(diag) if weights is None else np.square(weights[:diag.size] * np.sqrt(np.abs(diag)))
    return np.bincount(column + 1, scale, minlength=k + 1)[1:]        # rows without a column counted apart


def _unit_null_rows(C, first, scale) -> sp.csr_matrix:
    """``C`` (rows ``first``... of a Galerkin operator, global columns, sorted) with each null row emptied, its column's
    entries in this rank's rows dropped (other ranks' rows keep theirs, at rounding's size), and its ``scale`` (1 where
    that is 0) on its diagonal: a row empty or whose entries all lie within
    :data:`NULL_SHARE` of its ``scale`` (:func:`leaf_scales`), a coarse vector A annihilates (a leaf constant of a null
    component: a sealed pocket of a closed domain, whose row rounding leaves at 1e-16 of its scale, of either sign).
    Such a row couples to nothing and so stands alone, where the smoothers' sweeps (PCSOR) divide by its diagonal
    and the banded factor grounds it by its own magnitude: CG ended with DIVERGED_INDEFINITE_PC where 16 pockets of 9
    rows lay in 65 536 rows, and 50 in 9 216 rows on one and two ranks (``results/robust-20261128/ab.txt``)."""
    bound = NULL_SHARE * scale
    if not np.any(np.abs(C.diagonal(k=first)) <= bound):            # a null row's diagonal is within it too
        return C
    counts = np.diff(C.indptr)
    largest = np.zeros(C.shape[0])
    full = counts > 0
    largest[full] = np.maximum.reduceat(np.abs(C.data), C.indptr[:-1][full])
    null = largest <= bound
    row = np.repeat(np.arange(C.shape[0]), counts)
    col = C.indices - first
    own = (col >= 0) & (col < C.shape[0])
    keep = ~null[row] & ~(own & null[np.where(own, col, 0)])
    where = np.flatnonzero(null)
    C = (sp.csr_matrix((C.data[keep], C.indices[keep], np.concatenate(([0], np.cumsum(np.bincount(
        row[keep], minlength=C.shape[0]))))), shape=C.shape)
         + sp.csr_matrix((np.where(scale[where] > 0, scale[where], 1.0), (where, where + first)),
                         shape=C.shape)).tocsr()
    C.sort_indices()
    return C


def _rows_of(W, rows) -> sp.csr_matrix:
    """Rows ``rows`` (global, any rank's) of the MPIAIJ ``W``, all its columns, scipy CSR (collective)."""
    K = W.getSize()[1]
    want = PETSc.IS().createGeneral(rows.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    every = PETSc.IS().createStride(K, 0, 1, comm=PETSc.COMM_SELF)
    (sub,) = W.createSubMatrices(want, every)
    try:
        return read_csr(sub)
    finally:
        for obj in (want, every, sub):
            obj.destroy()


def _summed(C, first, k, comm) -> sp.csr_matrix:
    """Rows ``first:first+k`` of this rank's product ``C`` (K x K, scipy CSR, sorted) plus the rows every other
    rank's product holds of them (one all-to-all on more than one rank), sorted."""
    if comm.getSize() == 1:
        return C
    mpi = comm.tompi4py()
    lo, hi = C.indptr[first], C.indptr[first + k]
    mine = sp.csr_matrix((C.data[lo:hi], C.indices[lo:hi], C.indptr[first:first + k + 1] - lo), shape=(k, C.shape[1]))
    row = np.concatenate([np.repeat(np.arange(first), np.diff(C.indptr[:first + 1])),
                          np.repeat(np.arange(first + k, C.shape[0]), np.diff(C.indptr[first + k:]))])
    col = np.concatenate([C.indices[:lo], C.indices[hi:]])
    val = np.concatenate([C.data[:lo], C.data[hi:]])
    ends = np.array(mpi.allgather(first + k))
    owner = np.searchsorted(ends, row, side="right")
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=mpi.size).astype(np.int64)
    got = np.empty(mpi.size, dtype=np.int64)
    mpi.Alltoall(counts, got)
    total = int(got.sum())
    parts = []
    for send, dtype in ((row[order], np.int64), (col[order], np.int64), (val[order], np.float64)):
        recv = np.empty(total, dtype=dtype)
        mpi.Alltoallv((np.ascontiguousarray(send, dtype=dtype), counts), (recv, got))
        parts.append(recv)
    if not total:
        return mine
    theirs = sp.csr_matrix((parts[2], (parts[0] - first, parts[1])), shape=mine.shape)
    return mine + theirs
