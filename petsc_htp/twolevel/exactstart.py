"""The start of a KSPSolve whose preconditioner solves A exactly (one factor of the whole matrix):
x0 += M (b - A x0), after which PETSc's test at iteration 0 (||r0|| against rtol ||b||) ends the solve with the
answer to rounding, in any KSP. Without it the first iteration left a residual at rounding that some KSPs mistook:
BCGSL stopped with DIVERGED_DTOL after one iteration at relative residuals of 5e-3 to 70 on every small matrix of the
foreign study that the factor served (PETSc's own Cholesky PC does the same). No start (:func:`wanted`) for
Richardson and Chebyshev, whose first step with an exact M is exact, for Chebyshev's eigenvalue estimate (prefix
``esteig_``: the estimate would see no residual), and where the convergence test measures against the initial
residual (``-ksp_converged_use_initial_residual_norm``, ``..._min_...``), which a start at rounding puts out of reach
(Richardson then ran to its iteration limit).
"""
from __future__ import annotations

from petsc4py import PETSc

from .consistency import ESTIMATE

UNSTARTED = ("richardson", "chebyshev")
INITIAL = ("ksp_converged_use_initial_residual_norm", "ksp_converged_use_min_initial_residual_norm")


def wanted(ksp) -> bool:
    """Whether a solve by ``ksp`` takes the start."""
    prefix = ksp.getOptionsPrefix() or ""
    db = PETSc.Options(prefix)
    return not (ksp.getType() in UNSTARTED or prefix.endswith(ESTIMATE) or any(db.getBool(k, False) for k in INITIAL))


def residual(ksp, b, x, r) -> bool:
    """r = b - A x (A the KSP's Amat; r = b and x = 0 where ``ksp`` starts from zero) without its part along A's
    transpose null space (KSPSolve projects b only after the presolve); returns the KSP's initial-guess flag. The
    first half of a start, this one's and the deflated form's (:meth:`.forms.Forms.presolve`)."""
    nonzero = ksp.getInitialGuessNonzero()
    if nonzero:
        ksp.getOperators()[0].mult(x, r)
        r.aypx(-1.0, b)
    else:
        b.copy(r)
        x.set(0.0)
    nsp = ksp.getOperators()[0].getTransposeNullSpace()
    if nsp.handle:
        nsp.remove(r)
    return nonzero


def advance(ksp, x, v, nonzero) -> dict:
    """x += v less its part along A's null space (a start adds no null component; a guess keeps its own), the KSP
    then starting from x; returns the settings to give back after the solve ({'guess': the flag ``nonzero``})."""
    null = ksp.getOperators()[0].getNullSpace()
    if null.handle:
        null.remove(v)
    x.axpy(1.0, v)
    ksp.setInitialGuessNonzero(True)
    return {"guess": nonzero}


def start(ksp, b, x, apply):
    """x += M (b - A x) (:func:`residual`, :func:`advance`), M being ``apply`` (y = M x); the settings to give back
    after the solve, or None where the KSP takes no start (:func:`wanted`)."""
    if not wanted(ksp):
        return None
    r, v = ksp.getOperators()[0].createVecs()
    try:
        nonzero = residual(ksp, b, x, r)
        apply(r, v)
        return advance(ksp, x, v, nonzero)
    finally:
        r.destroy()
        v.destroy()
