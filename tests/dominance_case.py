"""Run under mpiexec: a diagonally dominant matrix on every rank takes ICC(0) of each rank's block (PCBJACOBI); new
values of the same pattern that lose the dominance on one rank only make a new analysis on all, the two-level
method's (DirectPC.moved is local, HTPPC or-reduces it); prints 'dominance ok on N ranks'."""
import sys

import petsc4py

petsc4py.init(sys.argv)
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

import petsc_htp  # noqa: E402
from petsc_htp.scenes import foreign  # noqa: E402


def main():
    comm = PETSc.COMM_WORLD
    rank, size = comm.getRank(), comm.getSize()
    K = foreign.dmda(2, 110, 1e3, 0)[0].tocsr()
    n = K.shape[0]
    start, end = rank * n // size, (rank + 1) * n // size
    off = np.asarray(abs(K).sum(axis=1)).ravel() - np.abs(K.diagonal())
    D = sp.csr_matrix(K, copy=True)
    D.setdiag(K.diagonal() + 0.01 * off)                      # every coupled row dominant by 1 %
    mine = D[start:end]
    mat = PETSc.Mat().createAIJ(((end - start, n), (end - start, n)), comm=comm,
                                csr=(mine.indptr.astype(PETSc.IntType), mine.indices.astype(PETSc.IntType), mine.data))
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(mat, mat)
    ksp.setType("cg")
    ksp.setTolerances(rtol=1e-8)
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
    ksp.getPC().setType("python")
    ctx = petsc_htp.HTPPC()
    ksp.getPC().setPythonContext(ctx)
    b, x = mat.createVecLeft(), mat.createVecRight()
    b.setArray(np.random.default_rng(rank).standard_normal(end - start))
    kinds = []
    for values in (D, K if rank == size - 1 else D):          # the last rank's rows lose their dominance
        part = values[start:end]
        mat.setValuesCSR(part.indptr.astype(PETSc.IntType), part.indices.astype(PETSc.IntType), part.data)
        mat.assemble()
        ksp.setOperators(mat, mat)
        x.set(0.0)
        ksp.solve(b, x)
        assert ksp.getConvergedReason() > 0, ksp.getConvergedReason()
        kinds.append((ctx.analysis_count, ctx.setup.describe()[0].split(":")[0]))
    assert kinds == [(1, "whole matrix"), (2, "graph")], kinds
    if rank == 0:
        print(f"dominance ok on {size} ranks")


if __name__ == "__main__":
    main()
