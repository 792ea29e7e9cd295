"""Run under mpiexec (2 or 3 ranks): PyAMG's 2-D elasticity (9 800 rows, two unknowns per node) handed over as a bare
AIJ Mat. Split as PETSc splits it, split so that every rank boundary cuts a node (one more row on the first rank),
and split so that every rank but the first holds one row (no whole node to check there), every rank finds block
size 2 in the pattern and CG converges in at most 40 iterations; a scalar matrix (a 5-point Laplacian of 9 800 rows)
finds none; prints 'blocksize ok'."""
import sys

import petsc4py

petsc4py.init(sys.argv)
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402
from pyamg.gallery import linear_elasticity  # noqa: E402

from petsc_htp.onesolve import solve_once  # noqa: E402


def bare(A, local):
    """``A`` as an AIJ Mat with ``local`` rows on this rank, no block size."""
    comm = PETSc.COMM_WORLD
    start = int(comm.tompi4py().exscan(local) or 0)
    sub = A[start:start + local]
    mat = PETSc.Mat().createAIJ(((local, A.shape[0]), (local, A.shape[0])), comm=comm,
                                csr=(sub.indptr.astype(PETSc.IntType), sub.indices.astype(PETSc.IntType), sub.data))
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    return mat, start


def main():
    A = sp.csr_matrix(linear_elasticity((70, 70))[0])
    A.sort_indices()
    n, rank = A.shape[0], PETSc.COMM_WORLD.getRank()
    for key, value in (("ksp_type", "cg"), ("ksp_norm_type", "unpreconditioned"), ("ksp_rtol", "1e-8"),
                       ("ksp_max_it", "1000"), ("pc_type", "python"), ("pc_python_type", "petsc_htp.HTPPC")):
        PETSc.Options().setValue(key, value)
    size = PETSc.COMM_WORLD.getSize()
    split = [n // size + (1 if r < n % size else 0) for r in range(size)]
    cut = [k + (1 if r == 0 else -1 if r == 1 else 0) for r, k in enumerate(split)]
    alone = [n - size + 1 if r == 0 else 1 for r in range(size)]   # every rank but the first holds one row
    found = {}
    for name, local in (("petsc", split[rank]), ("cut", cut[rank]), ("alone", alone[rank])):
        mat, start = bare(A, local)
        rhs = mat.createVecLeft()
        rhs.setArray(np.random.default_rng(0).standard_normal(n)[start:start + local])
        its, reason, _, _, relres = solve_once(mat, rhs)
        ksp = PETSc.KSP().create(mat.getComm())                       # the block size the analysis took
        ksp.setOperators(mat)
        ksp.setFromOptions()
        ksp.setUp()
        found[name] = ksp.getPC().getPythonContext().setup.st.bs
        PETSc.Sys.Print(f"{name}: iterations {its} reason {reason} relres {relres:.2e} block size {found[name]}")
        assert reason > 0 and relres <= 1.01e-8
        assert its <= 40, its
        for obj in (ksp, rhs, mat):
            obj.destroy()
    line = [sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], (k, k)) for k in (98, 100)]
    lap = sp.csr_matrix(sp.kron(line[0], sp.identity(100)) + sp.kron(sp.identity(98), line[1]))
    mat, _ = bare(lap, split[rank])
    ksp = PETSc.KSP().create(mat.getComm())
    ksp.setOperators(mat)
    ksp.setFromOptions()
    ksp.setUp()
    found["scalar"] = ksp.getPC().getPythonContext().setup.st.bs
    assert found == {"petsc": 2, "cut": 2, "alone": 2, "scalar": 1}, found
    PETSc.Sys.Print("blocksize ok")


if __name__ == "__main__":
    main()
