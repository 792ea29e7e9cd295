"""One level of the hierarchy: its leaves, the leaf-block matrix the leaf solves' smoother factors, its smoothed
coarse space and the Galerkin operator of the next level.

The leaves are each rank's own (PyAMG's compiled strength and aggregation kernels on the rank's diagonal block), so
a leaf never spans ranks and the leaf-block matrix has no couplings between ranks; the coarse space and the Galerkin
product are each rank's rows too (:mod:`.galerkin`).
"""
from __future__ import annotations

import contextlib

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..aijarrays import aij, split
from ..collective import Collective
from ..petscmat import diagonal_block, ghost_values, local_rows
from ..ranksplit import cut_rows, outside_rows
from ..twolevel.aggregation import aggregates, decoupled_among, decoupled_rows
from ..twolevel.csr import row_sums
from . import galerkin

PASSES = 1              # aggregation passes a level (2-D DMDA at 65 536 rows: one pass 18 CG iterations, two 23-28)
LEAST = {2: 0.0, 3: 7.0}    # mean rows a coarser level's leaves hold at least, by the graph's dimension: fewer, and
# that level is aggregated again at half the strength threshold, down to 1/16 of it (AMGCL halves its eps_strong on
# every level): in 3-D anisotropy and rough fields had left small leaves (50^3 with the z couplings times 0.1: 2.0 s,
# 0.37 s so, results/threed-20261129/least.txt; operator complexity above 3 at 24^3, tests/test_multilevel.py),
# while the 3-D DMDA matrix's 9-12 rows a leaf keep its hierarchy; halving on every level had cost it 2 CG
# iterations at 1M rows (README); 2-D: none needed
JACOBI = 1.4            # W = (I - JACOBI / g D^-1 A) W0, g the Gershgorin bound of D^-1 A (galerkin.smoothed_rows)


class Level:
    """A level's operator ``A`` (PETSc), its leaves, :attr:`column` (the coarse column of each of this rank's rows, on
    this rank, -1 for none: :func:`leaf_columns`), :attr:`joined` (on several ranks, whether some rank's diagonal block
    leaves a row coupled to other ranks only: such rows share leaves, which may then join two components of ``A``),
    the leaf-block matrix ``B`` (where ``blocks``: the leaf solves' smoother; else None), the coarse space ``W`` (A's
    rows by the next level's columns) and :attr:`below`, the next level's operator W^T A W (a new Mat, the caller's);
    ``rows``: this rank's rows of ``A`` where already read; ``weighted``: the leaf vectors take |a_ii|^-1/2 in place of
    1 (a row-scaled operator: :func:`row_scaled`), from each numeric step's values."""

    def __init__(self, A, jacobi=JACOBI, leaf=None, blocks=True, rows=None, weighted=False, least=0.0):
        self.A, self.jacobi, self.weighted = A, jacobi, weighted
        start = A.getOwnershipRange()[0]
        coll = Collective(A.getComm())
        with _read(A, rows) as rows:
            lone = decoupled_rows(rows, start)
            with diagonal_block(A, rows) as block:
                within = block_decoupled(rows, start, block)
            self.joined = coll.size > 1 and coll.any(np.any(within & ~lone))
            self.leaf = leaves(A, rows, within, least) if leaf is None else leaf
            self.column, self.k = leaf_columns(self.leaf, lone)
            column = self.column
            self.first, self.n_coarse = coll.exscan(self.k), coll.sum(self.k)
            self.halo = galerkin.Halo(rows, start)
            self.halo_columns = galerkin.coarse_columns(A, self.halo, np.where(column >= 0, column + self.first, -1))
            self.W0 = None if weighted else galerkin.tentative(self.halo_columns, self.n_coarse)   # else each step's
            self.at = galerkin.diagonal_entries(self.halo.matrix(rows, start))
            self.pattern = LeafPattern(A, rows, self.leaf, start) if blocks else None
            self._numeric(rows, start)

    def _numeric(self, rows, start):
        """The leaf-block matrix, the smoothed coarse space and the next operator from the values ``rows``."""
        self.B = None if self.pattern is None else self.pattern.matrix(self.A, rows)
        local = self.halo.matrix(rows, start)
        diag = local.data[self.at] if self.at is not None else local.diagonal()
        self.bound = gershgorin(rows, diag, self.A.getComm())
        weights = None
        if self.weighted:
            weights = _weights(self.A, diag, self.halo.ghosts)
            self.W0 = galerkin.tentative(self.halo_columns, self.n_coarse, weights)
        W_rows = galerkin.smoothed_rows(local, diag, self.W0, self.at, self.jacobi / self.bound)
        self.W = aij(self.A.getComm(), (self.A.getSizes()[0], (self.k, self.n_coarse)),
                     *split(W_rows, self.first, self.first + self.k))
        self.below = galerkin.galerkin(self.A, local, self.halo.ghosts, W_rows, self.W, self.first, self.k,
                                         galerkin.leaf_scales(self.column, diag, self.k, weights))

    def refresh(self, rows=None):
        """The leaf-block matrix (where held), the smoothed coarse vectors and a new :attr:`below` from the operator's
        new values (same pattern; the old :attr:`below` is the caller's to free); the leaves are kept."""
        self.destroy()
        with _read(self.A, rows) as rows:
            self._numeric(rows, self.A.getOwnershipRange()[0])

    def destroy(self):
        """Free the leaf-block matrix and the coarse space (not the operators)."""
        for mat in (self.B, self.W):
            if mat is not None:
                mat.destroy()


