"""The leaf solves B of the two-level method: exact solves of the leaf blocks, or of leaves grown by overlap.

Both keep one sparse matrix and one PETSc factor per rank whose pattern is fixed by the analysis, so a
frame's values cost one numeric factorisation.

- :class:`ExactLeaves`: B = D^-1, D the leaf blocks in A's row order or the leaves'
  (:mod:`.leaflayout`; either way the natural ordering factors it without fill between leaves). D B = I,
  which the deflated form uses.
- :class:`OverlappingLeaves`: additive Schwarz, B = sum_k R_k^T A_k^-1 R_k over each leaf grown by
  ``overlap`` layers of its neighbours among the rank's rows; the grown blocks sit side by side in one
  matrix with one factor. Symmetric, but D B != I: the forms then go through A W.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .csr import indptr_of, row_entries
from .inner import held

EXACT = ("cholesky", "lu")        # leaf PC types that solve D exactly


def seqaij(indptr, indices, values, n, m=None) -> PETSc.Mat:
    """A SeqAIJ on COMM_SELF that uses the given CSR arrays in place (new values: change them, stateIncrease)."""
    it = PETSc.IntType
    return PETSc.Mat().createAIJWithArrays((n, n if m is None else m),
                                           (np.asarray(indptr, dtype=it), np.asarray(indices, dtype=it), values),
                                           comm=PETSc.COMM_SELF)


class _Factored:
    """A SeqAIJ of fixed pattern with its factor, applied to rows ``gather``-ed from A's local rows (None: they
    are A's local rows)."""

    def __init__(self, indptr, indices, values, gather, make_pc):
        n = len(indptr) - 1
        self.values, self.gather = values, gather
        self.mat = seqaij(indptr, indices, values, n)
        self.pc = make_pc(self.mat)
        self.xp = self.vp = self.xs = self.vs = None         # work vectors, made on first use (a factor applied
        # to the KSP's own vectors needs none: 17 MB at 1M rows)

    def refactor(self):
        """Numeric factorisation of the new values."""
        self.mat.stateIncrease()
        self.pc.setUp()

    def solve_rows(self, x):
        """The factor's solve of the gathered rows of the local array ``x`` (a view of a work array)."""
        if self.xp is None:
            n = self.mat.getSize()[0]
            self.xp, self.vp = np.zeros(n), np.zeros(n)
            self.xs = PETSc.Vec().createWithArray(self.xp, comm=PETSc.COMM_SELF)
            self.vs = PETSc.Vec().createWithArray(self.vp, comm=PETSc.COMM_SELF)
        if self.gather is None:
            np.copyto(self.xp, x)
        else:
            np.take(x, self.gather, out=self.xp)
        self.pc.apply(self.xs, self.vs)
        return self.vp

    def destroy(self):
        for obj in (self.mat, self.pc, self.xs, self.vs):
            if obj is not None:
                obj.destroy()


class ExactLeaves:
    """B = D^-1 with D the leaf blocks (see the module docstring).

    Parameters
    ----------
    lay : LeafLayout
    values : numpy.ndarray
        D's values in ``lay``'s D structure; the caller fills them each frame (used in place).
    make_pc : callable
        Mat -> PC (the factor, configured by the caller's options).
    direct : bool
        D is in A's order on one rank: B applies to the KSP's vectors as they are.
    """

    summed = False

    def __init__(self, lay, values, make_pc, direct):
        self.lay, self.direct = lay, direct
        self.f = _Factored(lay.d_indptr, lay.d_indices, values, None if lay.d_in_a_order else lay.perm, make_pc)
        self.exact = self.f.pc.getType() in EXACT      # an incomplete factor (-htp_leaf_pc_type icc): D B != I

    @property
    def pc(self) -> PETSc.PC:
        """The factor."""
        return self.f.pc

    def numeric(self, data):
        """Factor D's new values (already in place)."""
        self.f.refactor()

    def apply(self, x, v):
        """v = B x (Vecs laid out like A's rows)."""
        if self.direct:
            self.f.pc.apply(x, v)
        elif self.lay.d_in_a_order:
            v.array_w[:] = self.f.solve_rows(x.array_r)
        else:
            np.take(self.f.solve_rows(x.array_r), self.lay.iperm, out=v.array_w)

    def nnz(self) -> int:
        """Stored values of D and its factor."""
        return int(self.f.values.size + held(self.f.pc))

    def describe(self) -> str:
        kind = "exact solves" if self.exact else "incomplete-factor solves"
        return f"{kind} by one factor of the leaf blocks per rank ({self.f.pc.getType()})"

    def destroy(self):
        self.f.destroy()


class OverlappingLeaves:
    """Additive Schwarz over leaves grown by ``overlap`` layers within the rank (see the module docstring).

    Parameters
    ----------
    lay : LeafLayout
    rows : scipy.sparse.csr_matrix
        The rank's rows of A (global columns, sorted); only its pattern is read.
    overlap : int
        Layers of neighbours added to every leaf.
    make_pc : callable
        Mat -> PC.
    """

    exact = False
    summed = True       # its pieces overlap: B A reaches about the overlap count, which a coarse error amplifies

    def __init__(self, lay, rows, overlap, make_pc):
        n, start = lay.n, lay.start
        block, member = lay.leaf.astype(np.int64), lay.perm.astype(np.int64)    # (grown leaf, A's local row) pairs
        col = rows.indices.astype(np.int64) - start
        local = (col >= 0) & (col < n) & (rows.data != 0)
        for _ in range(overlap):
            first, owner = row_entries(rows.indptr, member)
            keep = local[first]
            cand = np.unique(block[owner][keep] * n + col[first[keep]])
            have = block * n + member
            new = cand[~np.isin(cand, have)]
            block, member = np.concatenate([block, new // n]), np.concatenate([member, new % n])
        order = np.argsort(block, kind="stable")                        # leaf rows first, then the grown layers
        block, member = block[order], member[order]
        key = block * n + member
        sorter = np.argsort(key)
        first, owner = row_entries(rows.indptr, member)
        ok = local[first] | (col[first] == member[owner])
        first, owner = first[ok], owner[ok]
        want = block[owner] * n + col[first]
        at = np.searchsorted(key, want, sorter=sorter)
        at = np.minimum(at, key.size - 1)
        hit = key[sorter[at]] == want
        r, c, src = owner[hit], sorter[at[hit]], first[hit]
        order = np.lexsort((c, r))
        self.src = src[order]
        indptr = indptr_of(r, member.size)
        self.member, self.n = member, n
        self.f = _Factored(indptr, c[order], np.zeros(self.src.size), member, make_pc)

    @property
    def pc(self) -> PETSc.PC:
        """The factor."""
        return self.f.pc

    def numeric(self, data):
        """New values of the grown blocks and their factor."""
        np.take(data, self.src, out=self.f.values)
        self.f.refactor()

    def apply(self, x, v):
        """v = B x: solve every grown leaf, add the pieces up."""
        v.array_w[:] = np.bincount(self.member, self.f.solve_rows(x.array_r), minlength=self.n)

    def nnz(self) -> int:
        """Stored values of the grown blocks and their factor."""
        return int(self.f.values.size + held(self.f.pc))

    def describe(self) -> str:
        grown = self.member.size / self.n
        return f"additive Schwarz over leaves grown to {grown:.2f}x the rows, one factor per rank ({self.f.pc.getType()})"

    def destroy(self):
        self.f.destroy()
