"""Timed KSP solves as the example programs and the ``scale`` study's worker report them."""
from __future__ import annotations

import time

from petsc4py import PETSc


def timed_solve(ksp, rhs, x) -> tuple:
    """KSPSetUp (with PCSetUpOnBlocks), then KSPSolve of ``rhs`` into ``x`` (its start as it is), each timed between
    barriers of the KSP's ranks; (iterations, PETSc's reason, setup ms, solve ms, true relative residual
    ||b - A x|| / ||b||)."""
    comm = ksp.getComm()
    comm.barrier()
    t0 = time.perf_counter()
    ksp.setUp()
    ksp.setUpOnBlocks()
    comm.barrier()
    t1 = time.perf_counter()
    ksp.solve(rhs, x)
    comm.barrier()
    t2 = time.perf_counter()
    r = rhs.duplicate()
    ksp.getOperators()[0].mult(x, r)
    r.aypx(-1.0, rhs)
    relres = r.norm() / rhs.norm()
    r.destroy()
    return ksp.getIterationNumber(), ksp.getConvergedReason(), 1e3 * (t1 - t0), 1e3 * (t2 - t1), relres


def solve_frames(mat, rhs, frames=0, refill=None, prefix="", each=None) -> list:
    """:func:`timed_solve` of frame 0 and of ``frames`` more, each from zero, with one KSP on ``mat`` (both
    operators) configured by the options database under ``prefix``; before frame k > 0 ``refill(k)`` puts its new
    values into ``mat`` (the KSP then sets its preconditioner up again, as a simulation's next frame does), and
    after each frame ``each(k, result)`` runs where given. Frame 0 is a fresh KSP's single solve."""
    if frames and refill is None:
        raise ValueError(f"{frames} more frames need a refill that puts their values into the Mat")
    x = rhs.duplicate()
    ksp = PETSc.KSP().create(mat.getComm())
    out = []
    try:
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(mat, mat)
        ksp.setFromOptions()
        for k in range(frames + 1):
            if k:
                refill(k)
            x.set(0.0)
            out.append(timed_solve(ksp, rhs, x))
            if each is not None:
                each(k, out[-1])
        return out
    finally:
        ksp.destroy()
        x.destroy()


def solve_once(mat, rhs) -> tuple:
    """:func:`timed_solve` from zero with a fresh KSP on ``mat`` (both operators) configured by the options
    database."""
    return solve_frames(mat, rhs)[0]
