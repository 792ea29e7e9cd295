"""Run under mpiexec (2 ranks): a 2-D 5-point matrix whose rows come in a random order, split into contiguous
blocks as PETSc does, so most rows are coupled to the other rank and many stand alone in their rank's block (leaves
of such rows hold one piece, with a coarse column, per row). HTPPC converges, and W's pattern gives each row its own
piece's column only: the coarse operator keeps the few entries per row of the matrix it coarsens (each row of W
holding the whole leaf's columns made it about 80 per row and its LU take seconds), and -ksp_view's lines warn that
the split cuts half the couplings; prints 'shuffled ok'."""
import sys

import petsc4py

petsc4py.init(sys.argv)
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from petsc_htp.onesolve import timed_solve  # noqa: E402
from petsc_htp.pcview import lines  # noqa: E402
from petsc_htp.petscmat import local_csr, preallocated_aij  # noqa: E402

SIDE = 96


def shuffled() -> sp.csr_matrix:
    """The Dirichlet 5-point Laplacian on a SIDE^2 grid, rows and columns in a random order (the same on every
    rank)."""
    one = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (SIDE, SIDE))
    A = (sp.kron(one, sp.identity(SIDE)) + sp.kron(sp.identity(SIDE), one)).tocsr()
    p = np.random.default_rng(0).permutation(SIDE * SIDE)
    A = A[p][:, p].tocsr()
    A.sort_indices()
    return A


def main():
    comm = PETSc.COMM_WORLD
    A = shuffled()
    n = A.shape[0]
    mat, start, end = preallocated_aij(A, comm)
    mat.setValuesCSR(*local_csr(A, start, end))
    mat.assemble()
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    for key, value in (("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                       ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC")):
        PETSc.Options().setValue(key, value)
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(mat)
    ksp.setFromOptions()
    b, x = mat.createVecs()
    b.setArray(np.random.default_rng(1).standard_normal(n)[start:end])
    x.set(0.0)
    its, reason, _, _, relres = timed_solve(ksp, b, x)
    ctx = ksp.getPC().getPythonContext()
    E = ctx.setup.ops.E
    per_row = E.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"] / E.getSize()[0]
    lone = "1-64 per leaf" in "\n".join(ctx.setup.describe())
    view = "\n".join(lines(ctx))            # rows at random: half the couplings cross the ranks (petsc_htp.ranksplit)
    assert "of the off-diagonal couplings join rows of two ranks" in view and "WARNING: leaves hold one" in view, view
    PETSc.Sys.Print(f"iterations {its} relres {relres:.2e} coarse rows {E.getSize()[0]} "
                    f"entries per coarse row {per_row:.1f} lone-row leaves {lone}", comm=comm)
    assert reason > 0 and its <= 40 and relres <= 1e-8
    assert lone and per_row <= 10, per_row
    PETSc.Sys.Print("shuffled ok", comm=comm)


if __name__ == "__main__":
    main()
