"""The two-level method's distributed operators, each with its final pattern from the analysis and its values
moved in by every numeric step: O = A - D (the couplings between leaves), W (the coarse vectors), C = O W,
E = W^T A W (the Galerkin coarse operator, lifted on unused columns), and on demand F = W^T C (balanced form
with exact leaves) and A W (inexact leaves). Products are symbolic once, then numeric with PETSc's reuse. O and W
take their values in a fixed order (:class:`Pattern`).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from . import coarsespace
from .csr import compact
from .inner import scoped
from .leafsolvers import seqaij

RAP_MAX_ROWS = 262144   # one rank: rows up to which E = W^T A W takes PETSc's 'rap' PtAP, which keeps W^T and A W for
# its numeric reuse: on the own frames at 65 536 rows (sequence study) 4.2 against 4.7 ms per frame's products; at
# 1024^2 (the DMDA program) the default PtAP takes 169 against 202 ms and the peak RSS is 727 against 777 MB


def coo_aij(comm, rows, cols, shape, local, col_block=1) -> PETSc.Mat:
    """An AIJ on ``comm`` with the COO pattern (global ``rows``, ``cols``); values come by ``setValuesCOO``."""
    mat = PETSc.Mat().create(comm=comm)
    try:
        mat.setSizes(((local[0], shape[0]), (local[1], shape[1])))
        mat.setBlockSizes(1, col_block)
        mat.setType(PETSc.Mat.Type.AIJ)
        mat.setPreallocationCOO(rows.astype(PETSc.IntType), cols.astype(PETSc.IntType))
    except Exception:
        mat.destroy()
        raise
    return mat


class Pattern:
    """A matrix of fixed pattern given by COO entries (global ``rows``, ``cols``) whose values come in that order
    (:meth:`set`). On one rank a SeqAIJ on CSR arrays held here, its values written in place (PETSc's COO maps
    would hold two more integers per entry: 42 MB of O's and W's at 1M rows), else PETSc's COO assembly."""

    def __init__(self, comm, rows, cols, shape, local, col_block=1):
        self.order = self.values = None
        if comm.getSize() > 1:
            self.mat = coo_aij(comm, rows, cols, shape, local, col_block)
            return
        key = rows.astype(np.int64) * shape[1] + cols
        if np.any(key[1:] <= key[:-1]):                     # not yet in CSR order
            self.order = compact(np.argsort(key, kind="stable"), key.size)
            rows, cols = rows[self.order], cols[self.order]
            if np.any(np.diff(key[self.order]) == 0):
                raise ValueError("a pattern's entries must be unique (PETSc's COO assembly would add them)")
        indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=shape[0]))))
        self.values = np.zeros(rows.size)
        self.mat = seqaij(indptr, cols, self.values, shape[0], shape[1])
        self.mat.setBlockSizes(1, col_block)

    def set(self, values):
        """New values, in the order of the entries given."""
        if self.values is None:
            self.mat.setValuesCOO(values)
            return
        if values.shape != self.values.shape:
            raise ValueError(f"{values.size} values for a pattern of {self.values.size} entries")
        if self.order is None:
            np.copyto(self.values, values)
        else:
            np.take(values, self.order, out=self.values)
        self.mat.stateIncrease()

    def take(self, data, src) -> np.ndarray:
        """New values ``data[src]``, set and returned (on one rank, in CSR order already, the matrix's own array)."""
        if self.values is not None and self.order is None:
            np.take(data, src, out=self.values)
            self.mat.stateIncrease()
            return self.values
        values = np.take(data, src)
        self.set(values)
        return values


class Operators:
    """O, W and their products for one :class:`~.structure.Structure` on the operator ``mat`` (rows: this rank's
    rows, for O's pattern)."""

    def __init__(self, mat, rows, st):
        lay, comm = st.lay, mat.getComm()
        n, N = lay.n, st.N
        self.mat, self.st = mat, st
        self.o_perm_rows = compact(lay.iperm[lay.o_rows], n)         # O's rows in the leaves' order
        self.W = self.C = self.E = self.F = self.AW = self.Eb = self._lift = None
        self._o = Pattern(comm, lay.o_rows.astype(np.int64) + lay.start, rows.indices[lay.o_src], (N, N), (n, n))
        self.O = self._o.mat
        try:
            self._w = Pattern(comm, *st.w_pattern(), (N, st.m), (n, int(st.ncols.sum())), st.col_block)
            self.W = self._w.mat
        except Exception:
            self.destroy()
            raise

    def couplings(self, data) -> np.ndarray:
        """O's values from A's ``data`` (the analysed pattern), set and returned (read only: O holds them)."""
        return self._o.take(data, self.st.lay.o_src)

    def products(self, values, exact, need_F):
        """W's ``values``, then C = O W, A W (``exact`` False), E = W^T A W lifted, F = W^T C (``need_F``) and E as
        BAIJ where :meth:`blocked` made it."""
        self._w.set(values)
        first = self.C is None
        self.C = self.O.matMult(self.W, result=self.C)
        if not exact:
            self.AW = self.mat.matMult(self.W, result=self.AW)
        if first and self.st.coll.size == 1 and self.st.N <= RAP_MAX_ROWS:
            with scoped(self.mat.getOptionsPrefix() or "", {"matptap_via": "rap"}):
                self.E = self.mat.ptap(self.W)
        else:
            self.E = self.mat.ptap(self.W, result=self.E)
        if self.F is not None or need_F:
            self.F = self.W.transposeMatMult(self.C, result=self.F)
        self._lifted()
        if self.Eb is not None:
            self.Eb = self.E.convert(PETSc.Mat.Type.BAIJ, out=self.Eb)

    def blocked(self) -> PETSc.Mat:
        """E as BAIJ in W's column blocks, kept up to date from now on (block LU kernels: a third faster to factor
        and to apply)."""
        if self.Eb is None:
            self.Eb = self.E.convert(PETSc.Mat.Type.BAIJ, out=PETSc.Mat())
        return self.Eb

    def _lifted(self):
        """E's zero diagonal entries (unused columns) raised to E's largest diagonal magnitude over all ranks."""
        lift = self._lift or self.E.createVecLeft()
        diag = self.E.getDiagonal()
        top = self.st.coll.max_array(np.array([np.abs(diag.getArray()).max(initial=0.0)]))[0]
        lift.getArray()[:] = coarsespace.lift(np.append(diag.getArray(), top))[:-1]      # the global top sets the scale
        self.E.setDiagonal(lift, addv=PETSc.InsertMode.ADD_VALUES)
        diag.destroy()
        self._lift = lift

    def need_F(self):
        """F = W^T C (made on first use, then kept up to date by :meth:`products`)."""
        if self.F is None:
            self.F = self.W.transposeMatMult(self.C)

    def drop_F(self):
        """Free F (the balanced form as written needs none)."""
        if self.F is not None:
            self.F.destroy()
            self.F = None

    def nnz(self) -> int:
        """Values held on this rank: W, C, E, F and A W."""
        return int(sum(m.getInfo()["nz_used"] for m in (self.W, self.C, self.E, self.F, self.AW) if m is not None))

    def destroy(self):
        """Free the PETSc objects."""
        for name in ("O", "W", "C", "E", "Eb", "F", "AW", "_lift"):
            obj = getattr(self, name)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
