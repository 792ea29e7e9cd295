#!/usr/bin/env python
"""A plain PETSc program: a DMDA 5-point (7-point) variable-coefficient Poisson problem, one solve, any KSP and PC.

    python examples/dmda_poisson.py -n 256 -ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned \\
        -pc_type python -pc_python_type petsc_htp.HTPPC
    python examples/dmda_poisson.py -options_file options/cg_gamg.opts

``-n`` sets the grid side (256), ``-dim 3`` a 3-D grid. The matrix is handed over bare (no coordinates, no density, no
null space): the conductivity is 1 with discs (balls) of conductivity ``-contrast`` (1000), harmonic means on the
faces, homogeneous Dirichlet boundaries (:mod:`petsc_htp.scenes.dmda`: each rank sets its own rows by whole arrays;
in 2-D :func:`petsc_htp.scenes.gallery.variable_poisson` builds the same matrix). ``-scale_rows S`` hands over D A D
instead, D a random diagonal scaling in 10^-S .. 10^S (unknowns in mixed units; the right-hand side scaled alike).
``-frames K`` solves K more frames after the first, each with the discs of the next seed put into the same Mat and
solved by the same KSP (a simulation's loop: the preconditioner set up again for new values of the pattern).
``-warmup`` solves a smaller problem first, so that one-time costs (Python imports, first calls) are not in the timed
solve. Prints the iterations, PETSc's reason, the setup (KSPSetUp and PCSetUpOnBlocks: the preconditioner's analysis
and factorisation) and solve milliseconds, and the true relative residual (one line per later frame); exits non-zero
when a solve did not converge.
"""
import sys
from pathlib import Path

import numpy as np
import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.onesolve import solve_frames  # noqa: E402
from petsc_htp.scenes import dmda  # noqa: E402


def solve(n, contrast, seed, dim=2, scale=0.0, frames=0):
    """Assemble (scaled to D A D by 10^U(-scale, scale) per row where ``scale`` > 0) and solve frame 0, then
    ``frames`` more with the discs (balls) of seeds ``seed`` + k in the same Mat and KSP; each frame's (iterations,
    reason, setup ms, solve ms, true relative residual)."""
    da = dmda.grid(n, dim)
    A = dmda.operator(da, contrast, seed)
    b = dmda.source(A, n ** dim)
    d = None
    if scale > 0:
        d = b.duplicate()
        start, end = d.getOwnershipRange()
        d.setArray(10.0 ** np.random.default_rng(seed).uniform(-scale, scale, d.getSize())[start:end])
        A.diagonalScale(d, d)
        b.pointwiseMult(b, d)

    def refill(k):
        dmda.operator(da, contrast, seed + k, mat=A)
        if d is not None:
            A.diagonalScale(d, d)

    try:
        return solve_frames(A, b, frames, refill)
    finally:
        for obj in (A, b, da, d):
            if obj is not None:
                obj.destroy()


def main():
    db = PETSc.Options()
    contrast, seed, dim = db.getReal("contrast", 1000.0), db.getInt("seed", 0), db.getInt("dim", 2)
    scale = db.getReal("scale_rows", 0.0)
    if dim not in (2, 3):
        raise SystemExit(f"-dim must be 2 or 3, got {dim}")
    if db.getBool("warmup", False):
        solve(32 if dim == 2 else 12, contrast, seed + 1, dim, scale)
    frames = solve(db.getInt("n", 256), contrast, seed, dim, scale, db.getInt("frames", 0))
    its, reason, setup, solve_ms, relres = frames[0]
    PETSc.Sys.Print(f"iterations: {its}\nconverged reason: {reason}\nsetup ms (KSPSetUp): {setup:.1f}\n"
                    f"solve ms: {solve_ms:.1f}\ntrue relative residual ||b - A x|| / ||b||: {relres:.3e}")
    for k, (its, reason, setup, solve_ms, relres) in enumerate(frames[1:], 1):
        PETSc.Sys.Print(f"frame {k}: iterations {its}, converged reason {reason}, setup ms {setup:.1f}, "
                        f"solve ms {solve_ms:.1f}, true relative residual {relres:.3e}")
    return 0 if all(f[1] > 0 for f in frames) else 1


if __name__ == "__main__":
    sys.exit(main())
