"""W's values on one rank: every leaf's coarse vectors (:mod:`.coarsespace`) in W's pattern, with the null
components' columns left out (:mod:`.nullspace`).

The eig and learned spaces take one inverse-iteration step of the leaves' Neumann matrix S (one sparse matrix
per rank, its factor PETSc's, one multi-vector triangular solve). S has D's pattern and differs only on the
diagonal: with exact or incomplete leaf solves it borrows the leaf solver's matrix and factor (S's diagonal in,
factor, solve, D's diagonal back; the leaf solver factors D after), which saves a matrix and a factor of the
rank's size (about 90 MiB at 1M rows in 2-D). Aggregation leaves with at most one such vector
take it in numpy without the padded layout (:func:`.coarsespace.flat`); other leaves go through the padded basis
(:func:`.coarsespace.basis`). On the flat layout a row-scaled operator's pieces take |diag|^-1/2 in place of
their constants (:mod:`.scaling`).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from . import coarsespace, nullspace, scaling
from .consistency import RangeCheck
from .csr import row_sums
from .leafsolvers import seqaij
from .spacereuse import DiagonalWatch


class CoarseSpace:
    """The coarse vectors of a :class:`~.structure.Structure` (see the module docstring).

    Parameters
    ----------
    st : Structure
    make_pc : callable
        Mat -> PC, the factor of S (configured like the leaf factor).
    shared : leafsolvers._Factored, optional
        The leaf solver's matrix of D and its factor, to borrow for S (its values are D's, in place).
    """

    def __init__(self, st, make_pc, shared=None):
        lay = st.lay
        self.st, self.values = st, np.zeros(st.w_p.size)
        self.kept, self.age, self.dropped, self.pinned, self.range = None, 0, np.zeros(0, dtype=np.int64), 0, None
        self.weights = None                  # the flat space's piece vectors where they are not the constants
        self.watch = DiagonalWatch(lay.d_diag, st.coll)                   # W's row scaling
        self.flat = lay.leaves.kind == "aggregation" and st.q <= 1 and not st.extra and not st.fixed
        if self.flat:
            self.lead_mask = st.w_j < st.lead
            self.mine = ~self.lead_mask & (st.w_j - st.lead == st.piece_index[lay.pieces.label[st.w_p]])
        else:
            self.constants = coarsespace.piece_constants(lay, st.piece_index)
            self.src = lay.pos[st.w_p].astype(np.int64) * (st.lead + self.constants.shape[2]) + st.w_j
        self.seeds = coarsespace.seeds(lay.leaf, lay.leaves.offsets, lay.leaves.sizes, 1, st.seeded) if st.seeded else None
        self.s_values = self.S = self.S_factor = self.S_csr = self._dense = None
        self._zeroed_key, self.failed = None, PETSc.PC.FailedReason.NOERROR
        self.shared = bool(st.seeded) and shared is not None
        if self.shared:
            self.s_values, self.S, self.S_factor = shared.values, shared.mat, shared.pc
        elif st.seeded:
            self.s_values = np.zeros(lay.d_src.size)
            self.S = seqaij(lay.d_indptr, lay.d_indices, self.s_values, lay.n)
            try:
                self.S_factor = make_pc(self.S)
            except Exception:
                self.destroy()
                raise
        if st.seeded:
            self.S_csr = sp.csr_matrix((self.s_values, lay.d_indices, lay.d_indptr), shape=(lay.n, lay.n))

    def null(self, mat, rows) -> np.ndarray:
        """Null components (``mat``'s attached MatNullSpace, else the row sums of ``rows``, this rank's rows of A in
        the analysed pattern: then :attr:`range` checks b), and this rank's pieces
        to ground (a boolean array); the columns of the pieces to drop are kept for :meth:`finish`."""
        st, lay = self.st, self.st.lay
        nsp = mat.getNullSpace()
        reduce = st.coll.max_array if st.coll.size > 1 else None
        if nsp.handle:
            null = nullspace.null_from_vectors([z.getArray(readonly=True) for z in nsp.getVecs()], nsp.hasConstant(),
                                               st.comp_of_row, st.n_comp, reduce)
        else:
            diag = rows.data[lay.d_src[lay.d_diag]]
            rowsum = row_sums(rows.indptr, rows.data)
            null = nullspace.null_by_rowsums(rowsum, diag, st.comp_of_row, st.n_comp, reduce)
        found = not nsp.handle and null.any()                                          # b's part: :mod:`.consistency`
        self.range = RangeCheck(rows, st.comp_of_row, null, st.coll) if found else None
        drop, ground = nullspace.dropped(null, st.comp_of_piece, st.isolated)
        self.dropped = st.piece_col[st.my_pieces(drop) & st.has_col]
        self.null_components = int(null.sum())
        return st.my_pieces(ground)

    @property
    def renewed(self) -> bool:
        """Whether the space is the piece constants alone (or their row-scaled vectors, :mod:`.scaling`): made anew
        it costs about what keeping it does, and it follows a new row scaling (D A D handed over after A: 26 CG
        iterations against a kept constant space's 134)."""
        return self.flat and not self.st.seeded

    def compute(self, d_values, o_values, o_rows, seeds=None, near=None, weights=None):
        """New coarse vectors from D's values and the couplings ``o_values`` (rows ``o_rows``, leaves' order);
        ``seeds`` replaces the smooth seeds (learned space); ``near`` (n, fixed), the near null vectors in A's row
        order (:mod:`.nearnull`); ``weights`` (n, A's row order), the flat space's piece vectors in place of the
        constants (:mod:`.scaling`). With a borrowed factor, D's values come back as they were but its factor holds
        S's: the leaf solver factors D after this."""
        lay = self.st.lay
        near = None if near is None else near[lay.perm]
        self.weights = None if weights is None else weights[lay.perm]
        self.watch.made(d_values)
        if not self.st.seeded:
            return self._fill(None, None, near)
        outside = np.bincount(o_rows, o_values, minlength=lay.n)     # one inverse-iteration step with S
        diag = coarsespace.neumann_diagonal(d_values[lay.d_diag], outside, lay.leaf, lay.leaves.sizes)
        d_diagonal = d_values[lay.d_diag]
        if not self.shared:
            np.copyto(self.s_values, d_values)
        self.s_values[lay.d_diag] = diag
        try:
            self.S.stateIncrease()
            self.S_factor.setUp()
            self.failed = self.S_factor.getFailedReason()
            self._fill(self.seeds if seeds is None else seeds, diag, near)
            self._free_dense()                  # its work arrays: a frame's allocation reuses freed pages cheaply
            if self.failed != PETSc.PC.FailedReason.NOERROR:      # ICC/ILU keep a failure through later setups:
                self.S_factor.reset()                             # a new factor for the next values (D's too)
                self.S_factor.setOperators(self.S, self.S)
        finally:
            if self.shared:
                d_values[lay.d_diag] = d_diagonal

    def _fill(self, seeds, diag, near=None):
        """W's values from the seeds through S's factor (none: the constants alone) and the near null vectors
        ``near`` (leaves' order)."""
        st, lay = self.st, self.st.lay
        self.age = 0
        if self.flat:
            self._constants()
            self.kept = st.ncols
            if st.q:
                y, ok = coarsespace.flat(self.solve_neumann(seeds)[:, 0], lay.leaf, lay.pieces, self.weights)
                self.values[self.lead_mask] = y[st.w_p[self.lead_mask]]
                self.kept = st.ncols - ((st.ncols > 0) & ~ok)
            return
        P, self.kept = coarsespace.basis(lay, self.constants, seeds, self.solve_neumann, st.extra, self.apply_neumann,
                                         diag, st.cfg.tol, near)
        np.take(P.reshape(-1), self.src, out=self.values)

    def _constants(self):
        """W's values of the flat space: each piece's constant 1 / sqrt(size), or its :attr:`weights` normalised,
        in its own column, zeros elsewhere (made each time, not held: 16 MB at 1M rows)."""
        st, lay = self.st, self.st.lay
        self.values.fill(0.0)
        rows = st.w_p[self.mine]
        label = lay.pieces.label[rows]
        w = 1.0 if self.weights is None else self.weights[rows]
        w2 = lay.pieces.size if self.weights is None else np.bincount(label, w * w, minlength=lay.pieces.n_pieces)
        self.values[self.mine] = w / np.sqrt(np.maximum(w2[label], 1e-300))

    def finish(self, rows, bound) -> np.ndarray:
        """W's values with the dropped pieces' columns and the local ``rows`` their diagonal pins (a_ii >= ``bound``
        times their off-diagonal sum: :func:`.dominance.left_out`) zeroed (a copy only when some are)."""
        pinned = np.zeros(self.st.lay.n, dtype=bool)
        pinned[rows] = True
        self.pinned, self.bound = self.st.coll.sum(int(pinned.sum())), bound
        if not self.dropped.size and not self.pinned:
            return self.values
        values = self.values.copy()
        values[self._zeroed(self.dropped)] = 0.0
        values[pinned[self.st.lay.perm[self.st.w_p]]] = 0.0
        return values

    def notes(self, quotients) -> str:
        """What ``-ksp_view`` adds on the pieces' vectors (:func:`.scaling.note`) and on pinned rows."""
        return scaling.note(self.weights is not None, quotients) + (
            f"; {self.pinned} pinned row(s) left out of W (a_ii >= {self.bound:g} x the row's off-diagonal sum: "
            f"a penalty's Dirichlet rows, a strong reaction; the leaf solves take them)" if self.pinned else "")

    def _zeroed(self, dropped) -> np.ndarray:
        """W's entries in the columns ``dropped`` (cached: the null space rarely changes)."""
        key = dropped.tobytes()
        if self._zeroed_key != key:
            gone = np.zeros(int(self.st.ncols.sum()), dtype=bool)
            gone[dropped - self.st.col_first] = True
            self._zeroed_key, self._zeroed_at = key, np.flatnonzero(gone[self.st.w_local_col])
        return self._zeroed_at

    def apply_neumann(self, X) -> np.ndarray:
        """S X for an (n, q) array (rows in the leaves' order)."""
        lay = self.st.lay
        if not lay.d_in_a_order:
            return self.S_csr @ X
        return (self.S_csr @ X[lay.iperm])[lay.perm]

    def solve_neumann(self, X) -> np.ndarray:
        """S^-1 X for an (n, q) array (rows in the leaves' order), one multi-vector triangular solve (a view of a
        work array where S's rows are in that order)."""
        if self._dense is None or self._dense[0].shape != X.shape:
            self._free_dense()
            rhs = np.empty(X.shape, order="F")
            out = np.empty(X.shape, order="F")
            self._dense = (rhs, out, PETSc.Mat().createDense(X.shape, array=rhs, comm=PETSc.COMM_SELF),
                           PETSc.Mat().createDense(X.shape, array=out, comm=PETSc.COMM_SELF))
        rhs, out, R, Y = self._dense
        lay = self.st.lay
        np.copyto(rhs, X[lay.iperm] if lay.d_in_a_order else X)
        R.stateIncrease()
        self.S_factor.getFactorMatrix().matSolve(R, Y)
        return out[lay.perm] if lay.d_in_a_order else out

    def _free_dense(self):
        if self._dense is not None:
            self._dense[2].destroy()
            self._dense[3].destroy()
        self._dense = None

    def nnz(self) -> int:
        """Values held: S and its factor (none when borrowed from the leaf solver)."""
        if self.S is None or self.shared:
            return 0
        return int(self.S.getInfo()["nz_used"] + self.S_factor.getFactorMatrix().getInfo()["nz_used"])

    def destroy(self):
        """Free the PETSc objects."""
        self._free_dense()
        for obj in (self.S, self.S_factor):
            if obj is not None and not self.shared:
                obj.destroy()
        self.S = self.S_factor = None