def row_scaled(mat, rows) -> bool:
    """Whether ``mat`` (this rank's ``rows``, no null space attached) is row-scaled, D A D with D far from constant
    (unknowns in mixed units), whose near null space D^-1 1 the leaf constants miss and |diag|^-1/2 follows
    (:mod:`..twolevel.scaling`'s quotients, rows their own diagonal decides left out; only where the sampled
    neighbours' diagonals differ, :func:`..twolevel.scaling.neighbours_spread`). Collective."""
    from ..twolevel import dominance, scaling

    coll, start = Collective(mat.getComm()), mat.getOwnershipRange()[0]
    if mat.getNullSpace().handle or not scaling.neighbours_spread(rows, start, coll):
        return False
    with diagonal_block(mat, rows) as block:
        return scaling.weights(rows, start, coll, block, dominance.pinned(rows, start, coll)[0])[0] is not None


def _weights(A, diag, ghosts) -> np.ndarray:
    """|a_ii|^-1/2 (1 where a_ii is 0) of this rank's rows (``diag``), then of its ``ghosts`` (collective on several
    ranks)."""
    from ..twolevel.scaling import inverse_root

    z = inverse_root(diag)
    if A.getComm().getSize() == 1:
        return z
    return np.concatenate([z, ghost_values(A, z, ghosts)])


@contextlib.contextmanager
def _read(A, rows):
    """``rows`` where given, else this rank's rows of ``A`` (:func:`..petscmat.local_rows`)."""
    if rows is not None:
        yield rows
        return
    with local_rows(A) as rows:
        yield rows


def leaves(A, rows, lone=None, least=0.0) -> np.ndarray:
    """The leaf of each of this rank's ``rows`` of ``A``: :data:`PASSES` aggregation passes over the strong couplings
    of its diagonal block (``lone``: that block's decoupled rows where found), again at half the threshold while the
    coupled rows' leaves hold fewer than ``least`` rows on average (:data:`LEAST`; down to 1/16 of it), on several
    ranks the rows whose couplings to other ranks outweigh the rest in leaves of their own
    (:func:`..ranksplit.cut_rows`: log-normal edge weights exp(5 N(0, 1)) on 2 ranks, ``tests/edges_case.py`` at
    10 000 rows: 102 CG iterations without, 50 with, 43 on one rank; ``results/robust-20261128/ab.txt``)."""
    if not rows.shape[0]:
        return np.zeros(0, dtype=np.int64)
    with diagonal_block(A, rows) as block:
        alone = cut_rows(rows, block) if A.getComm().getSize() > 1 else None
        lone = block_decoupled(rows, A.getOwnershipRange()[0], block) if lone is None else lone
        block, scale = sp.csr_matrix(block), 1.0
        leaf = aggregates(block, passes=PASSES, lone=lone, alone=alone)
        shared = ~lone if alone is None else ~lone & ~alone            # the rows that may share a leaf
        while scale > 1 / 16 and _mean_size(leaf[shared]) < least:
            scale /= 2
            leaf = aggregates(block, passes=PASSES, lone=lone, alone=alone, scale=scale)
        return leaf


