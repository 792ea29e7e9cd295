"""Whether a right-hand side lies in the range of a singular matrix whose null space HTPPC found itself.

A matrix whose row sums vanish on a connected component annihilates that component's constant. Handed over without
a MatNullSpace, KSPSolve does not project b, and where b's part along those constants exceeds the KSP's tolerance no
x reaches it: CG with one exact factor of the grounded matrix then stepped 1e17 along the constant, its recursive
residual parted from the true one, and it reported CONVERGED_RTOL at a true relative residual of 7.6 (a 900-row
Neumann grid, random b; 16 on two ranks). :class:`RangeCheck` raises a named error before such a solve instead, on
every rank (its sums are collective).

Only components whose every row sum vanishes to rounding count here (:data:`STRICT`, relative to the row's own
entries): the grounding's test (:data:`.nullspace.NULL_TOL` times the largest diagonal entry) also takes a regular
matrix whose rows sum to a little of a large diagonal for singular (a Dirichlet square with a 1e11 inclusion), whose
factor then only serves a little worse, where this check would refuse a solve that converges. A regular matrix
shifted by less than that counts as singular, and the error says so: h^2 I + dt K (K a 5-point Neumann Laplacian of
256^2 rows, a random b) at dt = 1e7 and 1e9, where GAMG reported CONVERGED_RTOL at true relative residuals of 1.3e-6
and 1.2e-4 and the two-level method, not stopped, diverged at 1e9.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from .csr import row_sums
from .nullspace import STRICT      # |row sum| <= STRICT x the sum of the row's |a_ij| on every row of a null component

ESTIMATE = "esteig_"     # the options prefix of KSPCHEBYSHEV's eigenvalue estimate, a KSP on the same PC


def strictly_null(rows, comp_of_row, null, coll, absolute) -> np.ndarray:
    """``null`` without the components where some row of this rank's ``rows`` (CSR; all its entries, other ranks'
    columns included) sums to more than :data:`STRICT` of its ``absolute`` sum (collective on several ranks)."""
    loose = np.abs(row_sums(rows.indptr, rows.data)) > STRICT * absolute
    bad = np.zeros(null.size)
    bad[comp_of_row[loose]] = 1.0
    return null & (coll.max_array(bad) == 0)


class RangeCheck:
    """The constants of a matrix's null components, as its row sums found them.

    Parameters
    ----------
    rows : scipy.sparse.csr_matrix
        This rank's rows of the preconditioner's operator (the check reads the KSP's own).
    comp_of_row : numpy.ndarray (n,)
        Connected component of each of this rank's rows, numbered alike on every rank.
    null : numpy.ndarray of bool (C,)
        Which components are null (their row sums vanish); kept where they do to rounding (:func:`strictly_null`).
    coll : Collective
        The matrix's ranks.
    """

    def __init__(self, rows, comp_of_row, null, coll):
        absolute = row_sums(rows.indptr, np.abs(rows.data))
        null = strictly_null(rows, comp_of_row, null, coll, absolute)
        number = np.cumsum(null) - 1                        # each null component's index among them
        self.rows = np.flatnonzero(null[comp_of_row])
        self.comp = number[comp_of_row[self.rows]]
        self.k, self.coll, self.seen = int(null.sum()), coll, {}
        self.active = True          # whether the operator solved annihilates the constants too (:meth:`check`)
        self.size = coll.sum_array(np.bincount(self.comp, minlength=self.k).astype(np.float64))
        self.whole = self.k == 1 and self.size[0] == coll.sum(comp_of_row.size)     # one component, every row
        scale = absolute[self.rows]                          # ||(|A| z)|| for z below, by its largest entry
        top = float(coll.max_array(np.array([scale.max(initial=0.0)]))[0])      # (no overflow at 1e200)
        squares = np.square(scale / top).sum() if top > 0 else 0.0
        self.scale = top * float(np.sqrt(coll.sum_array(np.array([squares]))[0]))

    def project(self, vec):
        """``vec`` (a PETSc Vec of the operator's rows) less its mean on each null component, in place; returned
        (collective). For a solve whose operator annihilates the constants (:attr:`active`): with a regular Amat
        beside the singular Pmat the constants' part is the solution's own."""
        values = vec.array
        if self.whole:              # the mean alone (a Neumann square of 65 536 rows: 0.05 against 0.8 ms)
            values -= self.coll.sum_array(np.array([values.sum()]))[0] / self.size[0]
            return vec
        sums = self.coll.sum_array(np.bincount(self.comp, values[self.rows], minlength=self.k).astype(np.float64))
        values[self.rows] -= (sums / self.size)[self.comp]
        return vec

    def _annihilated(self, amat) -> bool:
        """Whether the solved operator ``amat`` annihilates the null constants too, z their sum: ||amat z|| at most
        1e-10 ||(|A| z)|| (a Pmat's components, but the Amat A + 0.01 I is regular; new values since the setup);
        once per operator and state (collective)."""
        key = (amat.handle, amat.stateGet())
        if key not in self.seen:
            z, y = amat.createVecs()
            z.set(0.0)
            z.array[self.rows] = 1.0
            amat.mult(z, y)
            self.seen = {key: y.norm() <= 1e-10 * self.scale}
            z.destroy()
            y.destroy()
        return self.seen[key]

    def check(self, ksp, b):
        """Raise ValueError where ``b``'s part along the null constants exceeds ``ksp``'s tolerance
        (max(rtol ||b||, atol), PETSc's default test); nothing where no component is null, the KSP tests no norm
        (a smoother's, PREONLY), is KSPCHEBYSHEV's eigenvalue estimate (prefix ``esteig_``: ten GMRES steps on a
        noisy b, which the Chebyshev solve of a consistent b had been refused for), its operator has a null space
        attached (the KSP removes that part) or does not annihilate the constants (a regular Amat, the Pmat
        singular)."""
        amat = ksp.getOperators()[0]
        self.active = bool(self.k) and self._annihilated(amat)     # :meth:`project` serves this solve (collective)
        if (not self.active or ksp.getNormType() == PETSc.KSP.NormType.NONE
                or (ksp.getOptionsPrefix() or "").endswith(ESTIMATE) or amat.getNullSpace().handle
                or amat.getTransposeNullSpace().handle):
            return
        sums = np.bincount(self.comp, b.array_r[self.rows], minlength=self.k).astype(np.float64)   # float on every
        sums = self.coll.sum_array(sums)                                        # rank, also one without such rows
        part, norm = float(np.sqrt(np.sum(sums * sums / self.size))), b.norm()
        rtol, atol = ksp.getTolerances()[:2]
        if part > max(rtol * norm, atol):
            raise ValueError(f"the matrix is singular (its row sums vanish on {self.k} connected component(s), and no "
                             f"MatNullSpace is attached) and the right-hand side is not in its range: its part along "
                             f"those components' constants is {part / norm:.1e} of its norm, above the KSP's "
                             f"tolerance (rtol {rtol:g}, atol {atol:g}), so no solution reaches it; attach the null "
                             f"space ({self._null_space()}, with MAT_SYMMETRIC set: the KSP then removes that part) "
                             f"or make b sum to zero on each component (rows that sum to at most {STRICT:g} of their "
                             f"entries count as summing to zero: a shift that small, as h^2 I beside dt K at a large dt, "
                             f"leaves the matrix singular in double precision)")

    def _null_space(self) -> str:
        """How to make the null space these components call for."""
        if self.k == 1:
            return "Mat.setNullSpace(NullSpace().create(constant=True))"
        return (f"Mat.setNullSpace(NullSpace().create(vectors=...)) with {self.k} orthonormal vectors, each constant "
                f"on one component and zero elsewhere: the constant alone is not its null space")

