"""Timed KSP solves as the example programs report them."""
from __future__ import annotations

import time

from petsc4py import PETSc


def timed_solve(ksp, rhs, x) -> tuple:
    """KSPSetUp, then KSPSolve of ``rhs`` into ``x`` (its start as it is), timed; (iterations, PETSc's reason,
    KSPSetUp ms, KSPSolve ms, true relative residual ||b - A x|| / ||b||)."""
    t0 = time.perf_counter()
    ksp.setUp()
    t1 = time.perf_counter()
    ksp.solve(rhs, x)
    t2 = time.perf_counter()
    r = rhs.duplicate()
    ksp.getOperators()[0].mult(x, r)
    r.aypx(-1.0, rhs)
    relres = r.norm() / rhs.norm()
    r.destroy()
    return ksp.getIterationNumber(), ksp.getConvergedReason(), 1e3 * (t1 - t0), 1e3 * (t2 - t1), relres


def solve_once(mat, rhs) -> tuple:
    """:func:`timed_solve` from zero with a fresh KSP on ``mat`` (both operators) configured by the options
    database."""
    x = rhs.duplicate()
    ksp = PETSc.KSP().create(mat.getComm())
    ksp.setOperators(mat, mat)
    ksp.setFromOptions()
    x.set(0.0)
    try:
        return timed_solve(ksp, rhs, x)
    finally:
        ksp.destroy()
        x.destroy()
