"""mpiexec -n R python tests/ksps_case.py: small matrices of the foreign study (below 2 000 rows: one factor of the
whole matrix, ICC(0) for the anisotropic one and PyAMG's ``bar``) under KSPs other than CG, each from a fresh KSP with HTPPC; prints
``KSP <matrix> <ksp> <reason> <its> <true relres>`` per solve."""
import sys

import petsc4py

petsc4py.init(sys.argv[:1])
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from petsc_htp import HTPPC  # noqa: E402
from petsc_htp.bench.foreigncases import CASES, pyamg_cases  # noqa: E402

COMM = PETSc.COMM_WORLD
KSPS = ("bcgsl", "richardson", "chebyshev", "cgs", "tfqmr", "minres", "gmres", "bcgs", "cgne")


def distributed(A, b):
    """The AIJ matrix and right-hand side of the global ``A``, ``b``, rows split as PETSc does."""
    mat = PETSc.Mat().create(COMM)
    mat.setSizes(A.shape)
    mat.setType("aij")
    mat.setUp()
    lo, hi = mat.getOwnershipRange()
    rows = sp.csr_matrix(A[lo:hi])
    rows.sort_indices()
    mat.setPreallocationCSR((rows.indptr, rows.indices))
    mat.setValuesCSR(rows.indptr, rows.indices, rows.data)
    mat.assemble()
    x, rhs = mat.createVecs()
    rhs.setArray(np.asarray(b)[lo:hi])
    return mat, rhs, x


MATRICES = {name: CASES[name](n, 0) for name, n in (("dmda2d", 1024), ("neumann", 900), ("aniso_e0.01_a30", 1024))}
MATRICES["pyamg_bar"] = pyamg_cases()["pyamg_bar"]

for name, (A, b) in MATRICES.items():
    mat, rhs, x = distributed(A, b)
    for kind in KSPS:
        ksp = PETSc.KSP().create(COMM)
        ksp.setOperators(mat)
        ksp.setType(kind)
        ksp.setTolerances(rtol=1e-8, max_it=2000)
        ksp.getPC().setType("python")
        ksp.getPC().setPythonContext(HTPPC())
        x.set(0.0)
        ksp.solve(rhs, x)
        r = rhs.duplicate()
        mat.mult(x, r)
        r.aypx(-1.0, rhs)
        PETSc.Sys.Print(f"KSP {name} {kind} {ksp.getConvergedReason()} {ksp.getIterationNumber()} "
                        f"{r.norm() / rhs.norm():.2e}")
        r.destroy()
        ksp.destroy()
    mat.destroy()
