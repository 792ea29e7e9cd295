"""Whether a right-hand side lies in the range of a singular matrix whose null space HTPPC found itself.

A matrix whose row sums vanish on a connected component annihilates that component's constant. Handed over without
a MatNullSpace, KSPSolve does not project b, and where b's part along those constants exceeds the KSP's tolerance no
x reaches it: CG with one exact factor of the grounded matrix then stepped 1e17 along the constant, its recursive
residual parted from the true one, and it reported CONVERGED_RTOL at a true relative residual of 7.6 (a 900-row
Neumann grid, random b; 16 on two ranks). :class:`RangeCheck` raises a named error before such a solve instead, on
every rank (its sums are collective). PETSc-free but for the KSP's tolerances and b's norm.
"""
from __future__ import annotations

import numpy as np


class RangeCheck:
    """The constants of a matrix's null components, as its row sums found them.

    Parameters
    ----------
    comp_of_row : numpy.ndarray (n,)
        Connected component of each of this rank's rows, numbered alike on every rank.
    null : numpy.ndarray of bool (C,)
        Which components are null (their row sums vanish).
    coll : Collective
        The matrix's ranks.
    """

    def __init__(self, comp_of_row, null, coll):
        number = np.cumsum(null) - 1                        # each null component's index among them
        self.rows = np.flatnonzero(null[comp_of_row])
        self.comp = number[comp_of_row[self.rows]]
        self.k, self.coll = int(null.sum()), coll
        self.size = coll.sum_array(np.bincount(self.comp, minlength=self.k).astype(float))

    def check(self, ksp, b):
        """Raise ValueError where ``b``'s part along the null constants exceeds ``ksp``'s tolerance
        (max(rtol ||b||, atol), PETSc's default test)."""
        sums = self.coll.sum_array(np.bincount(self.comp, b.array_r[self.rows], minlength=self.k))
        part, norm = float(np.sqrt(np.sum(sums * sums / self.size))), b.norm()
        rtol, atol = ksp.getTolerances()[:2]
        if part > max(rtol * norm, atol):
            raise ValueError(f"the matrix is singular (its row sums vanish on {self.k} connected component(s), and no "
                             f"MatNullSpace is attached) and the right-hand side is not in its range: its part along "
                             f"those components' constants is {part / norm:.1e} of its norm, above the KSP's rtol "
                             f"{rtol:g}, so no solution reaches the tolerance; attach the null space "
                             f"(Mat.setNullSpace(NullSpace().create(constant=True)): the KSP then removes that part) "
                             f"or make b sum to zero on each component")
