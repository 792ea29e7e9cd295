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

UNSTARTED = ("richardson", "chebyshev")
INITIAL = ("ksp_converged_use_initial_residual_norm", "ksp_converged_use_min_initial_residual_norm")


def wanted(ksp) -> bool:
    """Whether a solve by ``ksp`` takes the start."""
    prefix = ksp.getOptionsPrefix() or ""
    db = PETSc.Options(prefix)
    return not (ksp.getType() in UNSTARTED or prefix.endswith("esteig_") or any(db.getBool(k, False) for k in INITIAL))


def start(ksp, b, x, apply) -> dict:
    """x += M (b - A x) (x = M b where ``ksp`` starts from zero), M being ``apply`` (y = M x), A the KSP's Amat, the
    residual without its part along A's transpose null space (KSPSolve projects b only after this call), the step
    without its part along A's null space; the KSP then starts from x. Returns the settings changed, to give back
    after the solve ({'guess': the initial-guess flag}), or None where the KSP takes none (:func:`wanted`)."""
    if not wanted(ksp):
        return None
    nonzero, amat = ksp.getInitialGuessNonzero(), ksp.getOperators()[0]
    r, v = amat.createVecs()
    try:
        if nonzero:
            amat.mult(x, r)
            r.aypx(-1.0, b)
        else:
            b.copy(r)
            x.set(0.0)
        nsp = amat.getTransposeNullSpace()
        if nsp.handle:
            nsp.remove(r)
        apply(r, v)
        null = amat.getNullSpace()
        if null.handle:
            null.remove(v)
        x.axpy(1.0, v)
    finally:
        r.destroy()
        v.destroy()
    ksp.setInitialGuessNonzero(True)
    return {"guess": nonzero}
