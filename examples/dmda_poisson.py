#!/usr/bin/env python
"""A plain PETSc program: a DMDA 5-point (7-point) variable-coefficient Poisson problem, one solve, any KSP and PC.

    python examples/dmda_poisson.py -n 256 -ksp_type cg -ksp_rtol 1e-8 -ksp_norm_type unpreconditioned \\
        -pc_type python -pc_python_type petsc_htp.HTPPC
    python examples/dmda_poisson.py -options_file options/cg_gamg.opts

``-n`` sets the grid side (256), ``-dim 3`` a 3-D grid. The matrix is handed over bare (no coordinates, no density, no
null space): the conductivity is 1 with discs (balls) of conductivity ``-contrast`` (1000), harmonic means on the
faces, homogeneous Dirichlet boundaries (in 2-D :func:`petsc_htp.scenes.gallery.variable_poisson` builds the same
matrix). In 3-D each rank sets its own rows by whole arrays (a loop over two million cells would take minutes).
``-scale_rows S`` hands over D A D instead, D a random diagonal scaling in 10^-S .. 10^S (unknowns in mixed
units; the right-hand side scaled alike). ``-warmup`` solves a smaller problem
first, so that one-time costs (Python imports, first calls) are not in the timed solve. Prints the
iterations, PETSc's reason, the setup (KSPSetUp: the preconditioner's analysis and factorisation) and
solve milliseconds, and the true relative residual; exits non-zero when the solve did not converge.
"""
import sys
from pathlib import Path

import numpy as np
import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.onesolve import solve_once  # noqa: E402
from petsc_htp.scenes.gallery import balls, face_weights, inclusions  # noqa: E402


def assemble(da, contrast, seed):
    """The operator on the DMDA's grid, rows inserted by stencil (each rank its own)."""
    nx, ny = da.getSizes()
    wx, wy, edge = face_weights(inclusions(nx, ny, contrast, seed))
    A = da.createMat()
    row, col = PETSc.Mat.Stencil(), PETSc.Mat.Stencil()
    (x0, x1), (y0, y1) = da.getRanges()
    for j in range(y0, y1):
        for i in range(x0, x1):
            row.index = (i, j)
            diag = edge[j, i]
            for di, dj, w in ((-1, 0, wx[j, i - 1] if i > 0 else 0.0), (1, 0, wx[j, i] if i < nx - 1 else 0.0),
                              (0, -1, wy[j - 1, i] if j > 0 else 0.0), (0, 1, wy[j, i] if j < ny - 1 else 0.0)):
                if w:
                    col.index = (i + di, j + dj)
                    A.setValueStencil(row, col, -w)
                    diag += w
            A.setValueStencil(row, row, diag)
    A.assemble()
    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return A


def assemble_3d(da, contrast, seed):
    """The 7-point operator on a 3-D DMDA's grid: each rank sets its own rows, whole arrays at a time (DMDA's
    application ordering gives the neighbours' global numbers)."""
    shape = tuple(da.getSizes())[::-1]                                   # (nz, ny, nx)
    k = balls(shape, contrast, seed)
    wx, wy, wz, edge = face_weights(k)
    cell = np.meshgrid(*[np.arange(lo, hi) for lo, hi in da.getRanges()[::-1]], indexing="ij")
    cell = [c.ravel() for c in cell]                                     # the rank's cells in its rows' order
    diag = edge[tuple(cell)]
    cols, vals = [], []
    for axis, w in ((2, wx), (1, wy), (0, wz)):
        for step in (-1, 1):
            other = list(cell)
            other[axis] = cell[axis] + step
            inside = (other[axis] >= 0) & (other[axis] < shape[axis])
            face = list(cell)
            face[axis] = np.clip(np.minimum(cell[axis], other[axis]), 0, shape[axis] - 2)
            weight = np.where(inside, w[tuple(face)], 0.0)
            diag = diag + weight
            other[axis] = np.clip(other[axis], 0, shape[axis] - 1)
            cols.append(np.where(inside, np.ravel_multi_index(tuple(other), shape), -1))
            vals.append(-weight)
    rows = np.ravel_multi_index(tuple(cell), shape)
    cols, vals = np.stack(cols + [rows], 1), np.stack(vals + [diag], 1)
    ao = da.getAO()
    A = da.createMat()
    first = A.getOwnershipRange()[0]
    mapped = ao.app2petsc(np.where(cols >= 0, cols, 0).astype(PETSc.IntType).ravel()).reshape(cols.shape)
    petsc_cols = np.where(cols >= 0, mapped, -1)
    live = petsc_cols >= 0
    indptr = np.concatenate(([0], np.cumsum(live.sum(1)))).astype(PETSc.IntType)
    A.setValuesIJV(indptr, petsc_cols[live].astype(PETSc.IntType), vals[live],
                   rowmap=np.arange(first, first + rows.size, dtype=PETSc.IntType))
    A.assemble()
    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return A


def solve(n, contrast, seed, dim=2, scale=0.0):
    """Assemble (scaled to D A D by 10^U(-scale, scale) per row where ``scale`` > 0) and solve once; (iterations,
    reason, setup ms, solve ms, true relative residual)."""
    da = PETSc.DMDA().create([n] * dim, stencil_width=1, stencil_type=PETSc.DMDA.StencilType.STAR)
    da.setUp()
    A = assemble(da, contrast, seed) if dim == 2 else assemble_3d(da, contrast, seed)
    b = A.createVecLeft()
    b.set(1.0 / float(np.prod(da.getSizes())))
    if scale > 0:
        d = b.duplicate()
        start, end = d.getOwnershipRange()
        d.setArray(10.0 ** np.random.default_rng(seed).uniform(-scale, scale, d.getSize())[start:end])
        A.diagonalScale(d, d)
        b.pointwiseMult(b, d)
        d.destroy()
    out = solve_once(A, b)
    for obj in (A, b, da):
        obj.destroy()
    return out


def main():
    db = PETSc.Options()
    contrast, seed, dim = db.getReal("contrast", 1000.0), db.getInt("seed", 0), db.getInt("dim", 2)
    scale = db.getReal("scale_rows", 0.0)
    if dim not in (2, 3):
        raise SystemExit(f"-dim must be 2 or 3, got {dim}")
    if db.getBool("warmup", False):
        solve(32 if dim == 2 else 12, contrast, seed + 1, dim, scale)
    its, reason, setup, solve_ms, relres = solve(db.getInt("n", 256), contrast, seed, dim, scale)
    PETSc.Sys.Print(f"iterations: {its}\nconverged reason: {reason}\nsetup ms (KSPSetUp): {setup:.1f}\n"
                    f"solve ms: {solve_ms:.1f}\ntrue relative residual ||b - A x|| / ||b||: {relres:.3e}")
    return 0 if reason > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
