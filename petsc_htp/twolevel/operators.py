"""The two-level method's distributed operators, each with its final pattern from the analysis and its values
moved in by every numeric step: O = A - D (the couplings between leaves), W (the coarse vectors), C = O W and its
transpose, E = W^T A W (the Galerkin coarse operator, lifted on unused columns), and on demand F = W^T C (balanced form
with exact leaves) and A W (inexact leaves). Products are symbolic once, then numeric with PETSc's reuse. O and W
take their values in a fixed order (:class:`Pattern`).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from . import coarsespace
from ..collective import Collective
from .csr import compact, indptr_of
from .inner import scoped
from .leafsolvers import seqaij

RAP_MAX_ROWS = 262144   # one rank: rows up to which E = W^T A W takes PETSc's 'rap' PtAP, which keeps W^T and A W for
# its numeric reuse: on the own frames at 65 536 rows (sequence study) 4.2 against 4.7 ms per frame's products; at
# 1024^2 (the DMDA program) the default PtAP takes 169 against 202 ms and the peak RSS is 727 against 777 MB. A
# matrix with a dense row (graphshape.hub_rows; Structure.dense) takes 'rap' at any size: the default's symbolic
# step grows with the square of that row's length (a row coupled to every row of a 263 169-row DMDA matrix: 1 075
# against 78 ms of products)


def _csr(rows, cols, n) -> tuple:
    """Row pointer of ``n`` rows for entries already in row order, and the column indices, in PETSc's integers."""
    return indptr_of(rows, n).astype(PETSc.IntType), cols.astype(PETSc.IntType)


class Pattern:
    """A matrix of fixed pattern given by COO entries (global ``rows``, this rank's, and ``cols``) whose values come
    in that order (:meth:`set`): an AIJ on CSR arrays held here, its values written in place (on several ranks an
    MPIAIJ on its diagonal and off-diagonal parts); PETSc's COO assembly would hold two more integers per entry
    (42 MB of O's and W's at 1M rows)."""

    def __init__(self, comm, rows, cols, shape, local, col_block=1):
        coll = Collective(comm)
        first, col_first = coll.exscan(local[0]), coll.exscan(local[1])
        rows = rows - first
        if rows.size and (rows.min() < 0 or rows.max() >= local[0]):
            raise ValueError("a pattern's rows must be this rank's rows")
        key = rows.astype(np.int64) * shape[1] + cols
        order = None
        if np.any(key[1:] <= key[:-1]):                     # not yet in CSR order
            order = compact(np.argsort(key, kind="stable"), key.size)
            rows, cols = rows[order], cols[order]
            if np.any(np.diff(key[order]) == 0):
                raise ValueError("a pattern's entries must be unique (PETSc's COO assembly would add them)")
        self.size, self.parts = key.size, []
        if coll.size == 1:
            self.parts.append((order, np.zeros(key.size)))
            self.mat = seqaij(*_csr(rows, cols, local[0]), self.parts[0][1], local[0], shape[1])
        else:
            inside = (cols >= col_first) & (cols < col_first + local[1])
            csr = []
            for part, shift in ((inside, col_first), (~inside, 0)):
                where = np.flatnonzero(part)
                self.parts.append((compact(where if order is None else order[where], key.size),
                                   np.zeros(where.size)))
                csr.append(_csr(rows[where], cols[where] - shift, local[0]) + (self.parts[-1][1],))
            self.mat = PETSc.Mat().createAIJWithArrays(((local[0], shape[0]), (local[1], shape[1])), tuple(csr),
                                                       comm=comm)
        self.mat.setBlockSizes(1, col_block)

    def set(self, values):
        """New values, in the order of the entries given; on several ranks the MPIAIJ is assembled again (collective):
        with its state increased alone, a product's numeric reuse (PtAP) kept the old values."""
        if values.shape != (self.size,):
            raise ValueError(f"{values.size} values for a pattern of {self.size} entries")
        for src, held in self.parts:
            if src is None:
                np.copyto(held, values)
            else:
                np.take(values, src, out=held)
        if len(self.parts) > 1:
            self.mat.assemble()
        else:
            self.mat.stateIncrease()

    def take(self, data, src) -> np.ndarray:
        """New values ``data[src]``, set and returned (on one rank, in CSR order already, the matrix's own array)."""
        if self.parts[0][0] is None:
            held = self.parts[0][1]
            np.take(data, src, out=held)
            self.mat.stateIncrease()
            return held
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
        self._rap = st.coll.size == 1 and (st.N <= RAP_MAX_ROWS or st.dense)
        self.o_perm_rows = compact(lay.iperm[lay.o_rows], n)         # O's rows in the leaves' order
        self.W = self.C = self.CT = self.E = self.F = self.AW = self.Eb = self._lift = None
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
        if exact:                               # C^T v by MatMult, once an application (exact leaves' forms alone):
            self.CT = self.C.transpose(self.CT or PETSc.Mat())    # 13 against 49 us at 16 384 rows, 87 against 258
            # at 65 536 (the own frames' C: results/ctrans-20261129/ab.txt)
        if not exact:
            self.AW = self.mat.matMult(self.W, result=self.AW)
        if first and self._rap:
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
        """Values held on this rank: W, C, C^T, E, F and A W."""
        return int(sum(m.getInfo()["nz_used"] for m in (self.W, self.C, self.CT, self.E, self.F, self.AW)
                       if m is not None))

    def destroy(self):
        """Free the PETSc objects."""
        for name in ("O", "W", "C", "CT", "E", "Eb", "F", "AW", "_lift"):
            obj = getattr(self, name)
            if obj is not None:
                obj.destroy()
                setattr(self, name, None)
