"""Dirichlet rows whose couplings the other rows keep, as MatZeroRows leaves them (PETSc's DMDA tutorials ksp ex29,
ex45, TS ex15): A = [A_II A_ID; 0 D] is not symmetric, yet its solution on those rows is known, x_D = D^-1 b_D.

HTPPC preconditions A' = [A_II 0; 0 D], a copy of A with those columns dropped (SPD), as M':

- a KSPSolve starts on x_D = D^-1 b_D (:meth:`KeptColumns.start`): then every residual and Krylov vector vanishes on
  those rows, where A acts as A' does, and M' (exact on those rows) is what CG or GMRES needs;
- anywhere else (PREONLY, PCApply, a transposed product) M = (I - M' E) M' with E = A - A', or its transpose: A^-1
  where M' is A'^-1, as A = A' (I + A'^-1 E) and (A'^-1 E)^2 = 0.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .collective import Collective
from .validation import check_symmetry


class KeptColumns:
    """The copy A' of an operator whose Dirichlet rows keep their columns, and M made from M' (see the module).

    Attributes
    ----------
    rows : numpy.ndarray or None
        This rank's Dirichlet rows whose columns are dropped (local numbers); None where the operator is symmetric.
    count : int
        Those rows on all ranks.
    started : bool
        A KSPSolve started on x_D = D^-1 b_D: M' alone is applied.
    """

    def __init__(self):
        self.key, self.rows, self.count, self.started = None, None, 0, False
        self.copy = self.amat = self.keep = self.diag = self.d = self.u = self.t = None

    def operator(self, P, A):
        """``P`` (AIJ, this rank's rows ``A``) itself where it is symmetric, else A' with the new values. The
        symmetry probe (:func:`.validation.check_symmetry`, which raises where the asymmetry is not those rows')
        runs once per nonzero pattern, decided on every rank together (collective)."""
        key = (P.getId(), A.indptr, A.indices, A.data != 0)
        same = self.key is not None and key[0] == self.key[0] and all(
            np.array_equal(a, b) for a, b in zip(key[1:], self.key[1:]))
        if Collective(P.getComm()).any(not same):
            self.key = self.copy = self.keep = self.diag = self.u = self.t = None   # an analysis holding the old
            # copy frees it
            lone = check_symmetry(P, A)
            self.rows = None if lone is None else np.flatnonzero(lone)
            self.count = Collective(P.getComm()).sum(0 if lone is None else self.rows.size)
            self.key = tuple(np.copy(k) if isinstance(k, np.ndarray) else k for k in key)
        if self.rows is None:
            return P
        self.amat = P
        self._refresh(P)
        return self.copy

    def _refresh(self, P):
        """A' = P with the columns of :attr:`rows` dropped, their diagonal entries added back (P's pattern kept)."""
        if self.copy is None:
            self.copy = P.duplicate(copy=True)
            self.keep, self.diag = P.createVecs()
            self.u, self.t = P.createVecs()
            self.keep.set(1.0)
            self.keep.array[self.rows] = 0.0
        else:
            P.copy(self.copy, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        P.getDiagonal(self.diag)
        self.d = self.diag.array_r[self.rows].copy()
        self.diag.array[...] = 0.0
        self.diag.array[self.rows] = self.d
        self.copy.diagonalScale(R=self.keep)
        self.copy.setDiagonal(self.diag, addv=PETSc.InsertMode.ADD_VALUES)
        self.copy.setNearNullSpace(P.getNearNullSpace())
        self.copy.setOption(PETSc.Mat.Option.SYMMETRIC, True)

    def start(self, ksp, b, x):
        """Before a KSPSolve (not PREONLY, which takes no guess): x_D = D^-1 b_D, and :attr:`started`. Returns the
        KSP settings this changed ({'guess': its initial-guess flag}), else None."""
        if self.rows is None or ksp.getType() == PETSc.KSP.Type.PREONLY:
            return None
        nonzero = ksp.getInitialGuessNonzero()
        if not nonzero:
            x.set(0.0)
            ksp.setInitialGuessNonzero(True)
        x.array[self.rows] = b.array_r[self.rows] / self.d
        self.started = True
        return None if nonzero else {"guess": False}

    def apply(self, apply, x, y, transpose=False):
        """y = M x from ``apply(x, y)``, M' (see the module); ``transpose``: y = M^T x."""
        if self.rows is None:
            apply(x, y)
            return
        u, t, rows = self.u, self.t, self.rows
        if transpose:                      # M^T x = M' (x - E^T M' x): E^T w = (A^T w, w_D = 0) on the rows
            self._exact(apply, x, t)
            t.array[rows] = 0.0
            self.amat.multTranspose(t, u)
            t.array[...] = 0.0
            t.array[rows] = u.array_r[rows]
            t.aypx(-1.0, x)
            self._exact(apply, t, y)
            return
        self._exact(apply, x, y)
        if self.started:
            return
        u.set(0.0)                         # M x = z - M' E z, z = M' x: E z = A (z on the rows) less D z there
        u.array[rows] = y.array_r[rows]
        self.amat.mult(u, t)
        t.array[rows] = 0.0
        self._exact(apply, t, u)
        y.axpy(-1.0, u)

    def _exact(self, apply, x, y):
        """y = M' x, exact on the Dirichlet rows (a variant's M' need not be)."""
        apply(x, y)
        y.array[self.rows] = x.array_r[self.rows] / self.d

    def describe(self) -> list:
        """A ``-ksp_view`` line where there are such rows."""
        if self.rows is None:
            return []
        return [f"{self.count} Dirichlet row(s) hold just their diagonal while the other rows keep their couplings "
                "(MatZeroRows): preconditioned without those columns, a solve starting on x = b / diagonal there"]

    def free(self):
        """Drop the copy and the work vectors (a new operator is probed anew)."""
        for obj in (self.copy, self.keep, self.diag, self.u, self.t):
            if obj is not None:
                obj.destroy()
        self.__init__()