def _mean_size(leaf) -> float:
    """The mean number of rows of the leaves ``leaf`` names (inf for none)."""
    return leaf.size / np.unique(leaf).size if leaf.size else np.inf


def block_decoupled(rows, start, block) -> np.ndarray:
    """The decoupled rows of this rank's diagonal ``block`` of its ``rows`` (their diagonal in column ``start`` +
    row): the rows' own (kept on them, :func:`..twolevel.aggregation.decoupled_rows`), but where a row has entries
    outside the block, read again from the block (its couplings to other ranks alone would leave it decoupled there)."""
    lone = decoupled_rows(rows, start)
    if block is rows:                                              # one rank
        return lone
    extra = outside_rows(rows, block)
    within = lone.copy()
    within[extra] = decoupled_among(block, extra)
    return within


def banded_leaves(A, rows, leaf) -> np.ndarray:
    """``leaf`` (this rank's rows' leaves) renumbered in the order their rows first come in a breadth-first (reverse
    Cuthill-McKee) order of this rank's diagonal block: rows taken in that order of their leaves lie near the rows they
    couple to, and so do the coarse rows of every level below, which the leaves' numbers number, whatever the user's
    numbering (one breadth-first search of the rows: the leaves' own graph, made by sparse products on rows numbered at
    random, cost more than it saved)."""
    from ..twolevel.cuthill import reverse_cuthill_mckee

    count = int(leaf.max()) + 1 if leaf.size else 0
    with diagonal_block(A, rows) as block:
        seen = leaf[reverse_cuthill_mckee(block, exact=False)]
    first = np.full(count, seen.size, dtype=np.int64)
    np.minimum.at(first, seen, np.arange(seen.size))             # each leaf's first place
    rank = np.empty(count, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(count)
    return rank[leaf]


class LeafPattern:
    """Which of this rank's ``rows`` (global columns) of ``A`` couple rows of one leaf: :meth:`matrix` lays them out
    as ``A``, a block-diagonal matrix whose Cholesky factor in the natural order fills only within the leaves."""

    def __init__(self, A, rows, leaf, start):
        n = rows.shape[0]
        row = np.repeat(np.arange(n, dtype=np.int32), np.diff(rows.indptr))
        cols = rows.indices - start if start else rows.indices
        if A.getComm().getSize() == 1:
            self.keep = leaf[row] == leaf[cols]
        else:
            self.keep = (cols >= 0) & (cols < n)
            self.keep[self.keep] = leaf[row[self.keep]] == leaf[cols[self.keep]]
        self.indptr = np.concatenate(([0], np.cumsum(self.keep)))[rows.indptr].astype(PETSc.IntType)
        self.indices = cols[self.keep].astype(PETSc.IntType)

    def matrix(self, A, rows):
        """The leaf-block matrix of the values ``rows`` (this pattern)."""
        n = rows.shape[0]
        return aij(A.getComm(), A.getSizes(), sp.csr_matrix((rows.data[self.keep], self.indices, self.indptr),
                                                            shape=(n, n)))


def leaf_columns(leaf, lone):
    """The coarse column (numbered on this rank) of each row's leaf, -1 where the leaf holds no row coupled to another
    (decoupled rows, ``lone``, are solved by their leaf alone and get no coarse vector), and how many there are."""
    n = leaf.size
    keep = np.zeros(int(leaf.max()) + 1 if n else 0, dtype=bool)
    keep[leaf[~lone]] = True
    column = np.cumsum(keep) - 1
    return (np.where(keep[leaf], column[leaf], -1) if n else np.zeros(0, dtype=np.int64)), int(keep.sum())


def gershgorin(rows, diag, comm) -> float:
    """The largest row sum of |D^-1 A| over the ranks (``diag``: D, this rank's ``rows``' diagonal): a bound on the
    spectral radius of D^-1 A (2 for an M-matrix's diagonally dominant rows)."""
    diag = np.abs(diag)
    sums = row_sums(rows.indptr, np.abs(rows.data))
    local = float(np.max(sums / np.where(diag > 0, diag, np.inf))) if rows.shape[0] else 0.0
    return max(float(Collective(comm).max_array(np.array([local]))[0]), 1.0)
