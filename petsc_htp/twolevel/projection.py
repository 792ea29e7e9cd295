"""One factor of a singular matrix applied as P F^-1 P, P the projection off its null space: the KSP then never sees
the factor's answer along that space, which a grounded or shifted factor makes large or arbitrary.

On one rank the factor grounds the null components; where a null space is attached the KSP removes it from M r but
not from r, and MINRES stopped with DIVERGED_INDEFINITE_PC on a Neumann square of 625-2 500 rows (its second
residual, at rounding, held a constant part that weighed in). On several ranks the gathered factor is shifted, and
where the constant is null but no null space is attached (every row sum vanishing) CGS, TFQMR, Richardson and
Chebyshev diverged or stalled on the foreign study's Neumann matrix at 500 rows.
"""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from ..collective import Collective
from .consistency import RangeCheck


class Projection:
    """P F^-1 P for the factor ``pc`` of ``mat``, P off the null space ``nsp`` (attached to ``mat``), or off the
    constant where ``nsp`` is None."""

    def __init__(self, mat, nsp=None):
        comm = mat.getComm()
        self.nsp = (PETSc.NullSpace().create(constant=True, comm=comm) if nsp is None else
                    PETSc.NullSpace().create(constant=nsp.hasConstant(), vectors=nsp.getVecs(), comm=comm))
        self.work = mat.createVecLeft()

    def apply(self, pc, x, y):
        """y = P F^-1 P x, F^-1 the PC ``pc``."""
        x.copy(self.work)
        self.nsp.remove(self.work)
        pc.apply(self.work, y)
        self.nsp.remove(y)

    def destroy(self):
        """Free the null space copy and the work vector."""
        self.nsp.destroy()
        self.work.destroy()


def gathered(mat, rows):
    """On several ranks, where the gathered factor is shifted and nothing grounded: the :class:`.consistency.RangeCheck`
    of the constant for ``mat`` (this rank's ``rows``) and a :class:`Projection` off the attached null space or, where
    every row sum vanishes, off the constant (else None), both for these values (collective)."""
    one, nsp = np.ones(1, dtype=bool), mat.getNullSpace()
    check = RangeCheck(rows, np.zeros(rows.shape[0], dtype=np.int64), one, Collective(mat.getComm()))
    return check, (Projection(mat, nsp if nsp.handle else None) if nsp.handle or check.k else None)


def drop(project) -> None:
    """Free ``project`` (a :class:`Projection` or None); returns None. A projection serves the values it was made
    for: one kept after new values made the matrix regular left a solve at a true relative residual of 0.04 that CG
    reported converged."""
    if project is not None:
        project.destroy()
