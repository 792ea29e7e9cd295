"""A 2-D linear-elasticity operator (PyAMG's gallery, 2 unknowns per node) solved twice by CG + HTPPC on one
persistent KSP, the second time with new values; run by tests/test_operator_types.py under mpiexec.

Options: -mat_kind aij|baij|sbaij (the Mat's type, block size 2), -near none|bs|rbm (no block size on an AIJ
Mat, the block size alone, or PyAMG's rigid-body modes as the near null space). Prints one line per solve:
``solve K: its I reason R relres X`` and, with -ksp_view, what HTPPC saw."""
import sys

import petsc4py

petsc4py.init(sys.argv)
from petsc4py import PETSc  # noqa: E402
import numpy as np  # noqa: E402
from pyamg.gallery import linear_elasticity  # noqa: E402


def assemble(A, kind, bs, comm):
    """``A`` (scipy CSR) as a PETSc Mat of type ``kind`` (aij, baij or sbaij: the upper triangle) on ``comm``."""
    n = A.shape[0]
    mat = PETSc.Mat().create(comm=comm)
    mat.setSizes(((PETSc.DECIDE, n), (PETSc.DECIDE, n)), bsize=bs)
    mat.setType(kind)
    mat.setUp()
    mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    start, end = mat.getOwnershipRange()
    for i in range(start, end):
        cols = A.indices[A.indptr[i]:A.indptr[i + 1]]
        vals = A.data[A.indptr[i]:A.indptr[i + 1]]
        keep = cols >= i if kind == "sbaij" else slice(None)
        mat.setValues([i], cols[keep], vals[keep])
    mat.assemble()
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return mat


def main():
    db = PETSc.Options()
    kind, near = db.getString("mat_kind", "aij"), db.getString("near", "bs")
    A, B = linear_elasticity((db.getInt("side", 60),) * 2, format="csr")
    A.sort_indices()
    comm = PETSc.COMM_WORLD
    mat = assemble(A, kind, 1 if near == "none" else 2, comm)
    if near == "rbm":
        vecs = []
        for j in range(B.shape[1]):
            v = mat.createVecLeft()
            start, end = v.getOwnershipRange()
            v.getArray()[:] = B[start:end, j]
            v.normalize()
            vecs.append(v)
        mat.setNearNullSpace(PETSc.NullSpace().create(constant=False, vectors=vecs, comm=comm))
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.setTolerances(rtol=1e-8, max_it=1000)
    ksp.getPC().setType("python")
    ksp.getPC().setPythonType("petsc_htp.HTPPC")
    ksp.setFromOptions()
    b, x = mat.createVecLeft(), mat.createVecRight()
    b.setArray(np.random.default_rng(comm.getRank()).standard_normal(b.getLocalSize()))
    r = b.duplicate()
    for k in range(2):
        if k:                                   # new values, same pattern: the analysis is reused
            mat.scale(3.0)
            mat.shift(0.05)
        x.set(0.0)
        ksp.solve(b, x)
        ctx = ksp.getPC().getPythonContext()
        mat.mult(x, r)
        r.aypx(-1.0, b)
        PETSc.Sys.Print(f"solve {k}: its {ksp.getIterationNumber()} reason {ksp.getConvergedReason()} "
                        f"relres {r.norm() / b.norm():.3e} analyses {ctx.analysis_count} numeric {ctx.numeric_count}",
                        comm=comm)


if __name__ == "__main__":
    main()
