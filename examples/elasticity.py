#!/usr/bin/env python
"""A plain PETSc program: 2-D linear elasticity (PyAMG's gallery: bilinear elements, 2 unknowns per node, one
side clamped) or with ``-dim 3`` 3-D (trilinear hexahedra, 3 unknowns per node, one face clamped:
:func:`petsc_htp.scenes.meshes.q1_elasticity`), solved twice on one persistent KSP, the second time with new
values of the same pattern.

    python examples/elasticity.py -side 200 -near rbm -ksp_type cg -ksp_rtol 1e-8 \\
        -ksp_norm_type unpreconditioned -pc_type python -pc_python_type petsc_htp.HTPPC
    python examples/elasticity.py -side 200 -near rbm -options_file options/cg_gamg.opts

``-side`` nodes per side in 2-D (110), elements per edge in 3-D (20), ``-mat_kind aij|baij|sbaij`` the Mat's type (SBAIJ
holds the upper triangle), ``-near none|bs|rbm``: an AIJ Mat with no block size, the block size (2, 3) alone, or the
block size with the
rigid-body modes attached as the near null space (``MatSetNearNullSpace``, as GAMG reads them). ``-warmup`` solves
a small problem first (one-time costs out of the timed solves). Prints one line per solve (iterations, PETSc's
reason, true relative residual, HTPPC's analyses and numeric steps when it is the PC, KSPSetUp and KSPSolve ms);
exits non-zero when a solve did not converge.
"""
import sys
from pathlib import Path

import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402
import numpy as np  # noqa: E402
from pyamg.gallery import linear_elasticity  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from petsc_htp.onesolve import timed_solve  # noqa: E402
from petsc_htp.scenes.meshes import q1_elasticity  # noqa: E402


def assemble(A, kind, bs, comm):
    """``A`` (scipy CSR) as a PETSc Mat of type ``kind`` (aij, baij, or sbaij: the upper triangle) on ``comm``, each
    rank setting its own rows."""
    n = A.shape[0]
    mat = PETSc.Mat().create(comm=comm)
    mat.setSizes(((PETSc.DECIDE, n), (PETSc.DECIDE, n)), bsize=bs)
    mat.setType(kind)
    mat.setUp()
    mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    start, end = mat.getOwnershipRange()
    rows = A[start:end].tocoo()
    keep = rows.col >= rows.row + start if kind == "sbaij" else np.ones(rows.nnz, dtype=bool)
    r, c, v = rows.row[keep], rows.col[keep], rows.data[keep]
    indptr = np.concatenate(([0], np.cumsum(np.bincount(r, minlength=end - start))))
    mat.setValuesIJV(indptr.astype(PETSc.IntType), c.astype(PETSc.IntType), v,
                     rowmap=np.arange(start, end, dtype=PETSc.IntType))
    mat.assemble()
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return mat


def rigid_body_modes(mat, B):
    """The rigid-body modes ``B`` (n, 3 in 2-D, 6 in 3-D) as ``mat``'s near null space (made orthonormal, as
    MatNullSpaceCreate asks)."""
    vecs = []
    for j in range(B.shape[1]):
        v = mat.createVecLeft()
        start, end = v.getOwnershipRange()
        v.getArray()[:] = B[start:end, j]
        for q in vecs + vecs:                       # Gram-Schmidt, twice
            v.axpy(-q.dot(v), q)
        v.normalize()
        vecs.append(v)
    mat.setNearNullSpace(PETSc.NullSpace().create(constant=False, vectors=vecs, comm=mat.getComm()))


def run(side, kind, near, comm, dim=2, quiet=False):
    """Assemble, solve, change the values, solve again; False when a solve did not converge."""
    A, B = linear_elasticity((side, side), format="csr") if dim == 2 else q1_elasticity(side)
    A.sort_indices()
    mat = assemble(A, kind, 1 if near == "none" else dim, comm)
    if near == "rbm":
        rigid_body_modes(mat, B)
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(mat, mat)
    ksp.setFromOptions()
    b, x = mat.createVecLeft(), mat.createVecRight()
    b.setArray(np.random.default_rng(comm.getRank()).standard_normal(b.getLocalSize()))
    ok = True
    for k in range(2):
        if k:                                   # new values, same pattern: HTPPC keeps its analysis
            mat.scale(3.0)
            mat.shift(0.05)
        x.set(0.0)
        its, reason, setup_ms, solve_ms, relres = timed_solve(ksp, b, x)
        pc = ksp.getPC()
        ctx = pc.getPythonContext() if pc.getType() == "python" else None
        counts = f" analyses {ctx.analysis_count} numeric {ctx.numeric_count}" if ctx is not None else ""
        ok = ok and reason > 0
        if not quiet:
            PETSc.Sys.Print(f"solve {k}: its {its} reason {reason} relres {relres:.3e}{counts} setup ms {setup_ms:.1f} "
                            f"solve ms {solve_ms:.1f}", comm=comm)
    for obj in (ksp, mat, b, x):
        obj.destroy()
    return ok


def main():
    db = PETSc.Options()
    kind, near, dim = db.getString("mat_kind", "aij"), db.getString("near", "bs"), db.getInt("dim", 2)
    if kind not in ("aij", "baij", "sbaij") or near not in ("none", "bs", "rbm") or dim not in (2, 3):
        raise SystemExit(f"-mat_kind aij|baij|sbaij, -near none|bs|rbm and -dim 2|3, got {kind!r}, {near!r} and {dim}")
    if db.getBool("warmup", False):
        run(12 if dim == 2 else 4, kind, near, PETSc.COMM_WORLD, dim, quiet=True)
    return 0 if run(db.getInt("side", 110 if dim == 2 else 20), kind, near, PETSc.COMM_WORLD, dim) else 1


if __name__ == "__main__":
    sys.exit(main())
