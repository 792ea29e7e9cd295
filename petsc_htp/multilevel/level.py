"""One level of the hierarchy: its leaves, the leaf-block matrix the leaf solves' smoother factors, its smoothed
coarse space and the Galerkin operator of the next level.

All of a level's products run in PETSc (MatMatMult, MatPtAP) on any number of ranks; the leaves are each rank's
own (PyAMG's compiled strength and aggregation kernels on the rank's diagonal block), so a leaf never spans ranks
and the leaf-block matrix has no couplings between ranks.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from ..collective import Collective
from ..petscmat import diagonal_block, local_rows
from ..twolevel.aggregation import aggregates, decoupled_rows
from ..twolevel.csr import row_sums

PASSES = 1              # aggregation passes a level (2-D DMDA at 65 536 rows: one pass 18 CG iterations, two 23-28)
JACOBI = 1.4            # W = (I - JACOBI / g D^-1 A) W0, g the Gershgorin bound of D^-1 A (see smoothed)


class Level:
    """A level's operator ``A`` (PETSc), its leaves, the leaf-block matrix ``B`` (where ``blocks``: the leaf solves'
    smoother; else None) and the coarse space ``W`` (A's rows by the next level's columns); :meth:`coarse` gives
    the next level's operator."""

    def __init__(self, A, jacobi=JACOBI, leaf=None, blocks=True):
        self.A = A
        start = A.getOwnershipRange()[0]
        with local_rows(A) as rows:
            self.leaf = leaves(A, rows) if leaf is None else leaf
            lone = decoupled_rows(rows, start)
            self.B, self.inside = leaf_blocks(A, rows, self.leaf, start) if blocks else (None, None)
            bound = gershgorin(rows, start, A.getComm())
        self.jacobi, self.W0 = jacobi, coarse_space(A, self.leaf, lone)
        self.W = smoothed(A, self.W0, jacobi / bound)

    def coarse(self, into=None):
        """The Galerkin operator W^T A W of the next level (into its matrix ``into`` where it exists: new values)."""
        return self.A.ptap(self.W) if into is None else self.A.ptap(self.W, result=into)

    def refresh(self):
        """The leaf-block matrix (where held) and the smoothed coarse vectors from the operator's new values (same
        pattern, so both keep theirs); the leaves are kept."""
        start = self.A.getOwnershipRange()[0]
        with local_rows(self.A) as rows:
            values = None if self.B is None else rows.data[self.inside]
            bound = gershgorin(rows, start, self.A.getComm())
        smoothed(self.A, self.W0, self.jacobi / bound, into=self.W)
        if self.B is not None:
            ai, aj, _ = self.B.getValuesCSR()
            self.B.setValuesCSR(ai, aj, values)
            self.B.assemble()

    def destroy(self):
        """Free the leaf-block matrix and the coarse spaces (not the operator)."""
        for mat in (self.B, self.W0, self.W):
            if mat is not None:
                mat.destroy()


def leaves(A, rows) -> np.ndarray:
    """The leaf of each of this rank's ``rows`` of ``A``: :data:`PASSES` aggregation passes over the strong couplings
    of its diagonal block."""
    if not rows.shape[0]:
        return np.zeros(0, dtype=np.int64)
    with diagonal_block(A, rows) as block:
        return aggregates(sp.csr_matrix(block), passes=PASSES)


def leaf_blocks(A, rows, leaf, start):
    """The entries of this rank's ``rows`` (global columns) that couple rows of one leaf, laid out as ``A``: a
    block-diagonal matrix whose Cholesky factor in the natural order fills only within the leaves; and which of the
    rows' stored entries it holds."""
    n = rows.shape[0]
    row = np.repeat(np.arange(n, dtype=np.int32), np.diff(rows.indptr))
    cols = rows.indices - start if start else rows.indices
    if A.getComm().getSize() == 1:
        keep = leaf[row] == leaf[cols]
    else:
        keep = (cols >= 0) & (cols < n)
        keep[keep] = leaf[row[keep]] == leaf[cols[keep]]
    indptr = np.concatenate(([0], np.cumsum(keep)))[rows.indptr].astype(PETSc.IntType)
    B = PETSc.Mat().createAIJ(A.getSizes(), csr=(indptr, rows.indices[keep].astype(PETSc.IntType), rows.data[keep]),
                              comm=A.getComm())
    return B, keep


def coarse_space(A, leaf, lone):
    """W0: the constant of each leaf that holds a row coupled to another (decoupled rows, ``lone``, are solved by
    their leaf alone and get no coarse vector); its columns are numbered rank by rank."""
    n = leaf.size
    keep = np.zeros(int(leaf.max()) + 1 if n else 0, dtype=bool)
    keep[leaf[~lone]] = True
    column = np.cumsum(keep) - 1
    k = int(keep.sum())
    coll = Collective(A.getComm())
    first = coll.exscan(k)
    covered = keep[leaf] if n else np.zeros(0, dtype=bool)
    indptr = np.concatenate(([0], np.cumsum(covered))).astype(PETSc.IntType)
    cols = (first + column[leaf[covered]]).astype(PETSc.IntType)
    return PETSc.Mat().createAIJ(((n, None), (k, coll.sum(k))), csr=(indptr, cols, np.ones(cols.size)),
                                 comm=A.getComm())


def gershgorin(rows, start, comm) -> float:
    """The largest row sum of |D^-1 A| over the ranks: a bound on the spectral radius of D^-1 A (2 for an M-matrix's
    diagonally dominant rows)."""
    diag = np.abs(rows.diagonal(k=start)) if rows.shape[0] else np.ones(0)
    sums = row_sums(rows.indptr, np.abs(rows.data))
    local = float(np.max(sums / np.where(diag > 0, diag, np.inf))) if rows.shape[0] else 0.0
    return max(float(Collective(comm).max_array(np.array([local]))[0]), 1.0)


def smoothed(A, W0, omega, into=None):
    """W = (I - omega D^-1 A) W0, one damped Jacobi step on the coarse vectors (smoothed aggregation's
    prolongator), in PETSc (into ``into``, a W of A's pattern made before: new values)."""
    W = A.matMult(W0) if into is None else A.matMult(W0, result=into)
    d = A.getDiagonal()
    d.reciprocal()
    W.diagonalScale(L=d)
    W.scale(-omega)
    W.axpy(1.0, W0, structure=PETSc.Mat.Structure.SUBSET)
    d.destroy()
    return W
