"""Dirichlet rows whose couplings the other rows keep, as MatZeroRows leaves them (PETSc's DMDA tutorials ksp ex29,
ex45, TS ex15): A = [A_II A_ID; 0 D] is not symmetric, yet its solution on those rows is known, x_D = D^-1 b_D.

HTPPC preconditions A' = [A_II 0; 0 D], a copy of A with those columns dropped (SPD), as M':

- a KSPSolve of :data:`STARTED_KSPS` on the operator M was made from starts on x_D = D^-1 b_D
  (:meth:`KeptColumns.start`): then every residual and Krylov vector vanishes on those rows, where A acts as A'
  does, and M' (exact on those rows) is what CG or GMRES needs;
- anywhere else (PREONLY, PCApply, a transposed product, KSPs whose right preconditioning or normal equations mishandle
  a start: CGS, TFQMR, TCQMR, IBCGS, CGNE) M = (I - M' E) M' with E = A - A', or its transpose: A^-1 where M' is A'^-1,
  as A = A' (I + A'^-1 E) and (A'^-1 E)^2 = 0.

Where the Pmat is symmetric and its Dirichlet rows couple to nothing (MatZeroRowsColumns' form) but the Amat keeps
their columns (MatZeroRows'), a KSPSolve of :data:`STARTED_KSPS` starts on x_D = D^-1 b_D too, where the Amat's rows
there hold just D: CG then sees the Amat as the Pmat (22 iterations; before, 300 and an error of 15).

A transposed solve (KSPSolveTranspose) is started as a forward one, which A^T does not fit: under the deflated form
CG stops with DIVERGED_INDEFINITE_PC there (GMRES and the whole-matrix factor converge).
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .collective import Collective
from .petscmat import local_rows
from .twolevel.aggregation import decoupled_rows
from .twolevel.forms import DEFLATED_KSPS
from .validation import check_symmetry, probe_values

STARTED_KSPS = DEFLATED_KSPS + ("minres", "symmlq")     # those whose start the deflated form trusts, and these two

VANISHING = 1e-6        # a started solve's vectors on the Dirichlet rows: rounding, far below this share of their top


def kept_columns(P, A, previous):
    """The :class:`KeptColumns` of the AIJ operator ``P`` (this rank's rows ``A``): ``previous`` with the new values
    where the nonzero pattern is the same on every rank, else a new one after the symmetry probe
    (:func:`.validation.check_symmetry`, which raises where the asymmetry is not those rows'; ``previous`` is then
    untouched). Collective."""
    key = (P.getId(), A.indptr, A.indices, A.data != 0)
    same = previous is not None and previous.key is not None and key[0] == previous.key[0] and all(
        np.array_equal(a, b) for a, b in zip(key[1:], previous.key[1:]))
    coll = Collective(P.getComm())
    if not coll.any(not same):
        columns = previous
    else:
        lone = check_symmetry(P, lambda: decoupled_rows(A, P.getOwnershipRange()[0]))
        columns = KeptColumns(tuple(np.copy(k) if isinstance(k, np.ndarray) else k for k in key),
                              None if lone is None else np.flatnonzero(lone), coll)
    if columns.rows is not None:
        try:
            columns.refresh(P)
        except Exception:
            if columns is not previous:
                columns.free()
            raise
    return columns


class KeptColumns:
    """The copy A' of an operator whose Dirichlet rows keep their columns, and M made from M' (see the module).

    Attributes
    ----------
    rows : numpy.ndarray or None
        This rank's Dirichlet rows whose columns are dropped (local numbers); None where the operator is symmetric.
    count : int
        Those rows on all ranks.
    copy : petsc4py.PETSc.Mat or None
        A', made at the first :meth:`refresh`.
    started : bool
        A KSPSolve started on x_D = D^-1 b_D: M' alone is applied to vectors that vanish on those rows.
    alone : numpy.ndarray or None
        Where the operator is symmetric: its rows that couple to nothing (local numbers), started where an Amat
        keeps their columns (found at the first solve with such an Amat).
    """

    def __init__(self, key=None, rows=None, coll=None):
        self.key, self.rows, self.started, self.coll, self.alone = key, rows, False, coll, None
        self.count = 0 if coll is None else coll.sum(0 if rows is None else rows.size)
        self.copy = self.amat = self.keep = self.diag = self.d = self.u = self.t = None

    def refresh(self, P):
        """A' = P with the columns of :attr:`rows` dropped, their diagonal entries added back (P's pattern kept)."""
        if self.copy is None:
            self.copy = P.duplicate(copy=True)
            self.keep, self.diag = P.createVecs()
            self.u, self.t = P.createVecs()
            self.keep.set(1.0)
            self.keep.array[self.rows] = 0.0
        else:
            P.copy(self.copy, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self.amat = P
        P.getDiagonal(self.diag)
        self.d = self.diag.array_r[self.rows].copy()
        self.diag.array[...] = 0.0
        self.diag.array[self.rows] = self.d
        self.copy.diagonalScale(R=self.keep)
        self.copy.setDiagonal(self.diag, addv=PETSc.InsertMode.ADD_VALUES)
        self.copy.setNearNullSpace(P.getNearNullSpace())
        self.copy.setOption(PETSc.Mat.Option.SYMMETRIC, True)

    def start(self, ksp, b, x, aij=None):
        """Before a KSPSolve of :data:`STARTED_KSPS`: x_D = D^-1 b_D and :attr:`started`, D the Amat's diagonal now
        (a reused preconditioner's may be older); for an Amat other than the Pmat (a matrix-free Jacobian beside an
        assembled one), the Pmat's, where the Amat's rows there hold just it (:meth:`_diagonal_rows`; ``aij``: the
        Pmat's AIJ copy where it is of another type). Returns the KSP settings this changed ({'guess': its
        initial-guess flag}), else None."""
        self.started = False
        amat, pmat = ksp.getOperators()
        if ksp.getType() not in STARTED_KSPS:
            return None
        if self.rows is None:
            return self._alone_start(ksp, amat, pmat, b, x, pmat if aij is None else aij)
        if amat.handle == pmat.handle:
            amat.getDiagonal(self.t)
            d = self.t.array_r[self.rows].copy()
        elif self._diagonal_rows(amat, self.rows, self.d):
            d = self.d
        else:
            return None
        return self._set(ksp, self.rows, b, x, d)

    def _alone_start(self, ksp, amat, pmat, b, x, aij):
        """A symmetric Pmat whose Dirichlet rows couple to nothing (:attr:`alone`, found at the first such solve in
        ``aij``, the Pmat or its AIJ copy) beside an Amat that keeps their columns (the MatZeroRows form beside the
        MatZeroRowsColumns one): x_D = D^-1 b_D where the Amat's rows there hold just D, so that CG sees the Amat as
        the Pmat (collective)."""
        if amat.handle == pmat.handle:
            return None
        if self.alone is None:
            with local_rows(aij) as rows:
                self.alone = np.flatnonzero(decoupled_rows(rows, aij.getOwnershipRange()[0]))
        if not self.coll.any(self.alone.size > 0):
            return None
        diag = pmat.getDiagonal()
        d = diag.array_r[self.alone].copy()
        diag.destroy()
        return self._set(ksp, self.alone, b, x, d) if self._diagonal_rows(amat, self.alone, d) else None

    def _set(self, ksp, rows, b, x, d):
        """x = D^-1 b on ``rows`` (zero elsewhere unless the KSP has a guess), :attr:`started`; the changed settings."""
        nonzero = ksp.getInitialGuessNonzero()
        if not nonzero:
            x.set(0.0)
            ksp.setInitialGuessNonzero(True)
        x.array[rows] = b.array_r[rows] / d
        self.started = True
        return None if nonzero else {"guess": False}

    def _diagonal_rows(self, amat, rows, d) -> bool:
        """Whether ``amat``'s ``rows`` hold just the diagonal ``d`` there, each to 1e-6 of it (a matrix-free
        product: finite differences): (A v)_D = D v_D for a probe v, on every rank (one product, on vectors of its
        own: a product that raises leaves them locked; collective)."""
        v, av = amat.createVecs()
        try:
            start, end = v.getOwnershipRange()
            v.setArray(probe_values(start, end, 3))
            amat.mult(v, av)
            dv = d * v.array_r[rows]
            off = np.abs(av.array_r[rows] - dv) > 1e-6 * np.abs(dv)
            return not self.coll.any(bool(off.any()))
        finally:
            v.destroy()
            av.destroy()

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
        if self.started and self._vanishing(x):
            return
        u.set(0.0)                         # M x = z - M' E z, z = M' x: E z = A (z on the rows) less D z there
        u.array[rows] = y.array_r[rows]
        self.amat.mult(u, t)
        t.array[rows] = 0.0
        self._exact(apply, t, u)
        y.axpy(-1.0, u)

    def _vanishing(self, x) -> bool:
        """Whether ``x`` vanishes on the Dirichlet rows, to :data:`VANISHING` of its largest entry, on every rank (a
        started solve's vectors; not a vector PCApply gets after a solve that raised before its postSolve)."""
        local = np.array([np.abs(x.array_r[self.rows]).max(initial=0.0), np.abs(x.array_r).max(initial=0.0)])
        top = self.coll.max_array(local)
        return top[0] <= VANISHING * top[1]

    def _exact(self, apply, x, y):
        """y = M' x, exact on the Dirichlet rows (a variant's M' need not be)."""
        apply(x, y)
        y.array[self.rows] = x.array_r[self.rows] / self.d

    def describe(self) -> list:
        """A ``-ksp_view`` line where there are such rows."""
        if self.rows is None:
            return []
        return [f"{self.count} row(s) hold just their diagonal (Dirichlet rows), other rows keep couplings to some of "
                "them (MatZeroRows): preconditioned without their columns; a started solve sets x = b / diagonal there"]

    def free(self):
        """Destroy the copy and the work vectors (once no analysis holds the copy); the next operator is probed."""
        for obj in (self.copy, self.keep, self.diag, self.u, self.t):
            if obj is not None:
                obj.destroy()
        self.__init__()
